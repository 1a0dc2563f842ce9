"""The look-at camera transformation (SPEC §1)."""

import torch
import torch.nn.functional as F

from ._convert import as_tensor

__all__ = ["look_at"]


def _batched(vector, batch_size):
    """[3] -> [batch_size, 3]; [N, 3] is kept (it broadcasts against the vertices' batch)."""
    if vector.ndimension() == 1:
        return vector[None, :].expand(batch_size, 3)
    return vector


def look_at(vertices, eye, at=[0, 0, 0], up=[0, 1, 0]):
    """World to camera coordinates for a camera at ``eye`` looking at ``at``.

    ``z = normalize(at - eye)``, ``x = normalize(cross(up, z))``, ``y = normalize(cross(z, x))``
    (``eps = 1e-5``); ``p_c = R (p - eye)`` with rows x, y, z. The camera looks along +z and
    ``p_c.z`` is the depth.

    Args:
        vertices: [batch, V, 3].
        eye, at, up: [3] or [batch, 3] (list, tuple, numpy array or tensor); they take the
            vertices' device and dtype. A tensor ``eye`` is differentiable.

    Returns:
        [batch, V, 3] camera coordinates.
    """
    if vertices.ndimension() != 3:
        raise ValueError("vertices Tensor should have 3 dimensions")
    batch_size = vertices.shape[0]
    eye = _batched(as_tensor(eye, vertices), batch_size)
    at = _batched(as_tensor(at, vertices), batch_size)
    up = _batched(as_tensor(up, vertices), batch_size)

    # eps as SoftRas (chosen there to match the chainer Neural Renderer).
    z_axis = F.normalize(at - eye, eps=1e-5, dim=-1)
    x_axis = F.normalize(torch.cross(up.expand_as(z_axis), z_axis, dim=-1), eps=1e-5, dim=-1)
    y_axis = F.normalize(torch.cross(z_axis, x_axis, dim=-1), eps=1e-5, dim=-1)
    rotation = torch.stack((x_axis, y_axis, z_axis), dim=1)  # [batch, 3, 3], rows x, y, z

    return torch.matmul(vertices - eye[:, None, :], rotation.transpose(1, 2))
