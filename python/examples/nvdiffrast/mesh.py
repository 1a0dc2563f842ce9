"""What the textured samples (albedo.py, envphong.py) share: Spot loaded with its texture
coordinates, vertex normals, and random orbiting cameras. Written for softvk's samples.

Spot (``assets/spot_triangulated.obj``, Keenan Crane's cow, CC0; see ``assets/LICENSE-spot``) has
one texture coordinate per face corner, so positions and texture coordinates have separate
triangle lists, as nvdiffrast's samples keep them (``tri`` and ``uv_idx``).
"""

import pathlib

import numpy as np
import torch

ASSETS = pathlib.Path(__file__).resolve().parents[3] / "assets"


def load_obj(path=ASSETS / "spot_triangulated.obj"):
    """``(pos [V, 3] float32, tri [F, 3] int32, uv [T, 2] float32, uv_tri [F, 3] int32)`` of a
    triangulated OBJ whose faces are ``v/vt`` or ``v/vt/vn``."""
    pos, uv, tri, uv_tri = [], [], [], []
    for line in open(path):
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            pos.append([float(x) for x in parts[1:4]])
        elif parts[0] == "vt":
            uv.append([float(x) for x in parts[1:3]])
        elif parts[0] == "f":
            if len(parts) != 4:
                raise ValueError(f"{path}: a face of {len(parts) - 1} corners (triangles only)")
            corners = [p.split("/") for p in parts[1:]]
            if any(len(c) < 2 or not c[1] for c in corners):
                raise ValueError(f"{path}: a face without texture coordinates")
            tri.append([int(c[0]) - 1 for c in corners])
            uv_tri.append([int(c[1]) - 1 for c in corners])
    return (
        np.asarray(pos, np.float32),
        np.asarray(tri, np.int32),
        np.asarray(uv, np.float32),
        np.asarray(uv_tri, np.int32),
    )


def vertex_normals(pos, tri):
    """Unit vertex normals [V, 3]: the sum of the faces' area-weighted normals at each vertex."""
    p = pos.astype(np.float64)
    n = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    out = np.zeros_like(p)
    for k in range(3):
        np.add.at(out, tri[:, k], n)
    return (out / np.linalg.norm(out, axis=1, keepdims=True)).astype(np.float32)


def perspective(fov_y_deg=45.0, near=0.5, far=20.0):
    """An OpenGL-style perspective projection (camera down -z) into clip space, float64
    [4, 4]."""
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def random_rotation(rng):
    """A uniformly random rotation [3, 3] (a normalised 4-D Gaussian as a quaternion)."""
    w, x, y, z = rng.standard_normal(4) / 1.0
    n = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def random_camera(rng, distance=2.8, centre=(0.0, 0.1, 0.2)):
    """A camera orbiting ``centre`` at ``distance``, in a uniformly random direction:
    ``(mvp [4, 4] float32 tensor, eye [3] float32 tensor)``, the world fixed."""
    r = random_rotation(rng)  # world to camera
    view = np.eye(4)
    view[:3, :3] = r
    view[:3, 3] = -r @ np.asarray(centre) + np.array([0.0, 0.0, -distance])
    eye = r.T @ (np.array([0.0, 0.0, distance])) + np.asarray(centre)
    mvp = perspective() @ view
    return torch.from_numpy(mvp.astype(np.float32)), torch.from_numpy(eye.astype(np.float32))


def to_clip(mvp, pos):
    """Positions [V, 3] into clip space [1, V, 4] by ``mvp`` [4, 4]."""
    homogeneous = torch.cat([pos, torch.ones_like(pos[:, :1])], dim=1)
    return (homogeneous @ mvp.transpose(0, 1))[None].contiguous()
