"""The checks of what Python hands softvk, each written once.

``softvk.torch``, ``softvk.soft_renderer`` (its engine path and its composed steps) and
``softvk.pytorch3d`` call these, so that one bad input gets one error, whichever path, dtype or
interface it takes: a ``TypeError`` for a value of the wrong kind, a ``ValueError`` for one out
of its range, each naming the argument and what is wrong with it.
"""

import operator

import numpy as np
import torch

# The largest image side the engine renders (softvk::raster::settings::MAX_IMAGE_SIDE).
MAX_IMAGE_SIDE = 16384


def image_size(value, factor=1, name="image_size"):
    """``(height, width)`` times ``factor`` (2 for anti-aliasing) from ``value``: an int (a
    square, as SoftRas) or a ``(height, width)`` pair of ints, each side in
    ``[1, MAX_IMAGE_SIDE / factor]``. Not ints (floats, strings, bools): ``TypeError``, as
    SoftRas's C++ binding refuses them; sides out of range or not two of them: ``ValueError``."""
    pair = tuple(value) if isinstance(value, (tuple, list)) else (value, value)
    if len(pair) != 2:
        raise ValueError(
            f"softvk: {name} must be an int or a (height, width) pair, got {value!r}"
        )
    sides = []
    for side in pair:
        try:
            if isinstance(side, (bool, np.bool_)):
                raise TypeError
            sides.append(operator.index(side))
        except TypeError:
            raise TypeError(
                f"softvk: {name} must be an int or a (height, width) pair of ints, got {value!r}"
            ) from None
    most = MAX_IMAGE_SIDE // factor
    if not all(1 <= s <= most for s in sides):
        aliasing = " (anti_aliasing renders twice that)" if factor > 1 else ""
        raise ValueError(
            f"softvk: {name} must be between 1 and {most} pixels a side{aliasing}, got {value!r}"
        )
    return sides[0] * factor, sides[1] * factor


def finite(name, value):
    """``ValueError`` unless every value of ``value`` (a tensor on any device, a numpy array,
    a number, or a list of numbers) is finite."""
    if isinstance(value, torch.Tensor):
        if not (value.is_floating_point() or value.is_complex()):
            return
        bad = ~torch.isfinite(value.detach())
        if not bool(bad.any()):
            return
        at = tuple(int(i) for i in bad.nonzero()[0])
        raise ValueError(
            f"softvk: {name} has a value that is not finite: {float(value[at])} at {list(at)}"
        )
    array = np.asarray(value, dtype=np.float64)
    bad = ~np.isfinite(array)
    if bad.any():
        at = [int(i) for i in np.argwhere(bad)[0]]
        raise ValueError(
            f"softvk: {name} has a value that is not finite: {array[tuple(at)]} at {at}"
        )


def integer_faces(name, faces):
    """``TypeError`` unless ``faces`` (a tensor or a numpy array) holds integers: float indices
    would be truncated, bools would mask."""
    if isinstance(faces, np.ndarray):
        if not np.issubdtype(faces.dtype, np.integer):
            raise TypeError(f"softvk: {name} must be an integer array, got {faces.dtype}")
        return
    if not isinstance(faces, torch.Tensor):
        raise TypeError(f"softvk: {name} must be an integer tensor, got {type(faces).__name__}")
    if faces.dtype == torch.bool or faces.is_floating_point() or faces.is_complex():
        raise TypeError(f"softvk: {name} must be an integer tensor, got {faces.dtype}")


def face_indices(name, faces, vertices, meshes=None):
    """Integer ``faces`` (``[F, 3]``, or ``[B, F, 3]`` one set a mesh) whose every index names a
    vertex of its own mesh, in that mesh's numbering: ``0 <= i < vertices``. ``vertices`` is an
    int (every mesh's count), or a tensor of ``faces.shape[:-1]`` (each face's mesh's count,
    for packed meshes of different sizes, ``meshes`` then saying which mesh each face is of).

    A negative index would count from the end and one past a mesh's vertices would read the
    next mesh's in a batch (the composed steps gather from all the batch's vertices at once):
    ``ValueError``, on every path, before anything is rendered."""
    integer_faces(name, faces)
    if faces.numel() == 0:
        return
    limit = vertices if isinstance(vertices, int) else vertices[..., None]
    bad = (faces < 0) | (faces >= limit)
    if not bool(bad.any()):
        return
    at = tuple(int(i) for i in bad.nonzero()[0])
    index = int(faces[at])
    count = vertices if isinstance(vertices, int) else int(vertices[at[:-1]])
    where = f"face {at[-2]}, corner {at[-1]}"
    if faces.dim() == 3:
        where = f"mesh {at[0]}, " + where
    elif meshes is not None:
        where += f", of mesh {int(meshes[at[0]])} (in its own numbering)"
    raise ValueError(
        f"softvk: {name} has index {index} ({where}), outside the {count} vertices of its mesh"
    )
