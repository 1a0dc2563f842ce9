"""Directional light (SPEC §2, lighting)."""

import torch
import torch.nn.functional as F

from ... import _checks
from ._convert import as_tensor

__all__ = ["directional_lighting"]


def directional_lighting(light, normals, light_intensity=0.5, light_color=(1, 1, 1),
                         light_direction=(0, 1, 0)):
    """Adds ``I_l c_l max(0, n . d_l)`` to ``light`` in place and returns it, as SoftRas.

    ``d_l`` points towards the light and is used as given (not normalized), as SoftRas.

    Args:
        light: [batch, N, 3] accumulated light.
        normals: [batch, N, 3] unit normals (per face or per vertex).
        light_intensity: a number (or a tensor broadcasting against [batch, 1, 1]).
        light_color: [3] or [batch, 3].
        light_direction: [3] or [batch, 3].

    Returns:
        ``light``.
    """
    _checks.finite("light_intensity", light_intensity)
    light_color = as_tensor(light_color, light)
    light_direction = as_tensor(light_direction, light)
    _checks.finite("light_color", light_color)
    _checks.finite("light_direction", light_direction)
    if light_color.ndimension() == 1:
        light_color = light_color[None, :]
    if light_direction.ndimension() == 1:
        light_direction = light_direction[None, :]
    cosine = F.relu(torch.sum(normals * light_direction[:, None, :], dim=2))
    light += light_intensity * (light_color[:, None, :] * cosine[:, :, None])
    return light
