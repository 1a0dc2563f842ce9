"""PyTorch3D's mesh rasterizer on softvk: change one import.

    from softvk.pytorch3d import MeshRasterizer   # was: from pytorch3d.renderer import ...

``MeshRasterizer`` and ``rasterize_meshes`` are constructed and called as PyTorch3D's
(``cameras``, ``raster_settings``, ``**kwargs`` overrides), take PyTorch3D's own ``Meshes``
and cameras, and return PyTorch3D's ``Fragments``: the K nearest faces of every pixel
(``pix_to_face``, ``zbuf``, ``bary_coords``, ``dists``). Everything after the rasterizer
(``SoftSilhouetteShader``, ``SoftPhongShader``, ``HardPhongShader``, textures, lights,
blending) is PyTorch3D's own PyTorch and differentiates through the fragments unchanged.

What softvk does differently, and only this:

- **Where it runs**: on softvk's Vulkan device (any GPU, or lavapipe on a CPU), tiled, with
  exact binning: ``bin_size`` and ``max_faces_per_bin`` are accepted and change nothing, and no
  bin ever overflows. Tensors come back on the device they came from (through host copies,
  ``softvk._host.round_trip``).
- **Determinism**: the backward sums each face's gradient in a fixed order (per tile in pixel
  order, then tile by tile), with no float atomics: the same bits on every run.
- **Non-finite faces** (a NaN or infinite coordinate) raise ``ValueError`` naming the face;
  PyTorch3D's arithmetic makes NaN fragments of them. So do face indices outside their mesh's
  vertices (negative, or another mesh's: PyTorch3D's indexing wraps or reads them), and float
  indices raise ``TypeError``.
- **float64** face vertices run softvk's f64 CPU twin, forward and backward (for
  ``gradcheck``); float32 the kernels. Other dtypes raise ``TypeError``.

The results are PyTorch3D's CPU rasterizer's: the same faces in every slot (equal depths go to
the lower packed face index, as PyTorch3D's CPU code orders them), values within f32 rounding.
Near-plane clipping (``z_clip_value``, ``cull_to_frustum``, on by default for perspective
cameras through ``MeshRasterizer``) is PyTorch3D's own Python (``clip_faces``), so it needs
PyTorch3D installed; the faces it cuts in two are rasterized with PyTorch3D's rule for them.

PyTorch3D is the caller's dependency, not softvk's: it is imported when first needed, and a
clear ``ImportError`` says so when it is missing. ``rasterize_meshes`` takes any object with
PyTorch3D's packed-mesh accessors (``verts_packed``, ``faces_packed``,
``mesh_to_faces_packed_first_idx``, ``num_faces_per_mesh``).
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch

from . import _checks, _native
from ._host import like, round_trip

__all__ = ["MeshRasterizer", "RasterizationSettings", "rasterize_meshes", "Fragments"]


def _pytorch3d(what):
    """PyTorch3D's module `what` (e.g. "renderer.mesh.clip"), or a clear ImportError."""
    import importlib

    try:
        return importlib.import_module("pytorch3d." + what)
    except ImportError as e:
        raise ImportError(
            "softvk.pytorch3d: this needs PyTorch3D (pytorch3d.%s), which is not installed; "
            "softvk replaces only its rasterizer" % what
        ) from e


@dataclass
class _Fragments:
    """PyTorch3D's `Fragments`, where PyTorch3D is not installed (same fields)."""

    pix_to_face: object
    zbuf: object
    bary_coords: object
    dists: object

    def detach(self):
        return _Fragments(
            pix_to_face=self.pix_to_face,
            zbuf=self.zbuf.detach(),
            bary_coords=self.bary_coords.detach(),
            dists=self.dists.detach() if self.dists is not None else None,
        )


