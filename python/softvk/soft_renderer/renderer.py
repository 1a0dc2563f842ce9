"""SoftRas's renderer: lighting, then camera, then soft rasterization."""

import torch
import torch.nn as nn
import torch.nn.functional as F

from .lighting import Lighting
from .mesh import Mesh
from .rasterizer import SoftRasterizer
from .transform import Transform

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
        """Renders a :class:`Mesh`: [batch, 4, H, W] RGBA for ``mode=None`` (see
        :meth:`SoftRasterizer.forward` for the other modes). ``mesh`` is left as it was."""
        self.set_texture_mode(mesh.texture_type)
        fast = self._engine_arguments(mesh, mode)
        if fast is not None:
            return self._render_in_engine(mesh, mode, fast)
        return self._render_composed(mesh, mode)

    def _engine_arguments(self, mesh, mode):
        """The arguments of ``softvk.torch.render_mesh`` that render ``mesh`` as the composed
        steps would, or ``None`` when it cannot: a ``'look'`` camera, lights that differ per
        mesh of the batch, faces that differ per mesh, a mesh whose back faces were filled in
        (``fill_back_``), or ``mode='depth'``."""
        if mode not in (None, "rgb", "silhouettes") or getattr(mesh, "_fill_back", False):
            return None
        light = _engine_lights(self.lighting)
        if light is None:
            return None
        faces = mesh.faces
        if faces.shape[0] > 1 and bool(torch.any(faces != faces[:1])):
            return None
        transformer = self.transform.transformer
        if self.transform.camera_mode == "look_at":
            eyes = transformer._eye
            if not isinstance(eyes, torch.Tensor):
                eyes = torch.tensor(eyes, dtype=torch.float64)
            if eyes.numel() != 3 and (eyes.dim() != 2 or eyes.shape[0] != mesh.batch_size):
                return None
            camera = dict(camera_mode="look_at", eyes=eyes, perspective=transformer.perspective,
                          viewing_angle=transformer.viewing_angle,
                          viewing_scale=transformer.viewing_scale)
        elif self.transform.camera_mode == "projection":
            P, coeffs = transformer.P, transformer.dist_coeffs
            if P.shape[0] not in (1, mesh.batch_size) or any(
                isinstance(t, torch.Tensor) and t.requires_grad for t in (P, coeffs)
            ):
                return None
            camera = dict(camera_mode="projection", P=P, dist_coeffs=coeffs,
                          orig_size=transformer.orig_size)
        else:
            return None
        r = self.rasterizer
        raster = dict(background_color=r.background_color, near=r.near, far=r.far,
                      fill_back=r.fill_back, eps=r.eps, sigma_val=r.sigma_val,
                      dist_func=r.dist_func, dist_eps=r.dist_eps, gamma_val=r.gamma_val,
                      aggr_func_rgb=r.aggr_func_rgb, aggr_func_alpha=r.aggr_func_alpha,
                      texture_type=r.texture_type)
        return dict(camera, **raster, **light)

    def _render_in_engine(self, mesh, mode, arguments):
        """Lighting, camera and rasterization in one engine call (``softvk.torch.render_mesh``):
        no screen-space faces or lit textures are built in Python."""
        import softvk.torch as st

        scale = 2 if self.rasterizer.anti_aliasing else 1
        images = st.render_mesh(mesh.vertices, mesh.faces[0], mesh.textures,
                                image_size=self.rasterizer.image_size * scale,
                                silhouettes=mode == "silhouettes", **arguments)
        if scale == 2:
            images = F.avg_pool2d(images, kernel_size=2, stride=2)
        if mode == "rgb":
            return images[:, :3]
        if mode == "silhouettes":
            return images[:, 3]
        return images

    def _render_composed(self, mesh, mode):
        """Lighting, then camera, then rasterization, each a module of its own, on a shallow
        copy of ``mesh`` so that the caller's mesh keeps its vertices and textures."""
        mesh = mesh._shallow_copy()
        mesh = self.lighting(mesh)
        mesh = self.transform(mesh)
        return self.rasterizer(mesh, mode)

    def forward(self, vertices, faces, textures=None, mode=None, texture_type="surface"):
        """Renders vertices [batch, V, 3], faces [batch, F, 3] and textures (see :class:`Mesh`;
        ``None`` is white)."""
        mesh = Mesh(vertices, faces, textures=textures, texture_type=texture_type)
        return self.render_mesh(mesh, mode)
