"""softvk's renderer as PyTorch operations.

- :func:`soft_rasterize` is SoftRas's ``soft_rasterize`` (same arguments, defaults, shapes and
  dtypes): faces already projected to screen space in, RGBA images ``[B, 4, H, W]`` out.
- :func:`render_mesh` renders world-space meshes through SoftRas's ``look_at`` or
  ``projection`` camera with its ambient + directional lighting, all in the engine: no
  ``[B, F, 3, 3]`` tensor is built in Python.
- :func:`render` renders a ``softvk.soft_renderer`` mesh through a ``SoftRenderer`` as alpha
  alone (the alpha-only fast path) or as depth: what SoftRas's ``mode=`` never did.

Both are ``torch.autograd.Function`` s whose backward is softvk's: the exact derivative of the
forward (SoftRas drops some terms; softvk keeps them), deterministic, bit-identical on reruns,
with no float atomics. Gradients go only to the inputs that ask for them; an upstream gradient
that is zero on RGB (a silhouette loss) takes the alpha-only backward.

Tensors may live on any device: the engine reads host copies and the results go back to the
device of the input (CUDA tensors work, through those copies).
"""

import numpy as np
import torch

from . import _native

__all__ = ["soft_rasterize", "render_mesh", "render", "rasterize_settings"]


def _size(image_size):
    """``(height, width)`` from an int (square, as SoftRas) or a ``(height, width)`` pair."""
    if isinstance(image_size, (tuple, list)):
        height, width = image_size
        return int(height), int(width)
    return int(image_size), int(image_size)


def rasterize_settings(
    image_size=256,
    background_color=(0, 0, 0),
    near=1,
    far=100,
    fill_back=True,
    eps=1e-3,
    sigma_val=1e-5,
    dist_func="euclidean",
    dist_eps=1e-4,
    gamma_val=1e-4,
    aggr_func_rgb="softmax",
    aggr_func_alpha="prod",
    texture_type="surface",
    tile=8,
    brute=False,
    silhouettes=False,
):
    """The engine's settings from SoftRas's rasterizer arguments (validated here, once).
    ``silhouettes=True`` renders alpha alone (RGB left zero), without the depth and colour
    work."""
    height, width = _size(image_size)
    background = tuple(float(c) for c in _as_list(background_color))
    if len(background) != 3:
        raise ValueError(f"softvk: background_color needs 3 values, got {background_color!r}")
    return _native.Settings(
        width,
        height,
        sigma=float(sigma_val),
        gamma=float(gamma_val),
        near=float(near),
        far=float(far),
        eps=float(eps),
        dist_eps=float(dist_eps),
        dist_func=dist_func,
        aggr_func_rgb=aggr_func_rgb,
        aggr_func_alpha=aggr_func_alpha,
        background_color=background,
        fill_back=bool(fill_back),
        texture_type=texture_type,
        tile=int(tile),
        brute=bool(brute),
        silhouettes=bool(silhouettes),
    )


def _as_list(value):
    if isinstance(value, torch.Tensor):
        return value.detach().cpu().reshape(-1).tolist()
    if isinstance(value, np.ndarray):
        return value.reshape(-1).tolist()
    return list(value)


def _host(tensor, dtype=np.float32):
    """A C-contiguous numpy copy (or view) of ``tensor`` on the host."""
    array = tensor.detach().cpu().numpy()
    return np.ascontiguousarray(array, dtype=dtype)


def _upstream(grad_images):
    """dL/d(images) ``[B, 4, H, W]`` as the engine takes it (``[B, H, W, 4]`` float32), and
    whether its RGB part is zero everywhere (then the backward skips the colour terms)."""
    grad = grad_images.detach()
    alpha_only = not bool(torch.any(grad[:, :3] != 0))
    return _host(grad.permute(0, 2, 3, 1)), alpha_only


def _images(array, like):
    """Engine images ``[B, H, W, 4]`` as ``[B, 4, H, W]`` on ``like``'s device and dtype."""
    images = torch.from_numpy(array).permute(0, 3, 1, 2).contiguous()
    return images.to(device=like.device, dtype=like.dtype)


def _like(tensor):
    """What a gradient must match of an input: device, dtype and shape (not the tensor itself,
    which the autograd context should not hold)."""
    return tensor.device, tensor.dtype, tensor.shape


def _grad(array, like):
    device, dtype, shape = like
    return torch.from_numpy(array).reshape(shape).to(device=device, dtype=dtype)


