"""Lighting: ambient plus directional light multiplying the textures (SPEC §2)."""

import torch
import torch.nn as nn

from . import functional as srf
from .functional._convert import float_dtype

__all__ = ["AmbientLighting", "DirectionalLighting", "Lighting"]


class AmbientLighting(nn.Module):
    """``I_a c_a`` (``functional.ambient_lighting``)."""

    def __init__(self, light_intensity=0.5, light_color=(1, 1, 1)):
        super(AmbientLighting, self).__init__()
        self.light_intensity = light_intensity
        self.light_color = light_color

    def forward(self, light):
        return srf.ambient_lighting(light, self.light_intensity, self.light_color)


class DirectionalLighting(nn.Module):
    """``I_l c_l max(0, n . d_l)`` (``functional.directional_lighting``)."""

    def __init__(self, light_intensity=0.5, light_color=(1, 1, 1), light_direction=(0, 1, 0)):
        super(DirectionalLighting, self).__init__()
        self.light_intensity = light_intensity
        self.light_color = light_color
        self.light_direction = light_direction

    def forward(self, light, normals):
        return srf.directional_lighting(light, normals, self.light_intensity, self.light_color,
                                        self.light_direction)


class Lighting(nn.Module):
    """Ambient plus directional lights, in world space, multiplying a mesh's textures.

    ``light_mode='surface'`` lights each face with its face normal (surface textures);
    ``'vertex'`` lights each vertex with its vertex normal (vertex colours).
    """

    def __init__(self, light_mode="surface",
                 intensity_ambient=0.5, color_ambient=[1, 1, 1],
                 intensity_directionals=0.5, color_directionals=[1, 1, 1],
                 directions=[0, 1, 0]):
        super(Lighting, self).__init__()
        if light_mode not in ("surface", "vertex"):
            raise ValueError("Lighting mode only support surface and vertex")
        self.light_mode = light_mode
        self.ambient = AmbientLighting(intensity_ambient, color_ambient)
        self.directionals = nn.ModuleList(
            [DirectionalLighting(intensity_directionals, color_directionals, directions)]
        )

    def forward(self, mesh):
        """Multiplies ``mesh.textures`` by the light; returns ``mesh``."""
        dtype = float_dtype(mesh.vertices)
        if self.light_mode == "surface":
            light = torch.zeros(mesh.faces.shape, dtype=dtype, device=mesh.vertices.device)
            light = self.ambient(light)
            for directional in self.directionals:
                light = directional(light, mesh.surface_normals)
            mesh.textures = mesh.textures * light[:, :, None, :]
        elif self.light_mode == "vertex":
            light = torch.zeros(mesh.vertices.shape, dtype=dtype, device=mesh.vertices.device)
            light = self.ambient(light)
            for directional in self.directionals:
                light = directional(light, mesh.vertex_normals)
            mesh.textures = mesh.textures * light
        return mesh
