"""Perspective projection (SPEC §1)."""

import math

import torch

__all__ = ["perspective"]


def perspective(vertices, angle=30.0):
    """Camera to screen coordinates: ``x_s = x / (z tan a)``, ``y_s = y / (z tan a)``, ``z`` kept.

    Args:
        vertices: [batch, V, 3] camera coordinates.
        angle: half the field of view, in degrees (a number, or a [batch] tensor).

    Returns:
        [batch, V, 3] screen coordinates (x, y in [-1, 1] across the image) and depth.
    """
    if vertices.ndimension() != 3:
        raise ValueError("vertices Tensor should have 3 dimensions")
    if torch.is_tensor(angle):
        radians = angle.to(device=vertices.device, dtype=vertices.dtype) * (math.pi / 180)
    else:
        radians = torch.tensor(angle / 180 * math.pi, dtype=vertices.dtype, device=vertices.device)
    # tan in the vertices' dtype, as SoftRas (float32 there).
    width = torch.tan(radians).reshape(-1, 1)
    z = vertices[:, :, 2]
    x = vertices[:, :, 0] / z / width
    y = vertices[:, :, 1] / z / width
    return torch.stack((x, y, z), dim=2)
