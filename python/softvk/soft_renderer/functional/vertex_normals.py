"""Vertex normals (SPEC §1): the normalized sum of the incident faces' un-normalized normals."""

import torch
import torch.nn.functional as F

from ... import _checks
from ._convert import check_batched

__all__ = ["vertex_normals"]


def vertex_normals(vertices, faces):
    """Area-weighted vertex normals.

    Each face adds its un-normalized normal ``cross(v2 - v1, v0 - v1)`` (twice its area, pointing
    to the side the face is seen from) to its three vertices; the sums are normalized with
    ``eps = 1e-6`` (a vertex no face uses gets the zero vector).

    Args:
        vertices: [batch, V, 3].
        faces: [batch, F, 3] integer indices, each within its own mesh's vertices (else
            ``ValueError``; float indices: ``TypeError``).

    Returns:
        [batch, V, 3], differentiable in ``vertices``.
    """
    check_batched("vertices", vertices)
    check_batched("faces", faces)
    if vertices.shape[0] != faces.shape[0]:
        raise ValueError(
            "vertices and faces have different batch sizes (%d and %d)"
            % (vertices.shape[0], faces.shape[0])
        )
    bs, nv = vertices.shape[:2]
    # Each face's indices within its own mesh's vertices: the gather below spans the batch.
    _checks.face_indices("faces", faces, int(nv))
    offsets = torch.arange(bs, device=vertices.device) * nv
    index = faces.to(device=vertices.device, dtype=torch.long) + offsets[:, None, None]
    index = index.reshape(-1, 3)
    corners = vertices.reshape(bs * nv, 3)[index]  # [bs * F, 3, 3]
    v0, v1, v2 = corners[:, 0], corners[:, 1], corners[:, 2]

    # As SoftRas: each corner gets the cross product of its two outgoing edges, which is the same
    # face normal for all three corners (up to rounding).
    normals = torch.zeros(bs * nv, 3, dtype=vertices.dtype, device=vertices.device)
    normals = normals.index_add(0, index[:, 1], torch.cross(v2 - v1, v0 - v1, dim=-1))
    normals = normals.index_add(0, index[:, 2], torch.cross(v0 - v2, v1 - v2, dim=-1))
    normals = normals.index_add(0, index[:, 0], torch.cross(v1 - v0, v2 - v0, dim=-1))
    return F.normalize(normals, eps=1e-6, dim=1).reshape(bs, nv, 3)
