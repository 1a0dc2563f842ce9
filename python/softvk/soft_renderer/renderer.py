"""SoftRas's renderer: lighting, then camera, then soft rasterization."""

import torch
import torch.nn as nn
import torch.nn.functional as F

from . import functional as srf
from .lighting import AmbientLighting, DirectionalLighting, Lighting
from .mesh import Mesh
from .rasterizer import SoftRasterizer, render_depth, scaled_size
from .transform import LookAt, Projection, Transform

__all__ = ["SoftRenderer"]


def _plain(value, size):
    """``value`` as a list of ``size`` floats when it is one setting for the whole batch (a
    number, a list, or a tensor of ``size`` elements that needs no gradient); else ``None``."""
    if isinstance(value, torch.Tensor):
        if value.requires_grad or value.numel() != size:
            return None
        return [float(v) for v in value.detach().reshape(-1).tolist()]
    flat = [value] if size == 1 and not hasattr(value, "__len__") else list(value)
    if len(flat) != size:
        return None
    return [float(v) for v in flat]


def _engine_lights(lighting):
    """SoftRas's lights as ``softvk.torch.render_mesh`` takes them, or ``None`` when any of them
    differs per mesh of the batch or asks for a gradient."""
    ambient = _plain(lighting.ambient.light_intensity, 1)
    ambient_color = _plain(lighting.ambient.light_color, 3)
    if ambient is None or ambient_color is None:
        return None
    intensities, colors, directions = [], [], []
    for d in lighting.directionals:
        values = (_plain(d.light_intensity, 1), _plain(d.light_color, 3),
                  _plain(d.light_direction, 3))
        if any(v is None for v in values):
            return None
        intensities += values[0]
        colors.append(values[1])
        directions.append(values[2])
    if not intensities:  # no directional light: one of intensity 0
        intensities, colors, directions = [0.0], [[0.0] * 3], [[0.0, 1.0, 0.0]]
    return dict(light_intensity_ambient=ambient[0], light_color_ambient=ambient_color,
                light_intensity_directionals=intensities, light_color_directionals=colors,
                light_directions=directions)


def _per_view(value, batch):
    """A camera setting as one float, or one float per mesh of the batch; ``None`` when it asks
    for a gradient or has another size."""
    if isinstance(value, torch.Tensor):
        if value.requires_grad or value.numel() not in (1, batch):
            return None
        flat = [float(v) for v in value.detach().reshape(-1).tolist()]
        return flat[0] if len(flat) == 1 else flat
    if isinstance(value, (int, float)):
        return float(value)
    return None


# The functions SoftRas's modules call (``srf.<name>``, looked up at each call). The engine's
# path computes what these compute; a user who replaced one gets the composed steps instead.
_SRF_FUNCTIONS = ("soft_rasterize", "look_at", "perspective", "orthogonal", "projection",
                  "ambient_lighting", "directional_lighting", "face_vertices", "vertex_normals")
_ORIGINAL_SRF = {name: getattr(srf, name) for name in _SRF_FUNCTIONS}


def _stock(module, cls):
    """Whether ``module`` is exactly a ``cls`` as this package made it: not a subclass, no
    ``forward`` of its own on the instance, no forward hooks (its own or global)."""
    from torch.nn.modules import module as torch_module

    if type(module) is not cls or "forward" in vars(module):
        return False
    hooks = [getattr(module, name, None) for name in ("_forward_hooks", "_forward_pre_hooks")]
    hooks += [getattr(torch_module, name, None)
              for name in ("_global_forward_hooks", "_global_forward_pre_hooks")]
    return not any(h for h in hooks)


def _stock_steps(renderer):
    """Whether the renderer's lighting, camera and rasterizer are SoftRas's own, unreplaced,
    and call SoftRas's own functions: only then does the engine's path compute what they do.
    A module is recognised before any of its attributes is read: one of the user's need have
    none of SoftRas's (``ambient``, ``transformer``), as SoftRas only calls it."""
    lighting, transform = renderer.lighting, renderer.transform
    steps = [(lighting, Lighting), (transform, Transform), (renderer.rasterizer, SoftRasterizer)]
    if not all(_stock(m, cls) for m, cls in steps):
        return False
    if type(lighting.directionals) is not nn.ModuleList:
        return False
    parts = [(lighting.ambient, AmbientLighting)]
    parts += [(d, DirectionalLighting) for d in lighting.directionals]
    if not all(_stock(m, cls) for m, cls in parts):
        return False
    if type(transform.transformer) not in (LookAt, Projection):
        return False
    if not _stock(transform.transformer, type(transform.transformer)):
        return False
    return all(getattr(srf, name) is f for name, f in _ORIGINAL_SRF.items())


