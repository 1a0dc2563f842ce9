"""What the textured samples (albedo.py, envphong.py) share: Spot loaded with its texture
coordinates, vertex normals, and random orbiting cameras. Written for softvk's samples.

Spot (``assets/spot_triangulated.obj``, Keenan Crane's cow, CC0; see ``assets/LICENSE-spot``) has
one texture coordinate per face corner, so positions and texture coordinates have separate
triangle lists, as nvdiffrast's samples keep them (``tri`` and ``uv_idx``).
"""

import pathlib

import sys

import numpy as np
import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import cube  # noqa: E402  (this folder's cube.py: the projection and the quaternions)

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


def random_camera(rng, distance=2.8, centre=(0.0, 0.1, 0.2)):
    """A camera orbiting ``centre`` at ``distance``, in a uniformly random direction:
    ``(mvp [4, 4] float32 tensor, eye [3] float32 tensor)``, the world fixed."""
    r = cube.quat_to_matrix_np(cube.random_quaternion(rng))  # world to camera, uniform
    view = np.eye(4)
    view[:3, :3] = r
    view[:3, 3] = -r @ np.asarray(centre) + np.array([0.0, 0.0, -distance])
    eye = r.T @ (np.array([0.0, 0.0, distance])) + np.asarray(centre)
    mvp = cube.perspective(45.0, near=0.5, far=20.0) @ view
    return torch.from_numpy(mvp.astype(np.float32)), torch.from_numpy(eye.astype(np.float32))


def to_clip(mvp, pos):
    """Positions [V, 3] into clip space [1, V, 4] by ``mvp`` [4, 4]."""
    homogeneous = torch.cat([pos, torch.ones_like(pos[:, :1])], dim=1)
    return (homogeneous @ mvp.transpose(0, 1))[None].contiguous()
