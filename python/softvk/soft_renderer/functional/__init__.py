"""SoftRas's functional interface (``import softvk.soft_renderer.functional as srf``).

Stateless functions on batched tensors: cameras (``look_at``, ``look``, ``perspective``,
``orthogonal``, ``projection``, ``get_points_from_angles``), lighting (``ambient_lighting``,
``directional_lighting``), mesh helpers (``face_vertices``, ``vertex_normals``), files
(``load_obj``, ``save_obj``, ``save_voxel``), ``voxelization``, and ``soft_rasterize``, which runs
on softvk's engine. Everything but ``soft_rasterize`` is plain torch and works on any device.
"""

from .ambient_lighting import ambient_lighting
from .directional_lighting import directional_lighting
from .face_vertices import face_vertices
from .get_points_from_angles import get_points_from_angles
from .load_obj import load_obj
from .look import look
from .look_at import look_at
from .orthogonal import orthogonal
from .perspective import perspective
from .projection import projection
from .save_obj import save_obj, save_voxel
from .soft_rasterize import soft_rasterize
from .vertex_normals import vertex_normals
from .voxelization import voxelization

__all__ = [
    "ambient_lighting",
    "directional_lighting",
    "face_vertices",
    "get_points_from_angles",
    "load_obj",
    "look",
    "look_at",
    "orthogonal",
    "perspective",
    "projection",
    "save_obj",
    "save_voxel",
    "soft_rasterize",
    "vertex_normals",
    "voxelization",
]
