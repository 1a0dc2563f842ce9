"""nvdiffrast's PyTorch interface on softvk: change one import.

    import softvk.nvdiffrast.torch as dr     # was: import nvdiffrast.torch as dr

The same names, arguments, defaults, shapes, dtypes and return values as ``nvdiffrast.torch``:
``RasterizeCudaContext``, ``RasterizeGLContext``, ``rasterize``, ``DepthPeeler``,
``interpolate``, ``antialias``, ``antialias_construct_topology_hash``, ``texture``,
``texture_construct_mip``, ``get_log_level`` and ``set_log_level``, each differentiable as
nvdiffrast's (``rasterize`` to ``pos`` through ``u, v`` and, with ``grad_db``, ``rast_db``;
``interpolate`` to ``attr``, ``rast`` and ``rast_db``; ``antialias`` to ``color`` and ``pos``).
The pixel conventions are nvdiffrast's: clip-space ``(x, y, z, w)`` positions, outputs
``[minibatch, height, width, channels]`` with row 0 at the bottom (NDC y = -1), ``rast`` =
``(u, v, z/w, triangle id + 1)`` and zero where nothing is drawn.

What softvk does differently, and only this:

- **Where it runs**: on softvk's Vulkan device (any GPU, or lavapipe on a CPU); no CUDA, no
  OpenGL. Tensors may live on any device: the engine reads host copies, and the results come
  back on the device of the inputs (``softvk._host.round_trip``). A context is a handle of
  softvk's one engine per process (opened when the first context is made); ``device`` is
  accepted and recorded, nothing more.
- **Inputs are checked before anything runs**, one clear error each: a wrong dtype raises
  ``TypeError``, a wrong shape or value ``ValueError`` (both also ``RuntimeError``, what
  nvdiffrast's own checks raise). softvk also refuses what nvdiffrast leaves undefined:
  triangle indices outside the vertices, ranges past the triangles, ``diff_attrs`` entries
  outside the attributes, NaN or infinite positions. Inputs need not be contiguous.
- ``diff_attrs`` takes negative indices, counted from the last attribute as in Python, and any
  number of them (nvdiffrast: up to 32).
- **Depth peeling** returns both of two surfaces at exactly the same depth, one layer after the
  other (nvdiffrast loses the second). Surfaces within one rounding step of each other in
  depth may be ordered otherwise than nvdiffrast's fixed-point depth buffer orders them.
- **Coverage** of a triangle crossing the near or far plane is that of its clipped part, tested
  at pixel centres without snapping the clipped pieces (nvdiffrast snaps them to its 1/16-pixel
  grid): an edge shared with a snapped neighbour can leave or double a pixel within 1/32 pixel.
- **Gradients** are the exact derivative of the forward for fixed visibility, also where
  ``u, v`` are clamped (nvdiffrast ignores the clamps and adds 1e-6 to the area; the two agree
  wherever the barycentrics are in range). Sums run in a fixed order, with no float atomics:
  the same bits on every run.
- ``RasterizeGLContext(output_db=False)`` returns an empty ``rast_db`` ``[B, H, W, 0]`` and
  propagates no ``rast_db`` gradient, as nvdiffrast's OpenGL rasterizer did; it warns of no
  deprecation, and ``set_context()`` / ``release_context()`` do nothing (there is no OpenGL
  context to make current).
- ``texture`` and ``texture_construct_mip`` take 2D textures; cube maps
  (``boundary_mode='cube'``) are not there yet and raise ``NotImplementedError``. NaN or
  infinite textures, coordinates, derivatives and biases are refused (nvdiffrast reads them).
- The log level is kept (``get_log_level`` returns what ``set_log_level`` set, 1 at first);
  softvk has no messages of its own to print at any level.
"""

import operator

import numpy as np
import torch

from .. import _native
from .._host import like, round_trip

__all__ = [
    "RasterizeCudaContext",
    "get_log_level",
    "set_log_level",
    "rasterize",
    "DepthPeeler",
    "interpolate",
    "texture",
    "texture_construct_mip",
    "antialias",
    "antialias_construct_topology_hash",
    "RasterizeGLContext",
]

# The largest image side softvk rasterizes (softvk::raster::hard::MAX_SIZE).
_MAX_SIZE = 1 << 15


class InputTypeError(TypeError, RuntimeError):
    """An input of the wrong type or dtype: a ``TypeError``, and a ``RuntimeError`` as
    nvdiffrast's checks raise."""


class InputValueError(ValueError, RuntimeError):
    """An input of the wrong shape, device or value: a ``ValueError``, and a ``RuntimeError``
    as nvdiffrast's checks raise."""


def _type_error(what, message):
    return InputTypeError(f"softvk.nvdiffrast: {what}: {message}")


def _value_error(what, message):
    return InputValueError(f"softvk.nvdiffrast: {what}: {message}")


# ---------------------------------------------------------------------------------------------
# Log level.

_log_level = 1


def get_log_level():
    """The log level ``set_log_level`` last set (1, warnings, at first)."""
    return _log_level


