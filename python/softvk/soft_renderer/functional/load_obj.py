"""Loading Wavefront OBJ meshes with their MTL textures, as SoftRas's ``load_obj``.

The result is the mesh softvk's own loader (``softvk render --mesh``) makes of the same file:
vertices in the order of the ``v`` lines, polygons fan-triangulated ``(v0, vi, vi+1)``, and each
material's ``map_Kd`` image sampled once into R×R texels per face at SoftRas's texel centres,
with its bilinear filter and vertical flip.
"""

import os
import warnings

import numpy as np
import torch

from ._image import read_rgb

__all__ = ["load_obj", "load_mtl"]


def load_obj(filename_obj, normalization=False, load_texture=False, texture_res=4,
             texture_type="surface"):
    """Loads a Wavefront OBJ file.

    Only positions (``v``), texture coordinates (``vt``), faces (``f``, polygons fanned into
    triangles; negative indices count back from the last vertex) and materials (``mtllib``,
    ``usemtl``) are read.

    Args:
        filename_obj: path of the ``.obj``.
        normalization: scale and translate the vertices as SoftRas does: the longest side of
            the bounding box becomes [-1, 1] and the box is centred at the origin.
        load_texture: also return textures.
        texture_res: R, texels per face side for surface textures.
        texture_type: ``'surface'``: textures [F, R², 3] from the MTL (``map_Kd`` sampled, else
            the material's ``Kd``, else white); ``'vertex'``: colours [V, 3] from
            ``v x y z r g b`` lines.

    Returns:
        ``(vertices, faces)`` or ``(vertices, faces, textures)``: float32 [V, 3], int32 [F, 3]
        and float32 textures, on the CPU.

    A material file that ``mtllib`` names but that does not exist, or a ``map_Kd`` image that
    does not exist, is a warning (those faces get the material's ``Kd``, or white), as in
    ``softvk render``; an OBJ with no ``mtllib`` at all cannot give surface textures and is an
    error, as in SoftRas.
    """
    if texture_type not in ("surface", "vertex"):
        raise ValueError("texture_type must be 'surface' or 'vertex', got %r" % (texture_type,))
    with open(filename_obj) as f:
        lines = f.readlines()

    positions = []
    colors = []
    uvs = []
    faces = []
    face_uvs = []
    face_materials = []
    mtl_files = []
    material = ""
    for number, line in enumerate(lines, start=1):
        tokens = line.split()
        if not tokens:
            continue
        kind = tokens[0]
        if kind == "v":
            positions.append([float(v) for v in tokens[1:4]])
            colors.append([float(v) for v in tokens[4:7]])
        elif kind == "vt":
            uvs.append([float(v) for v in tokens[1:3]])
        elif kind == "f":
            corners = [_parse_corner(t, len(positions), len(uvs)) for t in tokens[1:]]
            if len(corners) < 3:
                raise ValueError("%s:%d: a face with fewer than 3 vertices"
                                 % (filename_obj, number))
            for i in range(len(corners) - 2):
                tri = (corners[0], corners[i + 1], corners[i + 2])
                faces.append([c[0] for c in tri])
                face_uvs.append([c[1] for c in tri])
                face_materials.append(material)
        elif kind == "usemtl" and len(tokens) > 1:
            material = tokens[1]
        elif kind == "mtllib" and len(tokens) > 1:
            mtl_files.append(line.strip()[len("mtllib"):].strip())

    if not positions:
        raise ValueError("%s: no vertices" % filename_obj)
    if not faces:
        raise ValueError("%s: no faces" % filename_obj)
    faces = np.asarray(faces, dtype=np.int64)
    if faces.min() < 0 or faces.max() >= len(positions):
        raise ValueError(
            "%s: a face index is out of range (the file has %d vertices)"
            % (filename_obj, len(positions))
        )
    vertices = torch.from_numpy(np.asarray(positions, dtype=np.float32))
    faces_t = torch.from_numpy(faces.astype(np.int32))

    textures = None
    if load_texture and texture_type == "surface":
        if not mtl_files:
            raise ValueError("%s: no mtllib line: failed to load textures" % filename_obj)
        textures = _surface_textures(
            filename_obj, mtl_files, uvs, face_uvs, face_materials, texture_res
        )
    elif load_texture and texture_type == "vertex":
        if any(len(c) != 3 for c in colors):
            raise ValueError(
                "%s: vertex textures need a colour on every v line (v x y z r g b)" % filename_obj
            )
        textures = torch.from_numpy(np.asarray(colors, dtype=np.float32))

    if normalization:
        # SoftRas's steps and order, in float32.
        vertices -= vertices.min(0)[0][None, :]
        vertices /= torch.abs(vertices).max()
        vertices *= 2
        vertices -= vertices.max(0)[0][None, :] / 2

    if load_texture:
        return vertices, faces_t, textures
    return vertices, faces_t


