"""The soft rasterizer as a module: a mesh in screen space to images (SPEC §2)."""

import torch
import torch.nn as nn
import torch.nn.functional as F

from .. import _checks
from . import functional as srf

__all__ = ["SoftRasterizer"]


class SoftRasterizer(nn.Module):
    """Soft rasterization of a mesh whose vertices are in screen space (x, y, depth).

    Every argument is an attribute that may be changed between calls (``sigma_val`` and
    ``gamma_val`` through :meth:`SoftRenderer.set_sigma` / ``set_gamma`` in SoftRas's scripts).
    """

    def __init__(self, image_size=256, background_color=[0, 0, 0], near=1, far=100,
                 anti_aliasing=False, fill_back=False, eps=1e-3,
                 sigma_val=1e-5, dist_func="euclidean", dist_eps=1e-4,
                 gamma_val=1e-4, aggr_func_rgb="softmax", aggr_func_alpha="prod",
                 texture_type="surface"):
        """
        Args:
            image_size: output height = width in pixels, or a ``(height, width)`` pair (SoftRas
                renders square images only; the shorter side spans [-1, 1] in screen space).
            background_color: RGB.
            near, far: depth range of the colour aggregation.
            anti_aliasing: render at twice the size and average 2×2 blocks.
            fill_back: faces are double-sided (SoftRas's default here is ``False``;
                :class:`SoftRenderer` passes ``True``).
            eps: background weight of the softmax colour aggregation.
            sigma_val: sharpness of the coverage.
            dist_func: ``'euclidean'``, ``'barycentric'`` or ``'hard'``.
            dist_eps: coverage below which a face is ignored.
            gamma_val: temperature of the softmax over depth.
            aggr_func_rgb: ``'softmax'`` or ``'hard'``.
            aggr_func_alpha: ``'prod'``, ``'sum'`` or ``'hard'``.
            texture_type: ``'surface'`` or ``'vertex'``.
        """
        super(SoftRasterizer, self).__init__()
        if dist_func not in ("hard", "euclidean", "barycentric"):
            raise ValueError("Distance function only support hard, euclidean and barycentric")
        if aggr_func_rgb not in ("hard", "softmax"):
            raise ValueError("Aggregate function(rgb) only support hard and softmax")
        if aggr_func_alpha not in ("hard", "prod", "sum"):
            raise ValueError("Aggregate function(a) only support hard, prod and sum")
        if texture_type not in ("surface", "vertex"):
            raise ValueError("Texture type only support surface and vertex")

        self.image_size = image_size
        # A copy, so that editing one renderer's colour cannot edit the shared default.
        if isinstance(background_color, (list, tuple)):
            background_color = list(background_color)
        self.background_color = background_color
        self.near = near
        self.far = far
        self.anti_aliasing = anti_aliasing
        self.eps = eps
        self.fill_back = fill_back
        self.sigma_val = sigma_val
        self.dist_func = dist_func
        self.dist_eps = dist_eps
        self.gamma_val = gamma_val
        self.aggr_func_rgb = aggr_func_rgb
        self.aggr_func_alpha = aggr_func_alpha
        self.texture_type = texture_type

    def forward(self, mesh, mode=None):
        """Renders ``mesh`` (vertices in screen space, textures already lit) as RGBA
        [batch, 4, H, W]. ``mode`` is accepted and ignored, as SoftRas ignores it; softvk's
        alpha-only and depth renders are :func:`softvk.torch.render`'s."""
        return _rasterize(self, mesh.face_vertices, mesh.face_textures, self.texture_type,
                          self.aggr_func_rgb, self.background_color)


def scaled_size(image_size, factor):
    """``image_size`` (an int, or a ``(height, width)`` pair) times ``factor``, checked
    (``softvk._checks.image_size``)."""
    height, width = _checks.image_size(image_size, factor)
    return (height, width) if isinstance(image_size, (tuple, list)) else height


def _rasterize(rasterizer, face_vertices, textures, texture_type, aggr_func_rgb,
               background_color):
    """``functional.soft_rasterize`` with the rasterizer's settings (and anti-aliasing)."""
    r = rasterizer
    image_size = scaled_size(r.image_size, 2 if r.anti_aliasing else 1)
    images = srf.soft_rasterize(face_vertices, textures, image_size, background_color,
                                r.near, r.far, r.fill_back, r.eps, r.sigma_val, r.dist_func,
                                r.dist_eps, r.gamma_val, aggr_func_rgb, r.aggr_func_alpha,
                                texture_type)
    if r.anti_aliasing:
        images = F.avg_pool2d(images, kernel_size=2, stride=2)
    return images


def render_depth(rasterizer, mesh):
    """[batch, H, W]: the depth of the nearest face covering each pixel (``far`` where none
    does), differentiable in the vertices, of a mesh in screen space, with ``rasterizer``'s
    settings. It is rendered with ``aggr_func_rgb='hard'`` and the inverse depths as vertex
    colours: interpolating those with the clipped barycentrics gives exactly ``1 / z`` of SPEC
    §2's depth."""
    face_vertices = mesh.face_vertices
    textures = _inverse_depth_colors(face_vertices)
    images = _rasterize(rasterizer, face_vertices, textures, "vertex", "hard", [0, 0, 0])
    inverse = images[:, 0]
    covered = inverse > 0
    safe = torch.where(covered, inverse, torch.ones_like(inverse))
    return torch.where(covered, 1.0 / safe, torch.full_like(inverse, float(rasterizer.far)))


def _inverse_depth_colors(face_vertices):
    """[batch, F, 3, 3] vertex colours (1/z, 1/z, 1/z) per corner; 0 at or behind the eye."""
    z = face_vertices[:, :, :, 2]
    positive = z > 0
    inverse = torch.where(positive, 1.0 / torch.where(positive, z, torch.ones_like(z)),
                          torch.zeros_like(z))
    return inverse[..., None].expand(*inverse.shape, 3)
