"""softvk: differentiable rendering (SoftRas soft rasterization) on Vulkan compute.

- :mod:`softvk.torch`: ``soft_rasterize`` (SoftRas's own operation) and ``render_mesh`` (camera,
  lighting and face set-up on the device) as ``torch.autograd.Function`` s.
- :mod:`softvk.soft_renderer`: SoftRas's Python interface (``import softvk.soft_renderer as sr``).
- :mod:`softvk.pytorch3d`: PyTorch3D's ``MeshRasterizer`` and ``rasterize_meshes``.
- :mod:`softvk.nvdiffrast.torch`: nvdiffrast's primitives (``import softvk.nvdiffrast.torch as dr``).

numpy is the one required dependency; torch is imported only by those two modules. The Vulkan
loader (libvulkan) is opened on the first render, on the device ``SOFTVK_DEVICE`` names (an
index or a part of its name; the first suitable one otherwise). One device context serves the
whole process; calls from several threads take turns on it, with the GIL released while the
device works. A forked child cannot use the context its parent opened (a clear error says so):
make the first softvk call in each process.
"""

from ._native import (
    Settings,
    device_name,
    is_forked_child,
    read_exr,
    reference_rasterize,
    reference_rasterize_grad,
    release_cached_scenes,
    write_exr,
)
from ._native import __version__

__all__ = [
    "Settings",
    "device_name",
    "is_forked_child",
    "read_exr",
    "reference_rasterize",
    "reference_rasterize_grad",
    "release_cached_scenes",
    "write_exr",
    "__version__",
]
