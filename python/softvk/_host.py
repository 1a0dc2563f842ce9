"""The one round trip between torch tensors and the engine.

The engine reads and writes host memory. Every call into it from ``softvk.torch``,
``softvk.soft_renderer``, ``softvk.pytorch3d`` and ``softvk.nvdiffrast.torch`` goes through
:func:`round_trip`, which hands it host copies of its tensor arguments and brings what it
returns (images, fragments, gradients) back to the device and dtype each result belongs to. So
tensors on any device work, CUDA's included, through these copies; on the CPU the copies are
views wherever the tensor is already C-contiguous. Nothing else in the package moves a tensor
between the host and a device for the engine (``python/tests/test_cuda.py`` checks).
"""

from collections import namedtuple

import numpy as np
import torch

__all__ = ["Like", "like", "round_trip"]

Like = namedtuple("Like", ["device", "dtype", "shape"])
Like.__doc__ = """Where a result of the engine goes: onto ``device``, as ``dtype`` (``None``:
the engine's own) and, unless ``None``, in ``shape`` (a gradient takes its input's). An
autograd context keeps these rather than the tensors themselves."""


def like(tensor, dtype=True):
    """A tensor's device, dtype and shape, as a gradient of it must have them; with
    ``dtype=False`` its device alone (the engine's dtype kept, as for integer fragments)."""
    return Like(tensor.device, tensor.dtype if dtype else None,
                tuple(tensor.shape) if dtype else None)


def round_trip(call, *args, back=None):
    """``call(*args)``, run on the host, with its results brought back.

    Each tensor among ``args`` (also inside a list or a tuple) is passed as a C-contiguous
    numpy array of its own dtype, detached from autograd; anything else (settings, handles,
    numpy arrays) as it is. ``back`` says where each result goes: for one result, one entry;
    for a tuple of results, a tuple of entries (missing ones are ``None``). An entry is
    ``None`` (the result returned as it is: a handle, a flag, a gradient not asked for), a
    tensor or a :class:`Like` (the numpy array as a tensor on that device, with that dtype and
    shape), or a list of them (a list of arrays, each brought back as its entry says)."""

    def host(value):
        if isinstance(value, torch.Tensor):
            return np.ascontiguousarray(value.detach().cpu().numpy())
        if isinstance(value, (list, tuple)) and any(isinstance(v, torch.Tensor) for v in value):
            return type(value)(host(v) for v in value)
        return value

    def bring(result, to):
        if to is None or result is None:
            return result
        if isinstance(to, list) or (isinstance(to, tuple) and not isinstance(to, Like)):
            entries = list(to) + [None] * (len(result) - len(to))
            return type(result)(bring(r, t) for r, t in zip(result, entries))
        if isinstance(to, torch.Tensor):
            to = Like(to.device, to.dtype, None)
        out = torch.from_numpy(result)
        if to.shape is not None:
            out = out.reshape(to.shape)
        return out.to(device=to.device, dtype=to.dtype)

    return bring(call(*(host(a) for a in args)), back)