class SoftRenderer(nn.Module):
    """Renders meshes as SoftRas's ``SoftRenderer`` does, on softvk's engine.

    ``self.lighting`` (:class:`Lighting`), ``self.transform`` (:class:`Transform`) and
    ``self.rasterizer`` (:class:`SoftRasterizer`) hold the settings, and may be changed between
    calls (``renderer.transform.set_eyes_from_angles(...)``, ``renderer.set_sigma(...)``).

    Unlike SoftRas, rendering does not modify the mesh it is given: SoftRas's ``render_mesh``
    left the mesh lit and in screen space (hence the ``mesh.reset_()`` in its scripts, which
    stays harmless here).
    """

    def __init__(self, image_size=256, background_color=[0, 0, 0], near=1, far=100,
                 anti_aliasing=False, fill_back=True, eps=1e-3,
                 sigma_val=1e-5, dist_func="euclidean", dist_eps=1e-4,
                 gamma_val=1e-4, aggr_func_rgb="softmax", aggr_func_alpha="prod",
                 texture_type="surface",
                 camera_mode="projection",
                 P=None, dist_coeffs=None, orig_size=512,
                 perspective=True, viewing_angle=30, viewing_scale=1.0,
                 eye=None, camera_direction=[0, 0, 1],
                 light_mode="surface",
                 light_intensity_ambient=0.5, light_color_ambient=[1, 1, 1],
                 light_intensity_directionals=0.5, light_color_directionals=[1, 1, 1],
                 light_directions=[0, 1, 0]):
        """
        Args:
            image_size, background_color, near, far, anti_aliasing, fill_back, eps, sigma_val,
            dist_func, dist_eps, gamma_val, aggr_func_rgb, aggr_func_alpha, texture_type:
                the rasterizer's (:class:`SoftRasterizer`).
            camera_mode, P, dist_coeffs, orig_size, perspective, viewing_angle, viewing_scale,
            eye, camera_direction: the camera's (:class:`Transform`). As in SoftRas the default
                ``camera_mode='projection'`` needs ``P``; SoftRas's scripts use
                ``camera_mode='look_at'``.
            light_mode, light_intensity_ambient, light_color_ambient,
            light_intensity_directionals, light_color_directionals, light_directions:
                the lighting's (:class:`Lighting`).
        """
        super(SoftRenderer, self).__init__()
        self.lighting = Lighting(light_mode,
                                 light_intensity_ambient, light_color_ambient,
                                 light_intensity_directionals, light_color_directionals,
                                 light_directions)
        self.transform = Transform(camera_mode,
                                   P, dist_coeffs, orig_size,
                                   perspective, viewing_angle, viewing_scale,
                                   eye, camera_direction)
        self.rasterizer = SoftRasterizer(image_size, background_color, near, far,
                                         anti_aliasing, fill_back, eps,
                                         sigma_val, dist_func, dist_eps,
                                         gamma_val, aggr_func_rgb, aggr_func_alpha,
                                         texture_type)

    def set_sigma(self, sigma):
        """Sets the coverage sharpness σ."""
        self.rasterizer.sigma_val = sigma

    def set_gamma(self, gamma):
        """Sets the depth-softmax temperature γ."""
        self.rasterizer.gamma_val = gamma

    def set_texture_mode(self, mode):
        """Lights and samples ``'surface'`` (per-face) or ``'vertex'`` textures."""
        if mode not in ("vertex", "surface"):
            raise ValueError("Mode only support surface and vertex")
        self.lighting.light_mode = mode
        self.rasterizer.texture_type = mode

    def render_mesh(self, mesh, mode=None):
        """Renders a :class:`Mesh`: [batch, 4, H, W] RGBA. ``mode`` is passed on to the
        rasterizer, which ignores it, as SoftRas's does (softvk's alpha-only and depth renders
        are :func:`softvk.torch.render`'s). ``mesh`` is left as it was."""
        return self._render(mesh, "rgba", mode)

    def forward(self, vertices, faces, textures=None, mode=None, texture_type="surface"):
        """Renders vertices [batch, V, 3], faces [batch, F, 3] and textures (see :class:`Mesh`;
        ``None`` is white): [batch, 4, H, W] RGBA, whatever ``mode`` says (as SoftRas)."""
        mesh = Mesh(vertices, faces, textures=textures, texture_type=texture_type)
        return self.render_mesh(mesh, mode)

    def _render(self, mesh, what, mode=None):
        """``what``: ``'rgba'`` [batch, 4, H, W], ``'silhouettes'`` [batch, H, W] (alpha alone)
        or ``'depth'`` [batch, H, W]. In the engine when it computes what the composed steps
        compute (:meth:`_engine_arguments`), else through the composed steps."""
        self.set_texture_mode(mesh.texture_type)
        if what == "depth":
            return render_depth(self.rasterizer, self._camera_space(mesh))
        fast = self._engine_arguments(mesh)
        if fast is not None:
            return self._render_in_engine(mesh, what, fast)
        images = self._render_composed(mesh, mode)
        return images[:, 3] if what == "silhouettes" else images

    def _engine_arguments(self, mesh):
        """The arguments of ``softvk.torch.render_mesh`` that render ``mesh`` as the composed
        steps would, or ``None`` when it cannot say so for sure. The composed steps are taken
        for float64 meshes (computed in double there), a mesh that is not exactly a
        :class:`Mesh` or whose back faces were filled in (``fill_back_``), lighting, camera or
        rasterizer modules that were replaced, subclassed, given a ``forward`` or hooks, or
        whose functions (``functional.*``) were replaced, a ``'look'`` camera, lights or
        faces that differ per mesh of the batch, and any light or camera setting that asks for
        a gradient. Every attribute is read here, at the call, as the composed steps read it."""
        if type(mesh) is not Mesh or getattr(mesh, "_fill_back", False):
            return None
        if mesh.vertices.dtype != torch.float32 or mesh.textures.dtype != torch.float32:
            return None
        if not _stock_steps(self):
            return None
        light = _engine_lights(self.lighting)
        if light is None:
            return None
        faces = mesh.faces
        if faces.shape[0] > 1 and bool(torch.any(faces != faces[:1])):
            return None
        batch = mesh.batch_size
        transformer = self.transform.transformer
        if type(transformer) is LookAt:
            eyes = transformer._eye
            if not isinstance(eyes, torch.Tensor):
                eyes = torch.tensor(eyes, dtype=torch.float64)
            if eyes.numel() != 3 and (eyes.dim() != 2 or eyes.shape[0] != batch):
                return None
            angle = _per_view(transformer.viewing_angle, batch)
            scale = _per_view(transformer.viewing_scale, 1)
            if angle is None or scale is None:
                return None
            camera = dict(camera_mode="look_at", eyes=eyes,
                          perspective=bool(transformer.perspective),
                          viewing_angle=angle, viewing_scale=scale)
        else:
            P, coeffs = transformer.P, transformer.dist_coeffs
            if P.shape[0] not in (1, batch) or any(
                isinstance(t, torch.Tensor) and t.requires_grad for t in (P, coeffs)
            ):
                return None
            camera = dict(camera_mode="projection", P=P, dist_coeffs=coeffs,
                          orig_size=transformer.orig_size)
        r = self.rasterizer
        raster = dict(background_color=r.background_color, near=r.near, far=r.far,
                      fill_back=r.fill_back, eps=r.eps, sigma_val=r.sigma_val,
                      dist_func=r.dist_func, dist_eps=r.dist_eps, gamma_val=r.gamma_val,
                      aggr_func_rgb=r.aggr_func_rgb, aggr_func_alpha=r.aggr_func_alpha,
                      texture_type=r.texture_type)
        return dict(camera, **raster, **light)

    def _render_in_engine(self, mesh, what, arguments):
        """Lighting, camera and rasterization in one engine call (``softvk.torch.render_mesh``):
        no screen-space faces or lit textures are built in Python."""
        import softvk.torch as st

        anti_aliasing = self.rasterizer.anti_aliasing
        size = scaled_size(self.rasterizer.image_size, 2 if anti_aliasing else 1)
        images = st.render_mesh(mesh.vertices, mesh.faces[0], mesh.textures, image_size=size,
                                silhouettes=what == "silhouettes", **arguments)
        if anti_aliasing:
            images = F.avg_pool2d(images, kernel_size=2, stride=2)
        return images[:, 3] if what == "silhouettes" else images

    def _render_composed(self, mesh, mode=None):
        """Lighting, then camera, then rasterization, each a module of its own, on a shallow
        copy of ``mesh`` so that the caller's mesh keeps its vertices and textures."""
        mesh = mesh._shallow_copy()
        mesh = self.lighting(mesh)
        mesh = self.transform(mesh)
        return self.rasterizer(mesh, mode)

    def _camera_space(self, mesh):
        """``mesh`` (a shallow copy) with its vertices through the camera, unlit."""
        mesh = mesh._shallow_copy()
        return self.transform(mesh)