def _parse_corner(token, num_positions, num_uvs):
    """``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` as (0-based vertex, 0-based vt or None)."""
    parts = token.split("/")
    v = _index(int(parts[0]), num_positions)
    vt = None
    if len(parts) > 1 and parts[1] != "":
        vt = _index(int(parts[1]), num_uvs)
    return v, vt


def _index(i, count):
    """OBJ indices are 1-based; negative ones count back from the last element so far."""
    return i - 1 if i > 0 else count + i


def load_mtl(filename_mtl):
    """The ``Kd`` colours and ``map_Kd`` file names of an MTL file, by material name.

    Returns:
        ``(colors, texture_filenames)``: dicts from material name to a float64 [3] array and to
        the image file named (options such as ``-s 1 1 1`` before the name are skipped).
    """
    texture_filenames = {}
    colors = {}
    material = ""
    with open(filename_mtl) as f:
        for line in f:
            tokens = line.split()
            if not tokens:
                continue
            if tokens[0] == "newmtl" and len(tokens) > 1:
                material = tokens[1]
            elif tokens[0] == "map_Kd" and len(tokens) > 1:
                value = line.strip()[len("map_Kd"):].strip()
                # With options the file comes last; without, the whole value (spaces and all).
                texture_filenames[material] = value.split()[-1] if value.startswith("-") else value
            elif tokens[0] == "Kd" and len(tokens) >= 4:
                colors[material] = np.array([float(v) for v in tokens[1:4]])
    return colors, texture_filenames


def _surface_textures(filename_obj, mtl_files, uvs, face_uvs, face_materials, texture_res):
    """[F, R², 3] float32 texels: white, then each material's Kd, then its sampled map_Kd."""
    obj_dir = os.path.dirname(filename_obj)
    colors, texture_files, texture_dirs = {}, {}, {}
    for name in mtl_files:
        path = os.path.join(obj_dir, name)
        if not os.path.isfile(path):
            warnings.warn("%s: material file %s not found; its faces are white"
                          % (filename_obj, path))
            continue
        mtl_colors, mtl_textures = load_mtl(path)
        colors.update(mtl_colors)
        texture_files.update(mtl_textures)
        texture_dirs.update({m: os.path.dirname(path) for m in mtl_textures})

    num_faces = len(face_materials)
    r2 = texture_res * texture_res
    textures = np.ones((num_faces, r2, 3), dtype=np.float32)
    materials = np.asarray(face_materials, dtype=object)
    for name, color in colors.items():
        textures[materials == name] = color.astype(np.float32)

    if not texture_files:
        return torch.from_numpy(textures)
    uv_table = np.asarray(uvs, dtype=np.float64).reshape(-1, 2)
    for name, file_name in texture_files.items():
        selected = np.nonzero(materials == name)[0]
        if len(selected) == 0:
            continue
        # Relative to the MTL's folder, else to the OBJ's (SoftRas's choice); usually the same.
        candidates = [os.path.join(texture_dirs[name], file_name), os.path.join(obj_dir, file_name)]
        path = next((p for p in candidates if os.path.isfile(p)), None)
        if path is None:
            warnings.warn(
                "%s: texture %s of material '%s' not found; its faces are %s"
                % (filename_obj, candidates[0], name,
                   "its Kd colour" if name in colors else "white")
            )
            continue
        # SoftRas flips the image so that v = 0 is its bottom row.
        image = read_rgb(path)[::-1]
        corner_uvs = _face_uvs(uv_table, [face_uvs[i] for i in selected])  # [n, 3, 2]
        textures[selected] = sample_face_textures(image, corner_uvs, texture_res)
    return torch.from_numpy(textures)