def Fragments(pix_to_face, zbuf, bary_coords, dists):
    """PyTorch3D's `Fragments` (its own class when it is installed)."""
    try:
        from pytorch3d.renderer.mesh.rasterizer import Fragments as P3DFragments
    except ImportError:
        return _Fragments(pix_to_face, zbuf, bary_coords, dists)
    return P3DFragments(
        pix_to_face=pix_to_face, zbuf=zbuf, bary_coords=bary_coords, dists=dists
    )


@dataclass(frozen=True)
class RasterizationSettings:
    """PyTorch3D's `RasterizationSettings`, where PyTorch3D is not installed (same fields and
    defaults). PyTorch3D's own class works as well."""

    image_size: object = 256
    blur_radius: float = 0.0
    faces_per_pixel: int = 1
    bin_size: Optional[int] = None
    max_faces_per_bin: Optional[int] = None
    perspective_correct: Optional[bool] = None
    clip_barycentric_coords: Optional[bool] = None
    cull_backfaces: bool = False
    z_clip_value: Optional[float] = None
    cull_to_frustum: bool = False


def _image_size(image_size):
    """PyTorch3D's `parse_image_size`: (H, W) from an int or a pair of ints."""
    if not isinstance(image_size, (tuple, list)):
        image_size = (image_size, image_size)
    if len(image_size) != 2:
        raise ValueError("Image size can only be a tuple/list of (H, W)")
    h, w = image_size
    for v in (h, w):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise ValueError("Image sizes must be integers; got %r" % (tuple(image_size),))
        if v <= 0:
            raise ValueError("Image sizes must be greater than 0; got %r" % (tuple(image_size),))
    return _checks.image_size((int(h), int(w)))


def _meshes_table(first_idx, num_faces):
    first = [int(x) for x in first_idx.detach().tolist()]
    count = [int(x) for x in num_faces.detach().tolist()]
    return list(zip(first, count))


def _check_faces(meshes, verts_packed, faces_packed):
    """Integer packed faces, each index within its own mesh's vertices where the meshes say
    where those are (PyTorch3D's ``Meshes`` do), else within all of them."""
    _checks.integer_faces("faces_packed", faces_packed)
    first_vert = getattr(meshes, "mesh_to_verts_packed_first_idx", None)
    verts_per_mesh = getattr(meshes, "num_verts_per_mesh", None)
    if first_vert is None or verts_per_mesh is None or faces_packed.numel() == 0:
        _checks.face_indices("faces_packed", faces_packed, int(verts_packed.shape[0]))
        return
    device = faces_packed.device
    counts = meshes.num_faces_per_mesh().to(device)
    mesh_of_face = torch.repeat_interleave(torch.arange(len(counts), device=device), counts)
    first = first_vert().to(device)[mesh_of_face]
    own = faces_packed - first[:, None].to(faces_packed.dtype)
    _checks.face_indices("faces_packed", own, verts_per_mesh().to(device)[mesh_of_face],
                         meshes=mesh_of_face)


class _RasterizeFaceVerts(torch.autograd.Function):
    """PyTorch3D's `_RasterizeFaceVerts` on softvk: the kernels for float32, the f64 twin for
    float64."""

    @staticmethod
    def forward(ctx, face_verts, meshes, neighbors, settings):
        f64 = face_verts.dtype == torch.float64
        nb = None if neighbors is None else neighbors.long()
        call = _native.reference_fragments if f64 else _native.rasterize_fragments
        on_device = like(face_verts, dtype=False)
        pix_to_face, zbuf, bary, dists = round_trip(call, face_verts, meshes, nb, settings,
                                                    back=(on_device,) * 4)
        ctx.save_for_backward(face_verts, pix_to_face)
        ctx.meshes = meshes
        ctx.settings = settings
        ctx.mark_non_differentiable(pix_to_face)
        return pix_to_face, zbuf, bary, dists

    @staticmethod
    def backward(ctx, _grad_pix_to_face, grad_zbuf, grad_bary, grad_dists):
        face_verts, pix_to_face = ctx.saved_tensors
        f64 = face_verts.dtype == torch.float64
        shape = tuple(pix_to_face.shape)

        def upstream(g, extra=()):
            if g is None:
                return np.zeros(shape + extra, dtype=np.float64 if f64 else np.float32)
            return g.to(face_verts.dtype)

        call = _native.reference_fragments_grad if f64 else _native.rasterize_fragments_grad
        grad = round_trip(
            call,
            face_verts,
            ctx.meshes,
            pix_to_face.long(),
            upstream(grad_zbuf),
            upstream(grad_bary, (3,)),
            upstream(grad_dists),
            ctx.settings,
            back=like(face_verts, dtype=False),
        )
        return grad, None, None, None