class SoftRasterizeFunction(torch.autograd.Function):
    """SoftRas's ``SoftRasterizeFunction`` on softvk's engine: float32 on the device; float64
    (what ``torch.autograd.gradcheck`` makes; SoftRas's kernels compute doubles in double) on
    the f64 CPU twin, forward and backward, never float32 behind a float64 result."""

    @staticmethod
    def forward(ctx, face_vertices, textures, settings):
        ctx.like = (_like(face_vertices), _like(textures))
        if face_vertices.dtype == torch.float64:
            host = (_host(face_vertices, np.float64), _host(textures, np.float64))
            ctx.double = (host, settings)
            return _images(_native.reference_rasterize(*host, settings), face_vertices)
        ctx.double = None
        images, raster = _native.rasterize(_host(face_vertices), _host(textures), settings)
        ctx.raster = raster
        return _images(images, face_vertices)

    @staticmethod
    def backward(ctx, grad_images):
        need_vertices, need_textures = ctx.needs_input_grad[:2]
        if not (need_vertices or need_textures):
            return None, None, None
        if ctx.double is not None:
            (face_vertices, textures), settings = ctx.double
            upstream = _host(grad_images.detach().permute(0, 2, 3, 1), np.float64)
            d_vertices, d_textures = _native.reference_rasterize_grad(
                face_vertices, textures, settings, upstream
            )
        else:
            upstream, alpha_only = _upstream(grad_images)
            d_vertices, d_textures, _ = ctx.raster.backward(upstream, alpha_only)
        face_vertices, textures = ctx.like
        return (
            _grad(d_vertices, face_vertices) if need_vertices else None,
            _grad(d_textures, textures) if need_textures else None,
            None,
        )


def soft_rasterize(
    face_vertices,
    textures,
    image_size=256,
    background_color=[0, 0, 0],
    near=1,
    far=100,
    fill_back=True,
    eps=1e-3,
    sigma_val=1e-5,
    dist_func="euclidean",
    dist_eps=1e-4,
    gamma_val=1e-4,
    aggr_func_rgb="softmax",
    aggr_func_alpha="prod",
    texture_type="surface",
):
    """SoftRas's soft rasterizer.

    ``face_vertices`` ``[B, F, 3, 3]``: each face's three vertices in screen space (x, y in
    [-1, 1] across the image, y up; depth). ``textures`` ``[B, F, R², 3]`` per-face texels
    (``texture_type='surface'``) or ``[B, F, 3, 3]`` per-corner colours (``'vertex'``), already
    lit. Returns RGBA ``[B, 4, H, W]``, row 0 at the top. ``image_size`` may also be a
    ``(height, width)`` pair.
    """
    settings = rasterize_settings(
        image_size,
        background_color,
        near,
        far,
        fill_back,
        eps,
        sigma_val,
        dist_func,
        dist_eps,
        gamma_val,
        aggr_func_rgb,
        aggr_func_alpha,
        texture_type,
    )
    _check_dtypes("soft_rasterize", (torch.float32, torch.float64),
                  face_vertices=face_vertices, textures=textures)
    return SoftRasterizeFunction.apply(face_vertices, textures, settings)


def _check_dtypes(what, allowed, **tensors):
    """One clear error unless every tensor has one dtype of ``allowed`` (as SoftRas's kernels,
    which dispatch on one floating type for all their inputs)."""
    dtypes = {name: t.dtype for name, t in tensors.items() if isinstance(t, torch.Tensor)}
    first = next(iter(dtypes.values()), None)
    if first not in allowed or any(d != first for d in dtypes.values()):
        names = ", ".join(f"{n} {d}" for n, d in dtypes.items())
        kinds = " or ".join(str(a) for a in allowed)
        raise TypeError(f"softvk: {what} takes {kinds} tensors, all of one dtype; got {names}")


class RenderMeshFunction(torch.autograd.Function):
    """World-space meshes through cameras and lights, all in the engine."""

    @staticmethod
    def forward(ctx, vertices, textures, eyes, faces, cameras, lighting, settings):
        view_mesh = np.arange(vertices.shape[0], dtype=np.int64)
        images, raster = _native.render_mesh(
            _host(vertices),
            _host(faces, np.int64),
            _host(textures),
            view_mesh,
            cameras,
            lighting,
            settings,
        )
        ctx.raster = raster
        ctx.like = (_like(vertices), _like(textures), _like(eyes))
        return _images(images, vertices)

    @staticmethod
    def backward(ctx, grad_images):
        need_vertices, need_textures, need_eyes = ctx.needs_input_grad[:3]
        if not (need_vertices or need_textures or need_eyes):
            return (None,) * 7
        upstream, alpha_only = _upstream(grad_images)
        d_vertices, d_textures, d_eyes = ctx.raster.backward(upstream, alpha_only, need_eyes)
        vertices, textures, eyes = ctx.like
        return (
            _grad(d_vertices, vertices) if need_vertices else None,
            _grad(d_textures, textures) if need_textures else None,
            _grad(d_eyes, eyes) if need_eyes else None,
            None,
            None,
            None,
            None,
        )