def _face_uvs(uv_table, face_uvs):
    """[n, 3, 2] wrapped texture coordinates of the faces' corners.

    A corner without a ``vt`` takes the last ``vt`` of the file (SoftRas reads index 0 - 1);
    coordinates outside [0, 1] repeat (SoftRas: ``uv % 1`` above 1).
    """
    if len(uv_table) == 0:
        uv_table = np.zeros((1, 2))
    index = np.array([[len(uv_table) - 1 if i is None else i for i in f] for f in face_uvs])
    uv = uv_table[np.clip(index, 0, len(uv_table) - 1)]
    outside = (uv < 0) | (uv > 1)
    return np.where(outside, uv - np.floor(uv), uv)


def texel_center_barycentrics(texture_res):
    """[R², 3] barycentrics (w0, w1, w2) of the centres of a face's R×R texels, SoftRas's order.

    Texel ``i = w_y R + w_x``: with ``w_x + w_y < R`` the lower triangle of cell (w_x, w_y),
    centred at ``((w_x + 1/3)/R, (w_y + 1/3)/R)``; else the upper triangle of cell
    ``(R-1-w_x, R-1-w_y)``, centred at ``((R-1-w_x + 2/3)/R, (R-1-w_y + 2/3)/R)``.
    """
    r = texture_res
    i = np.arange(r * r)
    w_x, w_y = i % r, i // r
    lower = w_x + w_y < r
    w0 = np.where(lower, (w_x + 1.0 / 3.0) / r, ((r - 1.0 - w_x) + 2.0 / 3.0) / r)
    w1 = np.where(lower, (w_y + 1.0 / 3.0) / r, ((r - 1.0 - w_y) + 2.0 / 3.0) / r)
    return np.stack([w0, w1, 1.0 - w0 - w1], axis=1)


def sample_face_textures(image, corner_uvs, texture_res):
    """Samples R×R texels per face from ``image`` (float [H, W, 3], row 0 at ``v = 0``).

    Each texel centre's barycentrics interpolate the corners' UVs; the image is read bilinearly
    at ``uv * (size - 1)`` with the lower texel by truncation, as SoftRas's ``load_textures``
    kernel (whose read one past the last row or column, with weight 0, is clamped here).

    Args:
        image: [H, W, 3].
        corner_uvs: [n, 3, 2].

    Returns:
        float32 [n, R², 3].
    """
    height, width = image.shape[:2]
    w = texel_center_barycentrics(texture_res)  # [R², 3]
    uv = np.einsum("tk,nkc->ntc", w, corner_uvs)  # [n, R², 2]
    pos_x = uv[..., 0] * (width - 1)
    pos_y = uv[..., 1] * (height - 1)
    x0 = pos_x.astype(np.int64)
    y0 = pos_y.astype(np.int64)
    wx1, wy1 = pos_x - x0, pos_y - y0
    wx0, wy0 = 1.0 - wx1, 1.0 - wy1

    def texel(x, y):
        return image[np.minimum(y, height - 1), np.minimum(x, width - 1)].astype(np.float64)

    color = (
        texel(x0, y0) * (wx0 * wy0)[..., None]
        + texel(x0, y0 + 1) * (wx0 * wy1)[..., None]
        + texel(x0 + 1, y0) * (wx1 * wy0)[..., None]
        + texel(x0 + 1, y0 + 1) * (wx1 * wy1)[..., None]
    )
    return color.astype(np.float32)