def set_log_level(level):
    """Sets the log level, on nvdiffrast's scale (0 info, 1 warning, 2 error, 3 fatal: messages
    of that severity and above are shown). softvk keeps the value; it has no messages of its
    own."""
    global _log_level
    if isinstance(level, bool):
        raise _type_error("set_log_level", f"level must be an integer, got {level!r}")
    try:
        _log_level = operator.index(level)
    except TypeError:
        raise _type_error("set_log_level", f"level must be an integer, got {level!r}") from None


# ---------------------------------------------------------------------------------------------
# Contexts.


class RasterizeCudaContext:
    """A rasterizer context: in softvk, a handle of the process's one engine on its Vulkan
    device, which this opens if need be. ``device`` (a ``torch.device``, a string such as
    ``'cuda:1'``, or an int) is accepted and kept as ``self.device``; softvk renders tensors
    of any device."""

    def __init__(self, device=None):
        self.device = device
        self.output_db = True
        # The DepthPeeler using this context, if any (one at a time, as nvdiffrast).
        self.active_depth_peeler = None
        # Opens the engine now, so a missing Vulkan device is reported here.
        self.device_name = _native.device_name()


class RasterizeGLContext(RasterizeCudaContext):
    """nvdiffrast's OpenGL context, on softvk's engine like ``RasterizeCudaContext``.
    ``output_db=False``: ``rasterize`` returns an empty ``rast_db`` ``[B, H, W, 0]`` and passes
    no gradient through it. ``mode`` is ``'automatic'`` or ``'manual'``; there is no OpenGL
    context to make current, so ``set_context`` and ``release_context`` do nothing."""

    def __init__(self, output_db=True, mode="automatic", device=None):
        if output_db is not True and output_db is not False:
            raise _type_error(
                "RasterizeGLContext", f"output_db must be True or False, got {output_db!r}"
            )
        if mode not in ("automatic", "manual"):
            raise _value_error(
                "RasterizeGLContext", f"mode must be 'automatic' or 'manual', got {mode!r}"
            )
        super().__init__(device=device)
        self.output_db = output_db
        self.mode = mode

    def set_context(self):
        """Does nothing: softvk has no OpenGL context to make current."""

    def release_context(self):
        """Does nothing: softvk has no OpenGL context to release."""


# ---------------------------------------------------------------------------------------------
# Checks (on the tensors' own device; the engine's host copies are ``round_trip``'s).


def _back(tensor):
    """Where a result of the engine goes: onto ``tensor``'s device (the engine's dtype kept)."""
    return like(tensor, dtype=False)


def _tensor(what, name, value, dtype):
    """``value`` must be a tensor of ``dtype``."""
    if not isinstance(value, torch.Tensor):
        raise _type_error(what, f"{name} must be a torch.Tensor, got {type(value).__name__}")
    if value.dtype != dtype:
        raise _type_error(what, f"{name} must be a {dtype} tensor, got {value.dtype}")


def _same_device(what, **tensors):
    devices = {name: t.device for name, t in tensors.items() if t is not None}
    if len(set(devices.values())) > 1:
        names = ", ".join(f"{n} on {d}" for n, d in devices.items())
        raise _value_error(what, f"the inputs must be on one device, got {names}")


def _shape_error(what, name, tensor, expected):
    return _value_error(what, f"{name} must have shape {expected}, got {list(tensor.shape)}")


def _positive(shape):
    return all(int(s) > 0 for s in shape)


def _triangles(what, tri, vertices, vertices_of):
    """``tri`` ``[>0, 3]`` int32 with every index in ``0..vertices``."""
    _tensor(what, "tri", tri, torch.int32)
    if tri.dim() != 2 or tri.shape[0] == 0 or tri.shape[1] != 3:
        raise _shape_error(what, "tri", tri, "[>0, 3]")
    low, high = int(tri.min()), int(tri.max())
    if low < 0 or high >= vertices:
        bad = low if low < 0 else high
        t = int(((tri < 0) | (tri >= vertices)).any(dim=1).nonzero()[0, 0])
        raise _value_error(
            what,
            f"triangle {t} has vertex index {bad}, outside the {vertices} vertices of "
            f"{vertices_of}",
        )


def _finite_positions(what, pos):
    """Every coordinate of ``pos`` (positions ``[..., 4]``) must be finite."""
    flat = pos.detach().reshape(-1)
    finite = torch.isfinite(flat)
    if not bool(finite.all()):
        i = int((~finite).nonzero()[0, 0])
        raise _value_error(
            what,
            f"pos has a coordinate that is not finite: {float(flat[i])} at vertex "
            f"{i // 4} (flattened), coordinate {i % 4}",
        )


def _resolution(what, resolution):
    """``(height, width)``, positive ints."""
    try:
        pair = tuple(resolution)
    except TypeError:
        raise _type_error(
            what, f"resolution must be a (height, width) pair of ints, got {resolution!r}"
        ) from None
    if len(pair) != 2:
        raise _value_error(
            what, f"resolution must be a (height, width) pair, got {len(pair)} values"
        )
    out = []
    for v in pair:
        if isinstance(v, (bool, np.bool_)):
            raise _type_error(what, f"resolution must be ints, got {pair!r}")
        try:
            out.append(operator.index(v))
        except TypeError:
            raise _type_error(what, f"resolution must be ints, got {pair!r}") from None
    height, width = out
    if not (0 < height <= _MAX_SIZE and 0 < width <= _MAX_SIZE):
        raise _value_error(
            what, f"resolution must be in [1, {_MAX_SIZE}] each, got ({height}, {width})"
        )
    return height, width