def _batched(tensor, batch, name):
    if tensor.dim() == 2:
        tensor = tensor.unsqueeze(0)
    if tensor.shape[0] == 1 and batch > 1:
        tensor = tensor.expand(batch, *tensor.shape[1:])
    if tensor.shape[0] != batch:
        raise ValueError(f"softvk: {name} has batch {tensor.shape[0]}, the vertices {batch}")
    return tensor


def render_mesh(
    vertices,
    faces,
    textures=None,
    eyes=None,
    image_size=256,
    background_color=[0, 0, 0],
    near=1,
    far=100,
    fill_back=True,
    eps=1e-3,
    sigma_val=1e-5,
    dist_func="euclidean",
    dist_eps=1e-4,
    gamma_val=1e-4,
    aggr_func_rgb="softmax",
    aggr_func_alpha="prod",
    texture_type="surface",
    camera_mode="look_at",
    perspective=True,
    viewing_angle=30,
    viewing_scale=1.0,
    P=None,
    dist_coeffs=None,
    orig_size=512,
    light_intensity_ambient=0.5,
    light_color_ambient=[1, 1, 1],
    light_intensity_directionals=0.5,
    light_color_directionals=[1, 1, 1],
    light_directions=[0, 1, 0],
    silhouettes=False,
):
    """Renders meshes as SoftRas's ``SoftRenderer`` does (lighting → camera → rasterizer), in
    the engine.

    ``vertices`` ``[B, V, 3]`` world positions; ``faces`` ``[F, 3]`` or ``[B, F, 3]`` (the same
    faces for every mesh); ``textures`` ``[B, F, R², 3]`` (surface) or ``[B, V, 3]`` (vertex),
    before lighting (white when ``None``). ``camera_mode='look_at'``: mesh ``b`` seen from
    ``eyes[b]`` (``[B, 3]`` or ``[3]``; SoftRas's default eye otherwise) looking at the origin
    with +y up, perspective with ``viewing_angle`` degrees or orthographic with
    ``viewing_scale``; ``'projection'``: SoftRas's 3×4 ``P`` (``[B, 3, 4]`` or ``[3, 4]``),
    ``dist_coeffs`` and ``orig_size``. Lighting is SoftRas's ambient + directional, arguments
    as ``SoftRenderer``'s. Returns RGBA ``[B, 4, H, W]``; with ``silhouettes=True`` only its
    alpha is rendered (RGB is zero), which saves the depth and colour work forward and
    backward. Gradients flow to ``vertices``, ``textures`` and (look_at) ``eyes``.
    """
    if vertices.dim() == 2:
        vertices = vertices.unsqueeze(0)
    # float64 meshes go through SoftRas's composed steps (softvk.soft_renderer), whose
    # rasterizer computes doubles on the f64 twin; the engine's camera and lights are float32.
    _check_dtypes("render_mesh", (torch.float32,), vertices=vertices, textures=textures)
    batch = vertices.shape[0]
    faces = faces.detach()
    if faces.dim() == 3:
        if bool(torch.any(faces != faces[:1])):
            raise ValueError("softvk: render_mesh needs the same faces for every mesh of a batch")
        faces = faces[0]
    if textures is None:
        if texture_type == "vertex":
            textures = torch.ones(batch, vertices.shape[1], 3, dtype=vertices.dtype)
        else:
            textures = torch.ones(batch, faces.shape[0], 1, 3, dtype=vertices.dtype)
        textures = textures.to(vertices.device)
    textures = _batched(textures, batch, "textures") if textures.dim() == 3 else textures
    if textures.dim() == 4 and textures.shape[0] == 1 and batch > 1:
        textures = textures.expand(batch, *textures.shape[1:])

    if camera_mode in ("look_at", "look"):
        if camera_mode == "look":
            raise ValueError("softvk: render_mesh renders look_at and projection cameras")
        angles = np.asarray(_as_list(viewing_angle) if not np.isscalar(viewing_angle)
                            else [viewing_angle], dtype=np.float64).reshape(-1)
        if len(angles) == 1:
            angles = np.repeat(angles, batch)
        if len(angles) != batch:
            raise ValueError(f"softvk: {len(angles)} viewing angles for a batch of {batch} meshes")
        if eyes is None:
            distance = 1.0 / np.tan(np.radians(angles)) + 1
            eyes = torch.from_numpy(np.stack([0 * distance, 0 * distance, -distance], axis=1))
            eyes = eyes.to(vertices.device, vertices.dtype)
        eyes = eyes.reshape(-1, 3)
        if eyes.shape[0] == 1 and batch > 1:
            eyes = eyes.expand(batch, 3)
        if eyes.shape[0] != batch:
            raise ValueError(f"softvk: {eyes.shape[0]} eyes for a batch of {batch} meshes")
        cameras = [
            ("look_at", tuple(e), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0),
             float(a) if perspective else None, float(viewing_scale))
            for e, a in zip(eyes.detach().cpu().double().tolist(), angles)
        ]
    elif camera_mode == "projection":
        if P is None:
            raise ValueError("softvk: camera_mode 'projection' needs P")
        matrices = _batched(torch.as_tensor(P).reshape(-1, 3, 4), batch, "P")
        coeffs = [0.0] * 5 if dist_coeffs is None else _as_list(dist_coeffs)
        coeffs = np.asarray(coeffs, dtype=np.float64).reshape(-1, 5)
        if coeffs.shape[0] == 1:
            coeffs = np.repeat(coeffs, batch, axis=0)
        cameras = [
            ("projection", tuple(m), tuple(c), float(orig_size))
            for m, c in zip(matrices.detach().cpu().double().reshape(batch, 12).tolist(), coeffs.tolist())
        ]
        eyes = torch.zeros(batch, 3, dtype=vertices.dtype, device=vertices.device)
    else:
        raise ValueError(f"softvk: unknown camera_mode {camera_mode!r}")

    lighting = (
        float(light_intensity_ambient),
        tuple(float(c) for c in _as_list(light_color_ambient)),
        _directionals(light_intensity_directionals, light_color_directionals, light_directions),
    )
    settings = rasterize_settings(
        image_size,
        background_color,
        near,
        far,
        fill_back,
        eps,
        sigma_val,
        dist_func,
        dist_eps,
        gamma_val,
        aggr_func_rgb,
        aggr_func_alpha,
        texture_type,
        silhouettes=silhouettes,
    )
    return RenderMeshFunction.apply(vertices, textures, eyes, faces, cameras, lighting, settings)


