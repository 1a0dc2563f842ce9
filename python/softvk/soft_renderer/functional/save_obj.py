"""Writing meshes (and voxel sets) as Wavefront OBJ, as SoftRas's ``save_obj``."""

import os

import numpy as np
import torch

from ._image import write_png

__all__ = ["save_obj", "save_voxel", "create_texture_image"]


def _numpy(tensor):
    if torch.is_tensor(tensor):
        return tensor.detach().cpu().numpy()
    return np.asarray(tensor)


def create_texture_image(textures, texture_res=16):
    """Lays per-face textures out in a texture atlas, as SoftRas.

    Each face gets a ``texture_res``² tile (tiles in rows of ``ceil(sqrt(F))``); its triangle's
    corners sit at ``(R/2, 1)``, ``(1, R - 2)`` and ``(R - 2, R - 2)`` within the tile, and every
    pixel of the tile takes the texel the clipped barycentrics of its position select (SPEC §2's
    sampling rule), so the whole tile is filled.

    Args:
        textures: [F, r², 3] per-face textures.
        texture_res: R, the tile size in pixels.

    Returns:
        ``(image, uvs)``: float [H, W, 3] with row 0 at the top, and [F, 3, 2] texture
        coordinates of the corners in [0, 1] (``v = 0`` at the bottom).
    """
    textures = _numpy(textures).astype(np.float64)
    num_faces = textures.shape[0]
    r_in = int(round(np.sqrt(textures.shape[1])))
    tile_width = int((num_faces - 1.0) ** 0.5) + 1
    tile_height = int((num_faces - 1.0) / tile_width) + 1
    R = texture_res

    face = np.arange(num_faces)
    column = face % tile_width
    row = face // tile_width
    corners = np.zeros((num_faces, 3, 2))  # pixel coordinates (x, y)
    corners[:, 0, 0] = column * R + R / 2
    corners[:, 0, 1] = row * R + 1
    corners[:, 1, 0] = column * R + 1
    corners[:, 1, 1] = (row + 1) * R - 1 - 1
    corners[:, 2, 0] = (column + 1) * R - 1 - 1
    corners[:, 2, 1] = (row + 1) * R - 1 - 1

    height, width = tile_height * R, tile_width * R
    y, x = np.mgrid[0:height, 0:width]
    fn = (x // R) + (y // R) * tile_width
    image = np.ones((height, width, 3))
    inside = fn < num_faces
    x, y, fn = x[inside].astype(np.float64), y[inside].astype(np.float64), fn[inside]

    # Barycentrics of each pixel in its face's triangle, clipped to [0, 1] and renormalized
    # (eps 1e-5 as SoftRas's kernel).
    eps = 1e-5
    p0, p1, p2 = corners[fn, 0], corners[fn, 1], corners[fn, 2]
    denominator = (
        p2[:, 0] * (p0[:, 1] - p1[:, 1])
        + p0[:, 0] * (p1[:, 1] - p2[:, 1])
        + p1[:, 0] * (p2[:, 1] - p0[:, 1])
    ) + eps

    def weight(a, b):
        return ((a[:, 1] - b[:, 1]) * x + (b[:, 0] - a[:, 0]) * y
                + (a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])) / denominator

    w = np.stack([weight(p1, p2), weight(p2, p0), weight(p0, p1)], axis=1)
    w = np.clip(w, 0.0, 1.0)
    w = w / (w.sum(axis=1, keepdims=True) + eps)
    w_x = (w[:, 0] * r_in).astype(np.int64)
    w_y = (w[:, 1] * r_in).astype(np.int64)
    lower = (w[:, 0] + w[:, 1]) * r_in - w_x - w_y <= 1
    texel = np.where(lower, w_y * r_in + w_x, (r_in - 1 - w_y) * r_in + (r_in - 1 - w_x))
    texel = np.clip(texel, 0, r_in * r_in - 1)
    image[inside] = textures[fn, texel]

    uvs = corners.copy()
    uvs[:, :, 0] /= width - 1
    uvs[:, :, 1] /= height - 1
    # Rows flipped so that the image's bottom is v = 0 (the corners were placed top-down).
    return image[::-1], uvs