class _Raster:
    """One rasterization's checked inputs."""

    def __init__(self, what, glctx, pos, tri, resolution, ranges, grad_db):
        if not isinstance(glctx, RasterizeCudaContext):
            raise _type_error(
                what,
                "glctx must be a RasterizeCudaContext or RasterizeGLContext, got "
                f"{type(glctx).__name__}",
            )
        if grad_db is not True and grad_db is not False:
            raise _type_error(what, f"grad_db must be True or False, got {grad_db!r}")
        _tensor(what, "pos", pos, torch.float32)
        if ranges is not None:
            _tensor(what, "ranges", ranges, torch.int32)
            if ranges.device.type != "cpu":
                raise _value_error(
                    what, f"ranges must be a CPU tensor (as nvdiffrast), got one on {ranges.device}"
                )
        self.instanced = pos.dim() > 2
        if self.instanced:
            if pos.dim() != 3 or not _positive(pos.shape) or pos.shape[2] != 4:
                raise _shape_error(what, "pos", pos, "[>0, >0, 4] (instanced mode)")
            vertices, batch = int(pos.shape[1]), int(pos.shape[0])
        else:
            if pos.dim() != 2 or not _positive(pos.shape) or pos.shape[1] != 4:
                raise _shape_error(what, "pos", pos, "[>0, 4] (range mode) or [>0, >0, 4]")
            if ranges is None:
                raise _value_error(what, "range mode (pos [V, 4]) needs ranges [B, 2]")
            if ranges.dim() != 2 or ranges.shape[0] == 0 or ranges.shape[1] != 2:
                raise _shape_error(what, "ranges", ranges, "[>0, 2]")
            vertices, batch = int(pos.shape[0]), int(ranges.shape[0])
        _tensor(what, "tri", tri, torch.int32)
        _same_device(what, pos=pos, tri=tri)
        _triangles(what, tri, vertices, "pos")
        self.ranges = None
        if not self.instanced:
            r = ranges.detach()
            count = int(tri.shape[0])
            for b, (first, n) in enumerate(r.tolist()):
                if first < 0 or n < 0 or first + n > count:
                    raise _value_error(
                        what,
                        f"range {b} is (start {first}, count {n}); it must lie within the "
                        f"{count} triangles",
                    )
            self.ranges = r
        self.height, self.width = _resolution(what, resolution)
        _finite_positions(what, pos)
        self.batch = batch
        self.output_db = bool(glctx.output_db)
        self.grad_db = grad_db and self.output_db


class _PeelState:
    """What a DepthPeeler keeps between layers: the last layer's per-pixel depth keys."""

    def __init__(self):
        self.keys = None


class _RasterizeFunction(torch.autograd.Function):
    """``rasterize`` (and a depth-peeling layer): gradients to ``pos``."""

    @staticmethod
    def forward(ctx, pos, tri, raster, peel):
        previous = None if peel is None else peel.keys
        rast, rast_db, keys = round_trip(
            _native.nv_rasterize, pos, tri, raster.height, raster.width, raster.ranges,
            previous, back=(_back(pos), _back(pos) if raster.output_db else None, None),
        )
        if peel is not None:
            peel.keys = keys
        if not raster.output_db:
            rast_db = torch.zeros(
                (raster.batch, raster.height, raster.width, 0), dtype=torch.float32,
                device=pos.device,
            )
        ctx.save_for_backward(pos, tri, rast)
        ctx.ranges = raster.ranges
        ctx.grad_db = raster.grad_db
        return rast, rast_db

    @staticmethod
    def backward(ctx, grad_rast, grad_rast_db):
        if not ctx.needs_input_grad[0]:
            return None, None, None, None
        pos, tri, rast = ctx.saved_tensors
        if grad_rast is None:
            grad_rast = torch.zeros_like(rast)
        ddb = None
        if ctx.grad_db and grad_rast_db is not None and grad_rast_db.shape[-1] == 4:
            ddb = grad_rast_db
        grad = round_trip(_native.nv_rasterize_grad, pos, tri, rast, grad_rast, ddb, ctx.ranges,
                          back=_back(pos))
        return grad, None, None, None