def _rasterize_face_verts(face_verts, meshes, neighbors, image_size, blur_radius,
                          faces_per_pixel, perspective_correct, clip_barycentric_coords,
                          cull_backfaces):
    if face_verts.dtype not in (torch.float32, torch.float64):
        raise TypeError(
            "softvk.pytorch3d: face vertices must be float32 (the kernels) or float64 (the f64 "
            "twin); got %s" % face_verts.dtype
        )
    if face_verts.dim() != 3 or tuple(face_verts.shape[1:]) != (3, 3):
        raise ValueError("face_verts must have dimensions (num_faces, 3, 3)")
    if int(faces_per_pixel) < 1:
        raise ValueError("faces_per_pixel must be at least 1; got %r" % (faces_per_pixel,))
    h, w = image_size
    settings = (
        h,
        w,
        float(blur_radius),
        int(faces_per_pixel),
        bool(perspective_correct),
        bool(clip_barycentric_coords),
        bool(cull_backfaces),
    )
    return _RasterizeFaceVerts.apply(face_verts, meshes, neighbors, settings)


def rasterize_meshes(
    meshes,
    image_size=256,
    blur_radius: float = 0.0,
    faces_per_pixel: int = 8,
    bin_size: Optional[int] = None,
    max_faces_per_bin: Optional[int] = None,
    perspective_correct: bool = False,
    clip_barycentric_coords: bool = False,
    cull_backfaces: bool = False,
    z_clip_value: Optional[float] = None,
    cull_to_frustum: bool = False,
):
    """PyTorch3D's `rasterize_meshes` on softvk: meshes already in NDC (as `MeshRasterizer`
    projects them) to `(pix_to_face, zbuf, bary_coords, dists)`, each `[N, H, W, K]` (the
    barycentrics `[N, H, W, K, 3]`). `bin_size` and `max_faces_per_bin` are accepted and have
    no effect: softvk's binning is exact."""
    del bin_size, max_faces_per_bin  # exact binning: nothing to size
    h, w = _image_size(image_size)
    verts_packed = meshes.verts_packed()
    faces_packed = meshes.faces_packed()
    _check_faces(meshes, verts_packed, faces_packed)
    face_verts = verts_packed[faces_packed]
    first_idx = meshes.mesh_to_faces_packed_first_idx()
    num_faces = meshes.num_faces_per_mesh()
    neighbors = None
    clipped = None
    if z_clip_value is not None or cull_to_frustum:
        clip = _pytorch3d("renderer.mesh.clip")
        frustum = clip.ClipFrustum(
            left=-1,
            right=1,
            top=-1,
            bottom=1,
            perspective_correct=perspective_correct,
            z_clip_value=z_clip_value,
            cull=cull_to_frustum,
        )
        clipped = clip.clip_faces(face_verts, first_idx, num_faces, frustum=frustum)
        face_verts = clipped.face_verts
        first_idx = clipped.mesh_to_face_first_idx
        num_faces = clipped.num_faces_per_mesh
        neighbors = clipped.clipped_faces_neighbor_idx
    pix_to_face, zbuf, bary, dists = _rasterize_face_verts(
        face_verts,
        _meshes_table(first_idx, num_faces),
        neighbors,
        (h, w),
        blur_radius,
        faces_per_pixel,
        perspective_correct,
        clip_barycentric_coords,
        cull_backfaces,
    )
    if clipped is not None:
        clip = _pytorch3d("renderer.mesh.clip")
        pix_to_face, bary = clip.convert_clipped_rasterization_to_original_faces(
            pix_to_face, bary, clipped
        )
    return pix_to_face, zbuf, bary, dists