def _directionals(intensities, colors, directions):
    """SoftRas's directional lights (one, or one per row) as ``(intensity, colour, direction)``."""
    directions = np.asarray(_as_list(directions), dtype=np.float64).reshape(-1, 3)
    colors = np.asarray(_as_list(colors), dtype=np.float64).reshape(-1, 3)
    intensities = np.asarray(
        _as_list(intensities) if not np.isscalar(intensities) else [intensities], dtype=np.float64
    ).reshape(-1)
    n = max(len(directions), len(colors), len(intensities))
    pick = lambda a, i: a[i if len(a) > 1 else 0]  # noqa: E731
    return [
        (float(pick(intensities, i)), tuple(pick(colors, i)), tuple(pick(directions, i)))
        for i in range(n)
    ]


def render(renderer, mesh, mode="rgba"):
    """Renders ``mesh`` (a ``softvk.soft_renderer.Mesh``) through ``renderer`` (a
    ``softvk.soft_renderer.SoftRenderer``), with its camera, lighting and rasterizer settings.

    - ``mode='rgba'``: ``[B, 4, H, W]``, what ``renderer.render_mesh(mesh)`` returns;
    - ``'silhouettes'``: ``[B, H, W]``, the alpha of that render, rendered alone when the engine
      takes the renderer (no depth or colour work, forward or backward: the same bits as the
      full render's alpha);
    - ``'depth'``: ``[B, H, W]``, the depth of the nearest face covering each pixel (``far``
      where none does), differentiable in the vertices.

    SoftRas's own ``mode=`` argument is ignored there, as SoftRas ignores it.
    """
    modes = ("rgba", "silhouettes", "depth")
    if mode not in modes:
        raise ValueError(f"softvk: render's mode must be one of {modes}, got {mode!r}")
    return renderer._render(mesh, mode)