def rasterize(glctx, pos, tri, resolution, ranges=None, grad_db=True):
    """Rasterizes triangles.

    Args:
        glctx: a ``RasterizeCudaContext`` or ``RasterizeGLContext``.
        pos: clip-space vertex positions, float32: ``[minibatch, vertices, 4]`` (instanced
            mode: every minibatch item draws all of ``tri`` over its own vertices) or
            ``[vertices, 4]`` (range mode, with ``ranges``).
        tri: ``[triangles, 3]`` int32 vertex indices.
        resolution: ``(height, width)`` of the output, ints.
        ranges: range mode only: ``[minibatch, 2]`` int32 on the CPU, ``(first triangle,
            count)`` of the triangles each minibatch item draws; ignored in instanced mode.
        grad_db: whether the gradient of ``rast_db`` flows back to ``pos``.

    Returns:
        ``(rast, rast_db)``, each ``[minibatch, height, width, 4]`` float32: ``(u, v, z/w,
        triangle id + 1)`` of the nearest surface at each pixel centre (all zero where there is
        none), and the barycentrics' pixel derivatives ``(du/dX, du/dY, dv/dX, dv/dY)``. A
        ``RasterizeGLContext`` made with ``output_db=False`` returns ``rast_db`` of shape
        ``[minibatch, height, width, 0]``.
    """
    raster = _Raster("rasterize", glctx, pos, tri, resolution, ranges, grad_db)
    if glctx.active_depth_peeler is not None:
        raise RuntimeError(
            "softvk.nvdiffrast: rasterize: this context is in use by a DepthPeeler; call its "
            "rasterize_next_layer() instead, or use another context"
        )
    return _RasterizeFunction.apply(pos, tri, raster, None)


class DepthPeeler:
    """Rasterizes the depth layers of a scene one after the other, as a context manager::

        with DepthPeeler(glctx, pos, tri, resolution) as peeler:
            for i in range(layers):
                rast, rast_db = peeler.rasterize_next_layer()

    The arguments are ``rasterize``'s. The first layer is what ``rasterize`` returns; each next
    one shows, at every pixel, the surface after the one the layer before showed there (nothing
    where that one showed nothing). While the peeler is open its context serves no other
    rasterization.
    """

    def __init__(self, glctx, pos, tri, resolution, ranges=None, grad_db=True):
        _Raster("DepthPeeler", glctx, pos, tri, resolution, ranges, grad_db)
        self.raster_ctx = glctx
        self.pos = pos
        self.tri = tri
        self.resolution = resolution
        self.ranges = ranges
        self.grad_db = grad_db
        self.peeling_idx = None
        self._peel = None

    def __enter__(self):
        if self.raster_ctx is None:
            raise RuntimeError(
                "softvk.nvdiffrast: DepthPeeler: this peeler has ended; make a new one"
            )
        if self.raster_ctx.active_depth_peeler is not None:
            raise RuntimeError(
                "softvk.nvdiffrast: DepthPeeler: another depth peeler is open on this context"
            )
        self.raster_ctx.active_depth_peeler = self
        self.peeling_idx = 0
        self._peel = _PeelState()
        return self

    def __exit__(self, *exc):
        if self.raster_ctx is not None and self.raster_ctx.active_depth_peeler is self:
            self.raster_ctx.active_depth_peeler = None
        # Drop every reference to the inputs.
        self.raster_ctx = None
        self.pos = None
        self.tri = None
        self.resolution = None
        self.ranges = None
        self.grad_db = None
        self.peeling_idx = None
        self._peel = None
        return None

    def rasterize_next_layer(self):
        """The next depth layer, as ``rasterize`` returns it: ``(rast, rast_db)``."""
        if self.raster_ctx is None or self.raster_ctx.active_depth_peeler is not self:
            raise RuntimeError(
                "softvk.nvdiffrast: rasterize_next_layer() needs the peeler open: use it "
                "inside its `with` block"
            )
        raster = _Raster(
            "rasterize_next_layer", self.raster_ctx, self.pos, self.tri, self.resolution,
            self.ranges, self.grad_db,
        )
        result = _RasterizeFunction.apply(self.pos, self.tri, raster, self._peel)
        self.peeling_idx += 1
        return result


# ---------------------------------------------------------------------------------------------
# Interpolate.


def _diff_attrs(diff_attrs, count):
    """The attribute indices to differentiate, each in ``0..count``: ``'all'``, or a 1-D list
    of ints (negative ones count from the end)."""
    what = "interpolate"
    if diff_attrs is None:
        return []
    if isinstance(diff_attrs, str):
        if diff_attrs != "all":
            raise _value_error(
                what, f"diff_attrs must be 'all' or a list of ints, got {diff_attrs!r}"
            )
        return list(range(count))
    if isinstance(diff_attrs, torch.Tensor):
        diff_attrs = np.asarray(diff_attrs.detach().tolist())
    try:
        values = diff_attrs if isinstance(diff_attrs, np.ndarray) else np.asarray(
            diff_attrs, dtype=object)
    except ValueError:
        values = None
    if values is None or values.ndim != 1:
        raise _value_error(
            what, f"diff_attrs must be 'all' or a 1-D list of ints, got {diff_attrs!r}"
        )
    if values.dtype != object and not np.issubdtype(values.dtype, np.integer) and values.size:
        raise _type_error(what, f"diff_attrs must hold ints, got {diff_attrs!r}")
    integral = (int, np.integer)
    if any(not isinstance(v, integral) or isinstance(v, (bool, np.bool_)) for v in values):
        raise _type_error(what, f"diff_attrs must hold ints, got {diff_attrs!r}")
    out = []
    for v in (int(v) for v in values):
        j = v + count if v < 0 else v
        if not 0 <= j < count:
            raise _value_error(
                what, f"diff_attrs entry {v} is outside the {count} attributes of attr"
            )
        out.append(int(j))
    return out


