"""The "look" camera transformation: a camera at ``eye`` looking along a direction."""

import torch
import torch.nn.functional as F

from ._convert import as_tensor

__all__ = ["look"]


def look(vertices, eye, direction=[0, 1, 0], up=None):
    """World to camera coordinates for a camera at ``eye`` looking along ``direction``.

    ``z = normalize(direction)``, ``x = normalize(cross(up, z))``, ``y = normalize(cross(z, x))``
    (``eps = 1e-5``); ``p_c = R (p - eye)`` with rows x, y, z.

    Args:
        vertices: [batch, V, 3].
        eye, direction: [3] or [batch, 3] (list, tuple, numpy array or tensor).
        up: [3] or [batch, 3]; ``None`` (the default) is +y. SoftRas's default ``None`` made
            this function fail; +y is what its ``look_at`` uses.

    Returns:
        [batch, V, 3] camera coordinates.
    """
    if vertices.ndimension() != 3:
        raise ValueError("vertices Tensor should have 3 dimensions")
    if up is None:
        up = [0, 1, 0]
    eye = as_tensor(eye, vertices)
    direction = as_tensor(direction, vertices)
    up = as_tensor(up, vertices)
    if eye.ndimension() == 1:
        eye = eye[None, :]
    if direction.ndimension() == 1:
        direction = direction[None, :]
    if up.ndimension() == 1:
        up = up[None, :]

    z_axis = F.normalize(direction, eps=1e-5, dim=-1)
    up, z_axis = torch.broadcast_tensors(up, z_axis)
    x_axis = F.normalize(torch.cross(up, z_axis, dim=-1), eps=1e-5, dim=-1)
    y_axis = F.normalize(torch.cross(z_axis, x_axis, dim=-1), eps=1e-5, dim=-1)
    rotation = torch.stack((x_axis, y_axis, z_axis), dim=1)

    return torch.matmul(vertices - eye[:, None, :], rotation.transpose(1, 2))
