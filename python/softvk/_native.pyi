"""Type stubs of ``softvk._native``, the engine as Python sees it (PyO3; python/src/lib.rs).

Arrays are numpy arrays, C-contiguous; images are ``[views, H, W, 4]`` RGBA, row 0 at the top.
"""

from os import PathLike
from typing import List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
I32 = npt.NDArray[np.int32]
U32 = npt.NDArray[np.uint32]
U8 = npt.NDArray[np.uint8]
_Path = Union[str, "PathLike[str]"]
_Vec3 = Tuple[float, float, float]

# ('look_at', eye, at, up, viewing_angle_degrees_or_None, orthographic_scale), or
# ('projection', P (12 floats, row-major 3×4), dist_coeffs (5), orig_size).
Camera = Union[
    Tuple[str, Sequence[float], Sequence[float], Sequence[float], Optional[float], float],
    Tuple[str, Sequence[float], Sequence[float], float],
]
# (ambient intensity, ambient colour, [(intensity, colour, direction), ...])
Lights = Tuple[float, Sequence[float], Sequence[Tuple[float, Sequence[float], Sequence[float]]]]

class Settings:
    """One render's settings: SoftRas's rasterizer arguments, the image size and how faces meet
    pixels (tiled with a tile edge, or SoftRas's brute-force loop)."""

    def __init__(
        self,
        width: int,
        height: int,
        *,
        sigma: float = 1e-5,
        gamma: float = 1e-4,
        near: float = 1.0,
        far: float = 100.0,
        eps: float = 1e-3,
        dist_eps: float = 1e-4,
        dist_func: str = "euclidean",
        aggr_func_rgb: str = "softmax",
        aggr_func_alpha: str = "prod",
        background_color: _Vec3 = (0.0, 0.0, 0.0),
        fill_back: bool = True,
        texture_type: str = "surface",
        tile: int = 8,
        brute: bool = False,
        silhouettes: bool = False,
    ) -> None: ...
    @property
    def shape(self) -> Tuple[int, int]:
        """``(height, width)`` of the images."""

class FragmentMemory:
    """The device-written memory that :func:`rasterize_fragments`' arrays view (their base);
    reused by a later call once they are all dropped."""

class Raster:
    """A render kept on the device for its backward."""

    def backward(
        self, grad_images: F32, alpha_only: bool = False, eyes: bool = False
    ) -> Tuple[F32, F32, Optional[F32]]:
        """dL/d(positions), dL/d(textures) and (``render_mesh`` with ``eyes``) dL/d(eyes),
        given dL/d(images) ``[views, H, W, 4]``."""
    def release(self) -> None:
        """Frees the render's device buffers now (its backward is gone)."""

def rasterize(face_vertices: F32, textures: F32, settings: Settings) -> Tuple[F32, Raster]:
    """SoftRas's ``soft_rasterize``: ``[B, F, 3, 3]`` screen-space faces and ``[B, F, R², 3]``
    (surface) or ``[B, F, 3, 3]`` (vertex) textures to images ``[B, H, W, 4]``."""

def reference_rasterize(face_vertices: F64, textures: F64, settings: Settings) -> F64:
    """The f64 CPU twin of :func:`rasterize`."""

def reference_rasterize_grad(
    face_vertices: F64, textures: F64, settings: Settings, grad_images: F64
) -> Tuple[F64, F64]:
    """The f64 twin's backward of :func:`reference_rasterize`: dL/d(face vertices) and
    dL/d(textures) given dL/d(images) ``[B, H, W, 4]``."""

FragmentSettings = Tuple[int, int, float, int, bool, bool, bool]
"""``(height, width, blur_radius, faces_per_pixel, perspective_correct,
clip_barycentric_coords, cull_backfaces)``: PyTorch3D's rasterization arguments."""

