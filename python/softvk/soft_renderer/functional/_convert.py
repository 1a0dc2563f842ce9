"""Turning the loosely typed arguments SoftRas accepts into tensors.

SoftRas's functions take colours, directions, eyes and the like as lists, tuples, numpy arrays
or tensors, and moved them with ``.cuda()``. Here they follow the tensor they are combined with:
same device, and the same floating dtype, so that float64 inputs stay float64 (numpy arrays are
float64 by default, which in SoftRas made ``matmul`` fail against float32 vertices).
"""

import numpy as np
import torch


def as_tensor(value, like):
    """``value`` (list, tuple, number, numpy array or tensor) as a tensor on ``like``'s device
    with ``like``'s dtype. Differentiable when ``value`` is a tensor."""
    if torch.is_tensor(value):
        return value.to(device=like.device, dtype=like.dtype)
    if isinstance(value, np.ndarray):
        return torch.from_numpy(value).to(device=like.device, dtype=like.dtype)
    return torch.tensor(value, dtype=like.dtype, device=like.device)


def float_dtype(tensor):
    """The floating dtype to compute in next to ``tensor``: its own if floating, else float32."""
    return tensor.dtype if tensor.is_floating_point() else torch.float32


def check_batched(name, tensor, last=3):
    """Raises ValueError unless ``tensor`` is [batch, n, last]."""
    if tensor.ndimension() != 3 or (last is not None and tensor.shape[2] != last):
        want = "[batch, n, %d]" % last if last is not None else "[batch, n, k]"
        raise ValueError("%s must be %s, got shape %s" % (name, want, tuple(tensor.shape)))
