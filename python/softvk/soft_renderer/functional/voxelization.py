"""Voxelization of triangle meshes: surface voxels plus the filled interior.

SoftRas does this with four CUDA kernels (``voxelize_sub1`` .. ``voxelize_sub4``); this is the
same computation with torch on the CPU, returned on the input's device:

1. ``sub1``, once per axis: each integer grid point of the plane across that axis that a face
   covers marks the cell at the face's depth there, and the three cells before it in the plane
   (the four cells that share the grid point);
2. ``sub2``: the cell of each face corner;
3. ``sub3`` / ``sub4``: empty cells on the grid's border are outside; outside spreads to the six
   neighbours of empty cells until it stops; everything not outside is the result.

Grid point ``y`` of the sub1 pass is the cell boundary between cells ``y - 1`` and ``y``, so a
mesh whose vertices lie at half-integers (as the ``* (size - 1) / size + 0.5`` normalization
SoftRas's callers use gives) fills exactly the cells it spans.
"""

import torch

__all__ = ["voxelization"]

# Upper bound on the (face, grid point) candidates tested at once, to bound memory.
_CHUNK = 1 << 22


def voxelization(faces, size, normalize=False):
    """Occupancy of the mesh given by its face vertices.

    Args:
        faces: [batch, F, 3, 3] face vertices (as ``face_vertices`` returns). Coordinate k of a
            vertex indexes axis k of the voxel grid.
        size: voxels per side.
        normalize: as SoftRas, ``False`` (the default) means the coordinates are in [0, 1] and
            are multiplied by ``size``; ``True`` means they are already in voxel units.

    Returns:
        int32 [batch, size, size, size], 1 for the surface and the inside; on ``faces``'s device.
        Not differentiable.
    """
    if faces.ndimension() != 4 or faces.shape[2:] != (3, 3):
        raise ValueError("faces must be [batch, F, 3, 3], got shape %s" % (tuple(faces.shape),))
    device = faces.device
    faces = faces.detach().to("cpu")
    if not faces.is_floating_point():
        faces = faces.float()
    if not normalize:
        faces = faces * size

    # sub1 along each axis: the depth axis last, the result transposed back to (0, 1, 2) order.
    voxels = _project(faces[..., [2, 1, 0]], size).transpose(1, 3)
    voxels |= _project(faces[..., [0, 2, 1]], size).transpose(2, 3)
    voxels |= _project(faces, size)
    voxels |= _corners(faces, size)
    return _fill(voxels).to(device=device, dtype=torch.int32)


def _project(faces, size):
    """``voxelize_sub1``: grid points (a, b) inside a face's projection on axes (0, 1) mark the
    cells (a - da, b - db, floor(depth)), da, db in {0, 1}."""
    bs, nf = faces.shape[:2]
    voxels = torch.zeros(bs, size, size, size, dtype=torch.bool)
    flat = faces.reshape(bs * nf, 3, 3)
    p0, p1, p2 = flat[:, 0], flat[:, 1], flat[:, 2]
    # Candidate grid points: the integer points of each face's bounding box within the grid,
    # grown by one so that rounding in the inside test decides at the box's edges too.
    low = (torch.ceil(torch.minimum(torch.minimum(p0, p1), p2)[:, :2]) - 1).clamp(0, size - 1)
    high = (torch.floor(torch.maximum(torch.maximum(p0, p1), p2)[:, :2]) + 1).clamp(-1, size - 1)
    counts = (high - low + 1).clamp(min=0).long()
    per_face = counts[:, 0] * counts[:, 1]
    keep = torch.nonzero(per_face > 0).flatten()
    if len(keep) == 0:
        return voxels

    # Chunks of faces with at most _CHUNK candidates each (a bigger face goes alone).
    cumulative = torch.cumsum(per_face[keep], 0)
    start = 0
    while start < len(keep):
        base = cumulative[start - 1] if start > 0 else 0
        end = int(torch.searchsorted(cumulative, base + _CHUNK, right=True))
        end = max(end, start + 1)
        _project_chunk(voxels, flat, keep[start:end], low, counts, per_face, nf, size)
        start = end
    return voxels