def save_obj(filename, vertices, faces, textures=None, texture_res=16, texture_type="surface"):
    """Writes a mesh as a Wavefront OBJ.

    Args:
        filename: path of the ``.obj``.
        vertices: [V, 3].
        faces: [F, 3] 0-based indices.
        textures: ``None``; surface textures [F, R², 3], written as a texture atlas
            (``<name>.png``, ``texture_res`` pixels per face side) with ``<name>.mtl``; or
            vertex colours [V, 3], written as ``v x y z r g b``.
        texture_res: the atlas tile size (at least 2).
        texture_type: ``'surface'`` or ``'vertex'``.
    """
    vertices = _numpy(vertices)
    faces = _numpy(faces)
    if vertices.ndim != 2 or faces.ndim != 2:
        raise ValueError("save_obj takes one mesh: vertices [V, 3] and faces [F, 3]")
    if texture_type not in ("surface", "vertex"):
        raise ValueError("texture_type must be 'surface' or 'vertex', got %r" % (texture_type,))
    if texture_res < 2:
        raise ValueError("texture_res must be at least 2, got %d" % texture_res)

    surface = textures is not None and texture_type == "surface"
    base = os.path.splitext(filename)[0]
    if surface:
        filename_mtl = base + ".mtl"
        filename_texture = base + ".png"
        material_name = "material_1"
        texture_image, uvs = create_texture_image(textures, texture_res)
        # SoftRas truncates; rounding keeps an 8-bit colour (k / 255) exact through a round trip.
        write_png(filename_texture, np.round(np.clip(texture_image, 0, 1) * 255).astype(np.uint8))
    colors = _numpy(textures) if textures is not None and texture_type == "vertex" else None

    lines = ["# %s" % os.path.basename(filename), "#", ""]
    if surface:
        lines += ["mtllib %s" % os.path.basename(filename_mtl), ""]
    if colors is not None:
        lines += ["v %.8f %.8f %.8f %.8f %.8f %.8f" % (tuple(v) + tuple(c))
                  for v, c in zip(vertices.tolist(), colors.tolist())]
    else:
        lines += ["v %.8f %.8f %.8f" % tuple(v) for v in vertices.tolist()]
    lines.append("")
    if surface:
        lines += ["vt %.8f %.8f" % tuple(uv) for uv in uvs.reshape(-1, 2).tolist()]
        lines += ["", "usemtl %s" % material_name]
        # Corner k of face i uses texture coordinate 3 i + k.
        lines += ["f %d/%d %d/%d %d/%d"
                  % (f[0] + 1, 3 * i + 1, f[1] + 1, 3 * i + 2, f[2] + 1, 3 * i + 3)
                  for i, f in enumerate(faces.tolist())]
        lines.append("")
    else:
        lines += ["f %d %d %d" % (f[0] + 1, f[1] + 1, f[2] + 1) for f in faces.tolist()]
    with open(filename, "w") as f:
        f.write("\n".join(lines) + "\n")

    if surface:
        with open(filename_mtl, "w") as f:
            f.write("newmtl %s\n" % material_name)
            f.write("map_Kd %s\n" % os.path.basename(filename_texture))


def save_voxel(filename, voxel):
    """Writes the occupied cells of a [X, Y, Z] voxel grid as OBJ points ``(i/X, j/Y, k/Z)``."""
    voxel = _numpy(voxel)
    points = np.argwhere(voxel == 1) / np.asarray(voxel.shape, dtype=np.float64)
    with open(filename, "w") as f:
        f.write("# %s\n#\n\n" % os.path.basename(filename))
        for p in points.tolist():
            f.write("v %.8f %.8f %.8f\n" % tuple(p))