class _InterpolateFunction(torch.autograd.Function):
    """``interpolate``: gradients to ``attr``, ``rast`` and (with pixel derivatives)
    ``rast_db``."""

    @staticmethod
    def forward(ctx, attr, rast, rast_db, tri, diff):
        out, out_da = round_trip(_native.nv_interpolate, attr, rast, tri, rast_db, diff,
                                 back=(_back(attr), _back(attr)))
        ctx.save_for_backward(attr, rast, rast_db, tri)
        ctx.diff = diff
        return out, out_da

    @staticmethod
    def backward(ctx, grad_out, grad_out_da):
        need_attr, need_rast, need_db = ctx.needs_input_grad[:3]
        if not (need_attr or need_rast or need_db):
            return None, None, None, None, None
        attr, rast, rast_db, tri = ctx.saved_tensors
        diff = ctx.diff
        if grad_out is None:
            grad_out = torch.zeros(
                tuple(rast.shape[:3]) + (attr.shape[-1],), dtype=torch.float32,
                device=rast.device,
            )
        dda = grad_out_da if rast_db is not None else None
        g_attr, g_rast, g_db = round_trip(
            _native.nv_interpolate_grad, attr, rast, tri, grad_out, rast_db, dda, diff,
            back=(_back(attr) if need_attr else None, _back(attr) if need_rast else None,
                  _back(attr) if need_db else None),
        )
        return (
            g_attr if need_attr else None,
            g_rast if need_rast else None,
            g_db if need_db else None,
            None,
            None,
        )


def interpolate(attr, rast, tri, rast_db=None, diff_attrs=None):
    """Interpolates vertex attributes over the rasterized triangles.

    Args:
        attr: float32 attributes, ``[vertices, attributes]`` (shared by the minibatch, and the
            shape range mode takes) or ``[minibatch, vertices, attributes]`` (one set per
            item; a leading 1 broadcasts).
        rast: ``rasterize``'s first output, ``[minibatch, height, width, 4]``.
        tri: ``[triangles, 3]`` int32 indices into ``attr``'s vertices (the rasterized
            triangle ids pick the rows).
        rast_db: ``rasterize``'s second output; needed for ``diff_attrs``.
        diff_attrs: the attributes whose pixel derivatives to compute: ``'all'`` or a list
            of indices (negative ones count from the end).

    Returns:
        ``(out, out_da)``: the interpolated attributes ``[minibatch, height, width,
        attributes]`` (zero where nothing is drawn), and with ``diff_attrs`` and ``rast_db``
        ``(dA/dX, dA/dY)`` for each listed attribute in order, ``[minibatch, height, width,
        2 len(diff_attrs)]``; otherwise an empty ``[minibatch, height, width, 0]``.
    """
    what = "interpolate"
    _tensor(what, "attr", attr, torch.float32)
    _tensor(what, "rast", rast, torch.float32)
    if rast.dim() != 4 or not _positive(rast.shape) or rast.shape[3] != 4:
        raise _shape_error(what, "rast", rast, "[>0, >0, >0, 4]")
    batch = int(rast.shape[0])
    if attr.dim() not in (2, 3) or not _positive(attr.shape):
        raise _shape_error(what, "attr", attr, "[>0, >0] or [>0, >0, >0]")
    if attr.dim() == 3 and attr.shape[0] not in (1, batch):
        raise _value_error(
            what,
            f"attr has a minibatch of {attr.shape[0]}, rast {batch} (attr's must be 1 or "
            "rast's)",
        )
    count = int(attr.shape[-1])
    _tensor(what, "tri", tri, torch.int32)
    diff = _diff_attrs(diff_attrs, count)
    if diff:
        if rast_db is None:
            raise _value_error(what, "diff_attrs needs rast_db (rasterize's second output)")
        _tensor(what, "rast_db", rast_db, torch.float32)
        if rast_db.dim() != 4 or tuple(rast_db.shape) != tuple(rast.shape):
            raise _shape_error(what, "rast_db", rast_db, f"{list(rast.shape)} (rast's)")
    else:
        rast_db = None
    _same_device(what, attr=attr, rast=rast, tri=tri, rast_db=rast_db)
    _triangles(what, tri, int(attr.shape[-2]), "attr")
    return _InterpolateFunction.apply(attr, rast, rast_db, tri, diff)


# ---------------------------------------------------------------------------------------------
# Texture.


_FILTER_MODES = ("nearest", "linear", "linear-mipmap-nearest", "linear-mipmap-linear")
_BOUNDARY_MODES = ("wrap", "clamp", "zero", "cube")
# The largest texture side (nvdiffrast's TEX_MAX_MIP_LEVEL: 2^16).
_MAX_TEXTURE = 1 << 16