def rasterize_fragments(
    face_verts: F32,
    meshes: Sequence[Tuple[int, int]],
    neighbors: Optional[I64],
    settings: FragmentSettings,
) -> Tuple[I64, F32, F32, F32]:
    """PyTorch3D's rasterizer on the device: packed projected faces ``[F, 3, 3]`` and each
    mesh's ``(first face, face count)`` to ``(pix_to_face, zbuf, bary_coords, dists)``,
    ``[N, H, W, K]`` (the barycentrics ``[N, H, W, K, 3]``). ``neighbors``: the other half of
    each face PyTorch3D's near-plane clipping cut in two, or -1."""

def rasterize_fragments_grad(
    face_verts: F32,
    meshes: Sequence[Tuple[int, int]],
    pix_to_face: I64,
    grad_zbuf: F32,
    grad_bary: F32,
    grad_dists: F32,
    settings: FragmentSettings,
) -> F32:
    """The backward of :func:`rasterize_fragments` to the face vertices ``[F, 3, 3]``."""

def reference_fragments(
    face_verts: F64,
    meshes: Sequence[Tuple[int, int]],
    neighbors: Optional[I64],
    settings: FragmentSettings,
) -> Tuple[I64, F64, F64, F64]:
    """The f64 CPU twin of :func:`rasterize_fragments`."""

def reference_fragments_grad(
    face_verts: F64,
    meshes: Sequence[Tuple[int, int]],
    pix_to_face: I64,
    grad_zbuf: F64,
    grad_bary: F64,
    grad_dists: F64,
    settings: FragmentSettings,
) -> F64:
    """The f64 twin's backward of :func:`reference_fragments`."""

def fragments_time_passes() -> None:
    """From now on, the fragment rasterizer times its passes with GPU timestamps."""

def fragments_pass_times() -> List[Tuple[str, int, float]]:
    """``(name, depth, ms)`` of every fragment pass timed since the last call."""

class NvTopologyHash:
    """The edge adjacency of a triangle array (:func:`nv_topology_hash`), for
    :func:`nv_antialias`."""

    @property
    def triangle_count(self) -> int:
        """The number of triangles it was built from."""

def nv_rasterize(
    pos: F32,
    tri: I32,
    height: int,
    width: int,
    ranges: Optional[I32] = None,
    previous: Optional[U32] = None,
) -> Tuple[F32, F32, U32]:
    """nvdiffrast's ``rasterize``: clip-space ``pos`` ``[B, V, 4]`` (instanced) or ``[V, 4]``
    with ``ranges`` ``[B, 2]``, ``tri`` ``[T, 3]``, to ``(rast, rast_db, keys)``: ``(u, v, z/w,
    id + 1)`` and ``(du/dX, du/dY, dv/dX, dv/dY)`` ``[B, H, W, 4]`` (row 0 at the bottom) and
    each pixel's depth key ``[B, H, W, 2]``; with a layer's keys as ``previous``, the next
    depth-peeling layer."""

def nv_rasterize_grad(
    pos: F32,
    tri: I32,
    rast: F32,
    dy: F32,
    ddb: Optional[F32] = None,
    ranges: Optional[I32] = None,
) -> F32:
    """The backward of :func:`nv_rasterize` to ``pos`` (its shape), given the gradients of
    ``rast`` (``dy``) and of ``rast_db`` (``ddb``), ``[B, H, W, 4]``."""

def nv_interpolate(
    attr: F32,
    rast: F32,
    tri: I32,
    rast_db: Optional[F32] = None,
    diff: Sequence[int] = (),
) -> Tuple[F32, F32]:
    """nvdiffrast's ``interpolate``: ``attr`` ``[V, A]``, ``[1, V, A]`` or ``[B, V, A]`` to
    ``(out [B, H, W, A], out_da [B, H, W, 2 len(diff)])`` (``out_da`` needs ``rast_db``)."""

def nv_interpolate_grad(
    attr: F32,
    rast: F32,
    tri: I32,
    dy: F32,
    rast_db: Optional[F32] = None,
    dda: Optional[F32] = None,
    diff: Sequence[int] = (),
) -> Tuple[F32, F32, Optional[F32]]:
    """The backward of :func:`nv_interpolate`: dL/d(attr), dL/d(rast) and (with ``rast_db``)
    dL/d(rast_db)."""

