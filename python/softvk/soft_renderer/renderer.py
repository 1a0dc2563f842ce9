"""SoftRas's renderer: lighting, then camera, then soft rasterization."""

import torch.nn as nn

from .lighting import Lighting
from .mesh import Mesh
from .rasterizer import SoftRasterizer
from .transform import Transform

__all__ = ["SoftRenderer"]


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
        # A fast path goes here: when the engine can run lighting, camera and rasterization in
        # one call for these settings, dispatch to it and return; everything else falls through
        # to the composed steps below, which stay the reference.
        return self._render_composed(mesh, mode)

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
