"""Projection by a 3x4 camera matrix with Brown distortion (SoftRas's ``projection`` mode)."""

import torch

from ._convert import as_tensor

__all__ = ["projection"]


def projection(vertices, P, dist_coeffs, orig_size):
    """World to screen coordinates through a pinhole camera matrix, in pixels of an image of
    ``orig_size``, mapped to [-1, 1].

    ``(x, y, z) = P (p, 1)``; ``x' = x / (z + 1e-5)``, ``y' = y / (z + 1e-5)``; with
    ``r² = x'² + y'²`` the distorted
    ``x'' = x'(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x' y' + p2 (r² + 2 x'²)`` and
    ``y'' = y'(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y'²) + 2 p2 x' y'``; then
    ``x_s = 2 (x'' - orig_size / 2) / orig_size`` (same for y) and the depth is ``z``.

    Args:
        vertices: [batch, V, 3] world coordinates.
        P: [batch, 3, 4] projection matrices (tensor or numpy array).
        dist_coeffs: [batch, 5] distortion coefficients ``(k1, k2, p1, p2, k3)``.
        orig_size: the size in pixels of the image P maps to.

    Returns:
        [batch, V, 3].
    """
    P = as_tensor(P, vertices)
    dist_coeffs = as_tensor(dist_coeffs, vertices)
    if dist_coeffs.ndimension() == 1:
        dist_coeffs = dist_coeffs[None, :]
    homogeneous = torch.cat([vertices, torch.ones_like(vertices[:, :, :1])], dim=-1)
    projected = torch.matmul(homogeneous, P.transpose(2, 1))
    x, y, z = projected[:, :, 0], projected[:, :, 1], projected[:, :, 2]
    x_ = x / (z + 1e-5)
    y_ = y / (z + 1e-5)

    k1 = dist_coeffs[:, None, 0]
    k2 = dist_coeffs[:, None, 1]
    p1 = dist_coeffs[:, None, 2]
    p2 = dist_coeffs[:, None, 3]
    k3 = dist_coeffs[:, None, 4]

    r2 = x_ ** 2 + y_ ** 2
    radial = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    x__ = x_ * radial + 2 * p1 * x_ * y_ + p2 * (r2 + 2 * x_ ** 2)
    y__ = y_ * radial + p1 * (r2 + 2 * y_ ** 2) + 2 * p2 * x_ * y_
    x__ = 2 * (x__ - orig_size / 2.0) / orig_size
    y__ = 2 * (y__ - orig_size / 2.0) / orig_size
    return torch.stack([x__, y__, z], dim=-1)
