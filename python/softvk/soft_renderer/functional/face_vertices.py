"""Per-face gathering of per-vertex attributes."""

import torch

from ... import _checks
from ._convert import check_batched

__all__ = ["face_vertices"]


def face_vertices(vertices, faces):
    """The three corners of every face.

    Args:
        vertices: [batch, V, 3] positions (or any per-vertex 3-vector, such as colours).
        faces: [batch, F, 3] vertex indices (any integer dtype), each within its own mesh's
            vertices (else ``ValueError``; float indices: ``TypeError``).

    Returns:
        [batch, F, 3, 3]: ``out[b, f, k] = vertices[b, faces[b, f, k]]``; differentiable in
        ``vertices``.
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
    # One flat gather over the whole batch: face indices offset by each mesh's first vertex.
    offsets = torch.arange(bs, device=vertices.device) * nv
    index = faces.to(device=vertices.device, dtype=torch.long) + offsets[:, None, None]
    return vertices.reshape(bs * nv, 3)[index]
