"""SoftRas's Python interface on softvk's engine.

``import softvk.soft_renderer as sr`` in place of ``import soft_renderer as sr`` runs SoftRas's
scripts unchanged but for their ``.cuda()`` calls: the same classes (``Mesh``, ``SoftRenderer``,
``Transform``, ``Lighting``, ``SoftRasterizer``, ``LaplacianLoss``, ``FlattenLoss``), arguments,
defaults, shapes and images, with the soft rasterization running on any Vulkan device through
``softvk.torch``. ``softvk.soft_renderer.functional`` is SoftRas's ``soft_renderer.functional``.

Tensors may live on any device; meshes, cameras, lighting, losses and files are plain torch.
"""

from . import functional
from .lighting import AmbientLighting, DirectionalLighting, Lighting
from .losses import FlattenLoss, LaplacianLoss
from .mesh import Mesh
from .rasterizer import SoftRasterizer
from .renderer import SoftRenderer
from .transform import Look, LookAt, Projection, Transform

# The version of SoftRas's interface this module follows.
__version__ = "1.0.0"

__all__ = [
    "functional",
    "Mesh",
    "SoftRenderer",
    "Projection",
    "LookAt",
    "Look",
    "Transform",
    "AmbientLighting",
    "DirectionalLighting",
    "Lighting",
    "SoftRasterizer",
    "LaplacianLoss",
    "FlattenLoss",
]