def _max_mip_level(what, max_mip_level):
    """``None`` or an int >= 0."""
    if max_mip_level is None:
        return None
    if isinstance(max_mip_level, (bool, np.bool_)):
        raise _type_error(what, f"max_mip_level must be an int, got {max_mip_level!r}")
    try:
        level = operator.index(max_mip_level)
    except TypeError:
        raise _type_error(what, f"max_mip_level must be an int, got {max_mip_level!r}") from None
    if level < 0:
        raise _value_error(what, f"max_mip_level must be >= 0, got {level}")
    return int(level)


def _texture_shape(what, tex, cube):
    """``tex`` float32 ``[>0, >0, >0, >0]`` (2D), or a cube map's ``[>0, 6, S, S, >0]``, of a
    size nvdiffrast takes."""
    _tensor(what, "tex", tex, torch.float32)
    if cube:
        if tex.dim() != 5 or not _positive(tex.shape) or tex.shape[1] != 6:
            raise _shape_error(what, "tex", tex, "[>0, 6, >0, >0, >0] (a cube map)")
        if tex.shape[2] != tex.shape[3]:
            raise _value_error(
                what, f"cube map faces must be square, got {list(tex.shape[2:4])}"
            )
        size = tex.shape[2:4]
    else:
        if tex.dim() != 4 or not _positive(tex.shape):
            raise _shape_error(what, "tex", tex, "[>0, >0, >0, >0]")
        size = tex.shape[1:3]
    if size[0] > _MAX_TEXTURE or size[1] > _MAX_TEXTURE:
        raise _value_error(
            what, f"texture size too large: {list(size)} (at most {_MAX_TEXTURE})"
        )


class _TextureFunction(torch.autograd.Function):
    """``texture``: gradients to ``tex`` (through the mip stack built from it), ``uv`` (but for
    'nearest'), ``uv_da`` and ``mip_level_bias`` ('linear-mipmap-linear'), and each level of a
    custom mip stack."""

    @staticmethod
    def forward(ctx, filter_mode, boundary_mode, mip, max_mip_level, tex, uv, uv_da, bias,
                *levels):
        ctx.args = (filter_mode, boundary_mode, mip, max_mip_level)
        ctx.has_levels = bool(levels)
        ctx.save_for_backward(tex, uv, uv_da, bias, *levels)
        return round_trip(_native.nv_texture,
                          *_texture_native_args(ctx.args, tex, uv, uv_da, bias, levels),
                          back=_back(uv))

    @staticmethod
    def backward(ctx, dy):
        tex, uv, uv_da, bias, *levels = ctx.saved_tensors
        filter_mode = ctx.args[0]
        args = list(_texture_native_args(ctx.args, tex, uv, uv_da, bias, levels))
        args.insert(2, dy)
        need = ctx.needs_input_grad
        lml = filter_mode == "linear-mipmap-linear"
        wanted = (
            _back(tex) if need[4] else None,
            _back(uv) if need[5] and filter_mode != "nearest" else None,
            _back(uv_da) if need[6] and lml and uv_da is not None else None,
            _back(bias) if need[7] and lml and bias is not None else None,
            [_back(t) if need[8 + k] else None for k, t in enumerate(levels)],
        )
        g_tex, g_uv, g_uv_da, g_bias, g_levels = round_trip(_native.nv_texture_grad, *args,
                                                             back=wanted)
        picked = [g if w is not None else None for g, w in zip((g_tex, g_uv, g_uv_da, g_bias),
                                                                 wanted)]
        g_levels = g_levels or []
        return (
            None,
            None,
            None,
            None,
            *picked,
            *(g if w is not None else None for g, w in zip(g_levels, wanted[4])),
        )


def _texture_native_args(args, tex, uv, uv_da, bias, levels):
    filter_mode, boundary_mode, mip, max_mip_level = args
    return (
        tex,
        uv,
        filter_mode,
        boundary_mode,
        uv_da,
        bias,
        mip,
        list(levels) if levels else None,
        max_mip_level,
    )