def nv_topology_hash(tri: I32) -> NvTopologyHash:
    """nvdiffrast's ``antialias_construct_topology_hash``."""

def nv_antialias(
    color: F32, rast: F32, pos: F32, tri: I32, topology: NvTopologyHash
) -> F32:
    """nvdiffrast's ``antialias`` of ``color`` ``[B, H, W, C]`` (same shape out)."""

def nv_antialias_grad(
    color: F32,
    rast: F32,
    pos: F32,
    tri: I32,
    topology: NvTopologyHash,
    dy: F32,
    pos_gradient_boost: float,
) -> Tuple[F32, F32]:
    """The backward of :func:`nv_antialias`: dL/d(color) and dL/d(pos) (times
    ``pos_gradient_boost``)."""

class NvTextureMip:
    """A texture's mip levels (:func:`nv_texture_construct_mip`), for :func:`nv_texture`."""

    texture_shape: List[int]
    max_mip_level: int
    cube_mode: bool

def nv_texture_construct_mip(
    tex: F32, max_mip_level: Optional[int] = None, cube_mode: bool = False
) -> NvTextureMip:
    """nvdiffrast's ``texture_construct_mip`` of a ``[B, H, W, C]`` texture, or with
    ``cube_mode`` of a ``[B, 6, S, S, C]`` cube map."""

def nv_texture(
    tex: F32,
    uv: F32,
    filter: str,
    boundary: str,
    uv_da: Optional[F32] = None,
    mip_level_bias: Optional[F32] = None,
    mip: Optional[NvTextureMip] = None,
    mip_levels: Optional[List[F32]] = None,
    max_mip_level: Optional[int] = None,
) -> F32:
    """nvdiffrast's ``texture``: ``[B, h, w, C]`` (``boundary='cube'``: ``tex`` a cube map
    ``[B, 6, S, S, C]``, ``uv`` directions ``[B, h, w, 3]``, ``uv_da`` ``[B, h, w, 6]``)."""

def nv_texture_grad(
    tex: F32,
    uv: F32,
    dy: F32,
    filter: str,
    boundary: str,
    uv_da: Optional[F32] = None,
    mip_level_bias: Optional[F32] = None,
    mip: Optional[NvTextureMip] = None,
    mip_levels: Optional[List[F32]] = None,
    max_mip_level: Optional[int] = None,
) -> Tuple[F32, F32, Optional[F32], Optional[F32], List[F32]]:
    """The backward of :func:`nv_texture`: dL/d(tex), dL/d(uv), dL/d(uv_da),
    dL/d(mip_level_bias) (None where not an input) and one per custom mip level."""

def render_mesh(
    vertices: F32,
    faces: I64,
    textures: F32,
    view_mesh: I64,
    cameras: Sequence[Camera],
    lighting: Lights,
    settings: Settings,
) -> Tuple[F32, Raster]:
    """World-space meshes ``[B, V, 3]`` with shared faces ``[F, 3]`` through cameras and
    lights, in the engine: view ``i`` shows mesh ``view_mesh[i]``."""

def device_name() -> str:
    """The name of the Vulkan device softvk renders on (opening it if need be)."""

def release_cached_scenes() -> None:
    """Frees the scenes kept for reuse by the next render of their kind, and the spare memory of
    fragment outputs."""

def is_forked_child() -> bool:
    """Whether this process is a fork of the one that opened the device."""

def read_exr(path: _Path) -> F32:
    """The first RGBA layer of an EXR as ``[H, W, 4]``."""

def write_exr(path: _Path, image: F32) -> None:
    """``[H, W, 4]`` RGBA as a lossless EXR, written whole or not at all."""

def read_rgb(path: _Path) -> F32:
    """An image as ``[H, W, 3]`` in [0, 1]."""

def write_png(path: _Path, image: U8) -> None:
    """``[H, W]`` or ``[H, W, 1 | 3 | 4]`` bytes as an 8-bit PNG, written whole or not at all."""
