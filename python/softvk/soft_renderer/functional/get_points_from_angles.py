"""Camera positions from distance, elevation and azimuth (SPEC §1)."""

import math
import numbers

import torch

__all__ = ["get_points_from_angles"]


def get_points_from_angles(distance, elevation, azimuth, degrees=True):
    """The eye ``(d cos(el) sin(az), d sin(el), -d cos(el) cos(az))``.

    With three numbers (Python or numpy scalars) it returns a tuple of three floats, as SoftRas
    does. Otherwise the arguments are broadcast as tensors (numbers and arrays are converted to
    the tensors' dtype, float32 if none is a tensor) and it returns [N, 3] for 1-D inputs, one
    row per view, differentiable in all three.

    Args:
        distance: distance from the origin.
        elevation: angle above the x-z plane.
        azimuth: angle about +y, 0 looking along +z from -z.
        degrees: angles in degrees (default) rather than radians.
    """
    args = (distance, elevation, azimuth)
    if all(isinstance(a, numbers.Real) for a in args):
        if degrees:
            elevation = math.radians(elevation)
            azimuth = math.radians(azimuth)
        return (
            distance * math.cos(elevation) * math.sin(azimuth),
            distance * math.sin(elevation),
            -distance * math.cos(elevation) * math.cos(azimuth),
        )

    like = next((a for a in args if torch.is_tensor(a) and a.is_floating_point()), None)
    device = next((a.device for a in args if torch.is_tensor(a)), None)
    dtype = like.dtype if like is not None else torch.float32
    distance, elevation, azimuth = (
        torch.as_tensor(a, dtype=dtype, device=device) for a in args
    )
    if degrees:
        elevation = elevation * (math.pi / 180.0)
        azimuth = azimuth * (math.pi / 180.0)
    return torch.stack(
        [
            distance * torch.cos(elevation) * torch.sin(azimuth),
            distance * torch.sin(elevation),
            -distance * torch.cos(elevation) * torch.cos(azimuth),
        ],
        dim=-1,
    )
