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
device of the input (``softvk._host.round_trip``, the package's one round trip; CUDA tensors
work through those copies, though no CUDA machine has tried them yet). Bad input is one clear
error on every path (``softvk._checks``); meshes without faces render the background, as
SoftRas's.
"""

import numpy as np
import torch

from . import _checks, _native
from ._host import Like, like, round_trip

__all__ = ["soft_rasterize", "render_mesh", "render", "rasterize_settings"]


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
    height, width = _checks.image_size(image_size)
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
    """A setting (a tensor on any device, a numpy array, a list) as a flat list of numbers."""
    if isinstance(value, torch.Tensor):
        return value.detach().reshape(-1).tolist()
    if isinstance(value, np.ndarray):
        return value.reshape(-1).tolist()
    return list(value)


def _upstream(grad_images):
    """dL/d(images) ``[B, 4, H, W]`` as the engine takes it (``[B, H, W, 4]``), and whether its
    RGB part is zero everywhere (then the backward skips the colour terms)."""
    grad = grad_images.detach()
    alpha_only = not bool(torch.any(grad[:, :3] != 0))
    return grad.permute(0, 2, 3, 1), alpha_only


def _images(images):
    """Engine images ``[B, H, W, 4]`` (already on their device) as ``[B, 4, H, W]``."""
    return images.permute(0, 3, 1, 2).contiguous()


def _wanted(likes, needs):
    """The ``round_trip`` entries of gradients: each input's :class:`Like` where its gradient
    is asked for, ``None`` (left on the host, then dropped by :func:`_picked`) where not."""
    return tuple(lk if need else None for lk, need in zip(likes, needs))


def _picked(grads, needs):
    """The gradients asked for; ``None`` for the others."""
    return tuple(g if need else None for g, need in zip(grads, needs))


class NothingToRender(torch.autograd.Function):
    """What SoftRas renders of meshes without faces (or of an empty batch): the background
    colour, alpha 0, and gradients of zero for every input. RGB is zero too where only alpha
    is rendered (``silhouettes``), as the engine leaves it."""

    @staticmethod
    def forward(ctx, shape, background, dtype, device, *inputs):
        ctx.likes = [like(t) for t in inputs]
        batch, height, width = shape
        images = torch.zeros(batch, 4, height, width, dtype=dtype, device=device)
        images[:, :3] = torch.tensor(background, dtype=dtype, device=device)[:, None, None]
        return images

    @staticmethod
    def backward(ctx, grad_images):
        zeros = (torch.zeros(lk.shape, dtype=lk.dtype, device=lk.device) for lk in ctx.likes)
        return (None, None, None, None, *zeros)


def _nothing(batch, settings, background, like_tensor, *inputs):
    """:class:`NothingToRender`'s images for ``batch`` meshes with ``settings``."""
    height, width = settings.shape
    return NothingToRender.apply((batch, height, width), background, like_tensor.dtype,
                                 like_tensor.device, *inputs)