class MeshRasterizer(torch.nn.Module):
    """PyTorch3D's `MeshRasterizer` on softvk: meshes in world space and cameras to PyTorch3D's
    `Fragments`, with PyTorch3D's projection, settings and defaults (clipped barycentrics when
    `blur_radius > 0`, perspective correction and a near-plane clip at `znear / 2` for
    perspective cameras, unless the settings say otherwise)."""

    def __init__(self, cameras=None, raster_settings=None):
        super().__init__()
        if raster_settings is None:
            try:
                raster_settings = _pytorch3d("renderer").RasterizationSettings()
            except ImportError:
                raster_settings = RasterizationSettings()
        self.cameras = cameras
        self.raster_settings = raster_settings

    def to(self, device):
        if self.cameras is not None:
            self.cameras = self.cameras.to(device)
        return self

    def transform(self, meshes_world, **kwargs):
        """The meshes' vertices in NDC (x, y) with view-space depth (z), as PyTorch3D's."""
        cameras = kwargs.get("cameras", self.cameras)
        if cameras is None:
            raise ValueError(
                "Cameras must be specified either at initialization or in the forward pass of "
                "MeshRasterizer"
            )
        n_cameras = len(cameras)
        if n_cameras != 1 and n_cameras != len(meshes_world):
            raise ValueError(
                "Wrong number (%r) of cameras for %r meshes" % (n_cameras, len(meshes_world))
            )
        verts_world = meshes_world.verts_padded()
        eps = kwargs.get("eps", None)
        verts_view = cameras.get_world_to_view_transform(**kwargs).transform_points(
            verts_world, eps=eps
        )
        to_ndc = cameras.get_ndc_camera_transform(**kwargs)
        try:
            projection = cameras.get_projection_transform(**kwargs)
        except NotImplementedError:
            projection = None
        if projection is not None:
            verts_ndc = projection.compose(to_ndc).transform_points(verts_view, eps=eps)
        else:
            verts_proj = cameras.transform_points(verts_world, eps=eps)
            verts_ndc = to_ndc.transform_points(verts_proj, eps=eps)
        verts_ndc[..., 2] = verts_view[..., 2]
        return meshes_world.update_padded(new_verts_padded=verts_ndc)

    def forward(self, meshes_world, **kwargs):
        meshes_proj = self.transform(meshes_world, **kwargs)
        settings = kwargs.get("raster_settings", self.raster_settings)
        clip_barycentric_coords = settings.clip_barycentric_coords
        if clip_barycentric_coords is None:
            clip_barycentric_coords = settings.blur_radius > 0.0
        cameras = kwargs.get("cameras", self.cameras)
        if settings.perspective_correct is not None:
            perspective_correct = settings.perspective_correct
        else:
            perspective_correct = cameras.is_perspective()
        if settings.z_clip_value is not None:
            z_clip = settings.z_clip_value
        else:
            znear = cameras.get_znear()
            if hasattr(znear, "min"):
                znear = znear.min().item()
            z_clip = None if not perspective_correct or znear is None else znear / 2
        pix_to_face, zbuf, bary_coords, dists = rasterize_meshes(
            meshes_proj,
            image_size=settings.image_size,
            blur_radius=settings.blur_radius,
            faces_per_pixel=settings.faces_per_pixel,
            bin_size=settings.bin_size,
            max_faces_per_bin=settings.max_faces_per_bin,
            clip_barycentric_coords=clip_barycentric_coords,
            perspective_correct=perspective_correct,
            cull_backfaces=settings.cull_backfaces,
            z_clip_value=z_clip,
            cull_to_frustum=settings.cull_to_frustum,
        )
        return Fragments(
            pix_to_face=pix_to_face, zbuf=zbuf, bary_coords=bary_coords, dists=dists
        )
