"""Orthographic projection (SPEC §1)."""

import torch

__all__ = ["orthogonal"]


def orthogonal(vertices, scale):
    """Camera to screen coordinates: ``x_s = s x``, ``y_s = s y``, ``z`` kept.

    The scale matching a perspective camera at depth ``d`` with viewing angle ``a`` is
    ``1 / (d tan a)``.

    Args:
        vertices: [batch, V, 3] camera coordinates.
        scale: a number (or a tensor broadcasting against [batch, V]).
    """
    if vertices.ndimension() != 3:
        raise ValueError("vertices Tensor should have 3 dimensions")
    z = vertices[:, :, 2]
    x = vertices[:, :, 0] * scale
    y = vertices[:, :, 1] * scale
    return torch.stack((x, y, z), dim=2)