def texture(tex, uv, uv_da=None, mip_level_bias=None, mip=None, filter_mode="auto",
            boundary_mode="wrap", max_mip_level=None):
    """Samples a texture at per-pixel coordinates, as nvdiffrast's ``texture``.

    Args:
        tex: float32 texture ``[minibatch, height, width, channels]`` (a minibatch of 1
            broadcasts); any size and channel count (the mipmap modes need each extent to halve
            evenly down to the levels used, as nvdiffrast's). With ``boundary_mode='cube'`` a
            cube map ``[minibatch, 6, size, size, channels]``, faces +x, -x, +y, -y, +z, -z.
        uv: float32 coordinates ``[minibatch, height, width, 2]``, ``u`` across the texture's
            width and ``v`` down its rows, the texture spanning [0, 1]; for a cube map,
            directions ``[minibatch, height, width, 3]`` of any length.
        uv_da: float32 ``[minibatch, height, width, 4]``: ``(du/dX, du/dY, dv/dX, dv/dY)``,
            the pixel derivatives of ``uv`` that pick the mip level (``interpolate``'s
            ``out_da``); for a cube map ``[minibatch, height, width, 6]``, ``(dx/dX, dx/dY,
            dy/dX, dy/dY, dz/dX, dz/dY)``.
        mip_level_bias: float32 ``[minibatch, height, width]``, added to the level (the
            level itself without ``uv_da``).
        mip: ``texture_construct_mip``'s result, or a list of float32 tensors, one per mip
            level below ``tex`` (their gradients their own); built here when omitted.
        filter_mode: 'auto' (the best ``uv_da`` and ``mip_level_bias`` allow), 'nearest',
            'linear', 'linear-mipmap-nearest' or 'linear-mipmap-linear'.
        boundary_mode: 'wrap', 'clamp', 'zero', or 'cube' (a cube map, seamless across its
            faces).
        max_mip_level: the most mip levels to build and use (0: none).

    Returns:
        ``[minibatch, height, width, channels]`` float32.
    """
    what = "texture"
    if not isinstance(filter_mode, str) or filter_mode not in ("auto",) + _FILTER_MODES:
        raise _value_error(
            what, f"filter_mode must be 'auto' or one of {_FILTER_MODES}, got {filter_mode!r}"
        )
    if not isinstance(boundary_mode, str) or boundary_mode not in _BOUNDARY_MODES:
        raise _value_error(
            what, f"boundary_mode must be one of {_BOUNDARY_MODES}, got {boundary_mode!r}"
        )
    max_mip_level = _max_mip_level(what, max_mip_level)
    if filter_mode == "auto":
        has_level = uv_da is not None or mip_level_bias is not None
        filter_mode = "linear-mipmap-linear" if has_level else "linear"
    mipmaps = "mipmap" in filter_mode
    if mipmaps and uv_da is None and mip_level_bias is None:
        raise _value_error(
            what, "mipmapping filter mode requires uv_da and/or mip_level_bias input"
        )
    if mipmaps and max_mip_level == 0:
        filter_mode, mipmaps = "linear", False
    cube = boundary_mode == "cube"
    _texture_shape(what, tex, cube)
    n_uv, n_da = (3, 6) if cube else (2, 4)
    _tensor(what, "uv", uv, torch.float32)
    if uv.dim() != 4 or not _positive(uv.shape) or uv.shape[3] != n_uv:
        raise _shape_error(what, "uv", uv, f"[>0, >0, >0, {n_uv}]")
    batch, height, width = (int(s) for s in uv.shape[:3])
    if tex.shape[0] not in (1, batch):
        raise _value_error(
            what,
            f"minibatch size mismatch between inputs tex, uv: {tex.shape[0]} and {batch}",
        )
    levels = []
    if not mipmaps:
        uv_da, mip_level_bias, mip = None, None, None
    else:
        if uv_da is not None:
            _tensor(what, "uv_da", uv_da, torch.float32)
            if tuple(uv_da.shape) != (batch, height, width, n_da):
                raise _shape_error(
                    what, "uv_da", uv_da, f"[{batch}, {height}, {width}, {n_da}]"
                )
        if mip_level_bias is not None:
            _tensor(what, "mip_level_bias", mip_level_bias, torch.float32)
            if tuple(mip_level_bias.shape) != (batch, height, width):
                raise _shape_error(
                    what, "mip_level_bias", mip_level_bias, f"[{batch}, {height}, {width}]"
                )
        if isinstance(mip, (list, tuple)):
            for k, level in enumerate(mip):
                _tensor(what, f"mip[{k}]", level, torch.float32)
            levels, mip = list(mip), None
        elif mip is not None and not isinstance(mip, _native.NvTextureMip):
            raise _type_error(
                what,
                "mip must be texture_construct_mip's result or a list of tensors, got "
                f"{type(mip).__name__}",
            )
        elif mip is not None and mip.cube_mode != cube:
            raise _value_error(
                what,
                "mip was built with cube_mode=" + str(mip.cube_mode) + ", but boundary_mode "
                f"is {boundary_mode!r}",
            )
    _same_device(what, tex=tex, uv=uv, uv_da=uv_da, mip_level_bias=mip_level_bias)
    return _TextureFunction.apply(
        filter_mode, boundary_mode, mip, max_mip_level, tex, uv, uv_da, mip_level_bias, *levels
    )


def texture_construct_mip(tex, max_mip_level=None, cube_mode=False):
    """Builds a texture's mip stack once, for a texture that stays the same between calls, as
    nvdiffrast's ``texture_construct_mip``: an opaque object for ``texture(mip=...)``, whose
    gradients still reach ``tex``.

    Args:
        tex: as ``texture``'s.
        max_mip_level: the most mip levels to build (``None``: down to 1 x 1).
        cube_mode: True for a cube map ``[minibatch, 6, size, size, channels]``.
    """
    what = "texture_construct_mip"
    if cube_mode is not True and cube_mode is not False:
        raise _type_error(what, f"cube_mode must be True or False, got {cube_mode!r}")
    max_mip_level = _max_mip_level(what, max_mip_level)
    _texture_shape(what, tex, cube_mode)
    return round_trip(_native.nv_texture_construct_mip, tex, max_mip_level, cube_mode)


# ---------------------------------------------------------------------------------------------
# Antialias.


