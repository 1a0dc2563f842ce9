"""Ambient light (SPEC §2, lighting)."""

from ... import _checks
from ._convert import as_tensor

__all__ = ["ambient_lighting"]


def ambient_lighting(light, light_intensity=0.5, light_color=(1, 1, 1)):
    """Adds ``I_a c_a`` to ``light`` in place and returns it, as SoftRas.

    Args:
        light: [batch, N, 3] accumulated light (per face or per vertex).
        light_intensity: a number (or a tensor broadcasting against [batch, 1, 1]).
        light_color: [3] or [batch, 3].

    Returns:
        ``light``.
    """
    _checks.finite("light_intensity", light_intensity)
    light_color = as_tensor(light_color, light)
    _checks.finite("light_color", light_color)
    if light_color.ndimension() == 1:
        light_color = light_color[None, :]
    light += light_intensity * light_color[:, None, :]
    return light