class SoftRasterizeFunction(torch.autograd.Function):
    """SoftRas's ``SoftRasterizeFunction`` on softvk's engine: float32 on the device; float64
    (what ``torch.autograd.gradcheck`` makes; SoftRas's kernels compute doubles in double) on
    the f64 CPU twin, forward and backward, never float32 behind a float64 result."""

    @staticmethod
    def forward(ctx, face_vertices, textures, settings):
        ctx.likes = (like(face_vertices), like(textures))
        images_like = Like(face_vertices.device, face_vertices.dtype, None)
        if face_vertices.dtype == torch.float64:
            ctx.double = (face_vertices.detach(), textures.detach(), settings)
            return _images(round_trip(_native.reference_rasterize, face_vertices, textures,
                                      settings, back=images_like))
        ctx.double = None
        images, ctx.raster = round_trip(_native.rasterize, face_vertices, textures, settings,
                                        back=(images_like, None))
        return _images(images)

    @staticmethod
    def backward(ctx, grad_images):
        needs = ctx.needs_input_grad[:2]
        if not any(needs):
            return None, None, None
        wanted = _wanted(ctx.likes, needs)
        if ctx.double is not None:
            face_vertices, textures, settings = ctx.double
            d_vertices, d_textures = round_trip(
                _native.reference_rasterize_grad, face_vertices, textures, settings,
                grad_images.detach().permute(0, 2, 3, 1), back=wanted,
            )
        else:
            upstream, alpha_only = _upstream(grad_images)
            d_vertices, d_textures, _ = round_trip(ctx.raster.backward, upstream, alpha_only,
                                                   back=wanted)
        return (*_picked((d_vertices, d_textures), needs), None)


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

    Faces or textures that are not finite, and image sizes out of range or too large for the
    device, raise ``ValueError``; no faces render what SoftRas renders of them, the background
    with alpha 0 (gradients zero).
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
    # Positions first: non-finite ones make non-finite lit textures on the composed steps.
    _checks.finite("face_vertices", face_vertices)
    _checks.finite("textures", textures)
    if face_vertices.dim() == 4 and 0 in face_vertices.shape[:2]:
        if textures.dim() != 4 or tuple(textures.shape[:2]) != tuple(face_vertices.shape[:2]):
            raise ValueError(f"softvk: textures has shape {list(textures.shape)}; expected "
                             f"[{face_vertices.shape[0]}, {face_vertices.shape[1]}, *, 3]")
        return _nothing(face_vertices.shape[0], settings, _as_list(background_color),
                        face_vertices, face_vertices, textures)
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
        images, ctx.raster = round_trip(
            _native.render_mesh, vertices, faces.long(), textures, view_mesh, cameras, lighting,
            settings, back=(Like(vertices.device, vertices.dtype, None), None),
        )
        ctx.likes = (like(vertices), like(textures), like(eyes))
        return _images(images)

    @staticmethod
    def backward(ctx, grad_images):
        needs = ctx.needs_input_grad[:3]
        if not any(needs):
            return (None,) * 7
        upstream, alpha_only = _upstream(grad_images)
        grads = round_trip(ctx.raster.backward, upstream, alpha_only, needs[2],
                           back=_wanted(ctx.likes, needs))
        return (*_picked(grads, needs), None, None, None, None)


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

    Float face indices raise ``TypeError``; indices outside the vertices, textures or lights
    that are not finite, and image sizes out of range or too large for the device raise
    ``ValueError``. No faces render the background with alpha 0 (gradients zero).
    """
    if vertices.dim() == 2:
        vertices = vertices.unsqueeze(0)
    # float64 meshes go through SoftRas's composed steps (softvk.soft_renderer), whose
    # rasterizer computes doubles on the f64 twin; the engine's camera and lights are float32.
    _check_dtypes("render_mesh", (torch.float32,), vertices=vertices, textures=textures)
    batch = vertices.shape[0]
    faces = faces.detach()
    _checks.face_indices("faces", faces, int(vertices.shape[1]))
    if faces.dim() == 3:
        if bool(torch.any(faces != faces[:1])):
            raise ValueError("softvk: render_mesh needs the same faces for every mesh of a batch")
        faces = faces[0] if faces.shape[0] else faces.reshape(-1, 3)
    if textures is None:
        if texture_type == "vertex":
            textures = torch.ones(batch, vertices.shape[1], 3, dtype=vertices.dtype)
        else:
            textures = torch.ones(batch, faces.shape[0], 1, 3, dtype=vertices.dtype)
        textures = textures.to(vertices.device)
    _checks.finite("textures", textures)
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
            eyes = np.stack([0 * distance, 0 * distance, -distance], axis=1)
            eyes = torch.tensor(eyes.tolist(), dtype=vertices.dtype, device=vertices.device)
        eyes = eyes.reshape(-1, 3)
        if eyes.shape[0] == 1 and batch > 1:
            eyes = eyes.expand(batch, 3)
        if eyes.shape[0] != batch:
            raise ValueError(f"softvk: {eyes.shape[0]} eyes for a batch of {batch} meshes")
        cameras = [
            ("look_at", tuple(e), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0),
             float(a) if perspective else None, float(viewing_scale))
            for e, a in zip(eyes.detach().double().tolist(), angles)
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
            for m, c in zip(matrices.detach().double().reshape(batch, 12).tolist(), coeffs.tolist())
        ]
        eyes = torch.zeros(batch, 3, dtype=vertices.dtype, device=vertices.device)
    else:
        raise ValueError(f"softvk: unknown camera_mode {camera_mode!r}")

    lights = dict(light_intensity_ambient=light_intensity_ambient,
                  light_color_ambient=light_color_ambient,
                  light_intensity_directionals=light_intensity_directionals,
                  light_color_directionals=light_color_directionals,
                  light_directions=light_directions)
    for name, value in lights.items():
        _checks.finite(name, value)
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
    if batch == 0 or faces.shape[0] == 0:
        background = [0.0] * 3 if silhouettes else _as_list(background_color)
        return _nothing(batch, settings, background, vertices, vertices, textures, eyes)
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