def antialias_construct_topology_hash(tri):
    """The edge adjacency of ``tri`` (``[triangles, 3]`` int32), to pass to ``antialias`` as
    ``topology_hash`` when the triangles stay the same between calls. An opaque object."""
    what = "antialias_construct_topology_hash"
    _tensor(what, "tri", tri, torch.int32)
    if tri.dim() != 2 or tri.shape[0] == 0 or tri.shape[1] != 3:
        raise _shape_error(what, "tri", tri, "[>0, 3]")
    if int(tri.min()) < 0:
        raise _value_error(what, "tri has a negative vertex index")
    return round_trip(_native.nv_topology_hash, tri)


class _AntialiasFunction(torch.autograd.Function):
    """``antialias``: gradients to ``color`` and ``pos``."""

    @staticmethod
    def forward(ctx, color, rast, pos, tri, topology, pos_gradient_boost):
        out = round_trip(_native.nv_antialias, color, rast, pos, tri, topology,
                         back=_back(color))
        ctx.save_for_backward(color, rast, pos, tri)
        ctx.topology = topology
        ctx.boost = pos_gradient_boost
        return out

    @staticmethod
    def backward(ctx, grad_out):
        need_color, _, need_pos = ctx.needs_input_grad[:3]
        if not (need_color or need_pos):
            return (None,) * 6
        color, rast, pos, tri = ctx.saved_tensors
        g_color, g_pos = round_trip(
            _native.nv_antialias_grad, color, rast, pos, tri, ctx.topology, grad_out, ctx.boost,
            back=(_back(color) if need_color else None, _back(pos) if need_pos else None),
        )
        return (
            g_color if need_color else None,
            None,
            g_pos if need_pos else None,
            None,
            None,
            None,
        )


def antialias(color, rast, pos, tri, topology_hash=None, pos_gradient_boost=1.0):
    """Antialiases silhouette edges analytically, so that their positions get gradients.

    Where two neighbouring pixels show different surfaces and a silhouette edge of the nearer
    passes between their centres, the pixel whose box the edge cuts takes a share of its
    neighbour's colour that follows the edge's position. Silhouettes are found by vertex
    index: a vertex shared by triangles must have one index in all of them.

    Args:
        color: the image, ``[minibatch, height, width, channels]`` float32.
        rast: ``rasterize``'s first output for the same geometry.
        pos: the positions given to ``rasterize``.
        tri: the triangles given to ``rasterize``.
        topology_hash: ``antialias_construct_topology_hash(tri)``, made once for a ``tri``
            that stays the same; built for the call when not given.
        pos_gradient_boost: a factor on the gradient to ``pos``.

    Returns:
        The antialiased image, ``color``'s shape.
    """
    what = "antialias"
    _tensor(what, "color", color, torch.float32)
    _tensor(what, "rast", rast, torch.float32)
    _tensor(what, "pos", pos, torch.float32)
    if color.dim() != 4 or not _positive(color.shape):
        raise _shape_error(what, "color", color, "[>0, >0, >0, >0]")
    batch, height, width = (int(s) for s in color.shape[:3])
    if rast.dim() != 4 or tuple(rast.shape) != (batch, height, width, 4):
        raise _shape_error(what, "rast", rast, f"[{batch}, {height}, {width}, 4] (color's)")
    if pos.dim() == 3:
        if not _positive(pos.shape) or pos.shape[2] != 4 or pos.shape[0] != batch:
            raise _shape_error(what, "pos", pos, f"[{batch}, >0, 4] (instanced mode)")
    elif pos.dim() != 2 or not _positive(pos.shape) or pos.shape[1] != 4:
        raise _shape_error(what, "pos", pos, "[>0, 4] (range mode) or [minibatch, >0, 4]")
    _tensor(what, "tri", tri, torch.int32)
    _same_device(what, color=color, rast=rast, pos=pos, tri=tri)
    _triangles(what, tri, int(pos.shape[-2]), "pos")
    _finite_positions(what, pos)
    if isinstance(pos_gradient_boost, bool):
        raise _type_error(what, f"pos_gradient_boost must be a number, got {pos_gradient_boost!r}")
    try:
        boost = float(pos_gradient_boost)
    except (TypeError, ValueError):
        raise _type_error(
            what, f"pos_gradient_boost must be a number, got {pos_gradient_boost!r}"
        ) from None
    if not np.isfinite(boost):
        raise _value_error(what, f"pos_gradient_boost must be finite, got {boost}")
    if topology_hash is None:
        topology_hash = round_trip(_native.nv_topology_hash, tri)
    elif not isinstance(topology_hash, _native.NvTopologyHash):
        raise _type_error(
            what,
            "topology_hash must come from antialias_construct_topology_hash, got "
            f"{type(topology_hash).__name__}",
        )
    if topology_hash.triangle_count != tri.shape[0]:
        raise _value_error(
            what,
            f"topology_hash was built from {topology_hash.triangle_count} triangles, tri has "
            f"{tri.shape[0]}",
        )
    return _AntialiasFunction.apply(color, rast, pos, tri, topology_hash, boost)