def _project_chunk(voxels, flat, faces_idx, low, counts, per_face, nf, size):
    n = per_face[faces_idx]
    face = torch.repeat_interleave(faces_idx, n)
    # Position of each candidate within its face's box, row-major over (a, b).
    first = torch.cumsum(n, 0) - n
    local = torch.arange(int(n.sum())) - torch.repeat_interleave(first, n)
    nb = counts[face, 1]
    a = low[face, 0].long() + local // nb
    b = low[face, 1].long() + local % nb

    f = flat[face]
    dtype = f.dtype
    # The kernel's arithmetic, in the faces' dtype and its order.
    a1d = f[:, 1, 0] - f[:, 0, 0]
    b1d = f[:, 1, 1] - f[:, 0, 1]
    z1d = f[:, 1, 2] - f[:, 0, 2]
    a2d = f[:, 2, 0] - f[:, 0, 0]
    b2d = f[:, 2, 1] - f[:, 0, 1]
    z2d = f[:, 2, 2] - f[:, 0, 2]
    apd = a.to(dtype) - f[:, 0, 0]
    bpd = b.to(dtype) - f[:, 0, 1]
    det = b1d * a2d - b2d * a1d
    ok = det != 0
    safe = torch.where(ok, det, torch.ones_like(det))
    t1 = (a2d * bpd - b2d * apd) / safe
    t2 = (-a1d * bpd + b1d * apd) / safe
    ok &= (t1 >= 0) & (t2 >= 0) & (t1 + t2 <= 1)
    depth = torch.floor(t1 * z1d + t2 * z2d + f[:, 0, 2])
    ok &= (depth >= 0) & (depth < size)
    batch = face[ok] // nf
    a, b, depth = a[ok], b[ok], depth[ok].long()
    for da in (0, 1):
        for db in (0, 1):
            ai, bi = a - da, b - db
            inside = (ai >= 0) & (bi >= 0)
            voxels[batch[inside], ai[inside], bi[inside], depth[inside]] = True


def _corners(faces, size):
    """``voxelize_sub2``: the cell holding each face corner."""
    bs = faces.shape[0]
    voxels = torch.zeros(bs, size, size, size, dtype=torch.bool)
    cells = torch.floor(faces).long().reshape(bs, -1, 3)
    batch = torch.arange(bs)[:, None].expand(bs, cells.shape[1]).reshape(-1)
    cells = cells.reshape(-1, 3)
    inside = ((cells >= 0) & (cells < size)).all(dim=1)
    cells, batch = cells[inside], batch[inside]
    voxels[batch, cells[:, 0], cells[:, 1], cells[:, 2]] = True
    return voxels


def _fill(surface):
    """``voxelize_sub3``/``sub4``: cells not reachable from the border through empty cells
    (6-neighbourhood)."""
    empty = ~surface
    outside = torch.zeros_like(surface)
    outside[:, 0] = empty[:, 0]
    outside[:, -1] = empty[:, -1]
    outside[:, :, 0] = empty[:, :, 0]
    outside[:, :, -1] = empty[:, :, -1]
    outside[:, :, :, 0] = empty[:, :, :, 0]
    outside[:, :, :, -1] = empty[:, :, :, -1]
    while True:
        # A cell becomes outside when empty and next to an outside cell: a 3x3x3 cross dilation.
        grown = outside.clone()
        grown[:, 1:] |= outside[:, :-1]
        grown[:, :-1] |= outside[:, 1:]
        grown[:, :, 1:] |= outside[:, :, :-1]
        grown[:, :, :-1] |= outside[:, :, 1:]
        grown[:, :, :, 1:] |= outside[:, :, :, :-1]
        grown[:, :, :, :-1] |= outside[:, :, :, 1:]
        grown &= empty
        if torch.equal(grown, outside):
            return ~outside
        outside = grown
