"""Bad input from Python gets one clear error on every path: the engine's and the composed
steps', float32 and float64, through ``softvk.torch``, ``softvk.soft_renderer`` and
``softvk.pytorch3d`` alike (a ``ValueError`` or ``TypeError`` naming the argument and what is
wrong), and input that is good but unusual (no faces, strided tensors, tensors that require a
gradient none can reach) gets what SoftRas gives it.

The paths a world-space mesh takes (``MESH_PATHS``):

- ``render_mesh``: ``softvk.torch.render_mesh`` (the engine: camera, lights and faces on the
  device);
- ``engine``: ``SoftRenderer`` in float32, which hands the mesh to the engine;
- ``composed_f64``: ``SoftRenderer`` in float64 (SoftRas's composed steps, the f64 twin);
- ``composed_replaced``: ``SoftRenderer`` in float32 with its lighting replaced by a subclass
  of the user's (the composed steps in float32).

``soft_rasterize`` and ``soft_rasterize_f64`` take the same mesh as screen-space faces, and
``pytorch3d`` / ``pytorch3d_f64`` as PyTorch3D's packed meshes (``rasterize_meshes``).
"""

import math

import numpy as np
import pytest
import torch
import torch.nn as nn

import softvk.pytorch3d as sp
import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf
import softvk.torch as st
from test_pytorch3d import StandInMeshes

SIZE = 16
BACKGROUND = (0.25, 0.5, 0.75)
SIGMA = 1e-4

MESH_PATHS = ["render_mesh", "engine", "composed_f64", "composed_replaced"]
RGBA_PATHS = ["soft_rasterize", "soft_rasterize_f64"] + MESH_PATHS
FACE_PATHS = MESH_PATHS + ["pytorch3d", "pytorch3d_f64"]


def dtype_of(path):
    return torch.float64 if path.endswith("_f64") else torch.float32


def quad(batch=1, dtype=torch.float32):
    """Two triangles over four vertices, near the origin and facing SoftRas's default look_at
    eye; each mesh of the batch a little smaller than the one before. Faces ``[F, 3]``."""
    base = torch.tensor([[-0.6, -0.5, 0.0], [0.5, -0.6, 0.1], [0.6, 0.5, 0.0], [-0.5, 0.6, -0.1]],
                        dtype=dtype)
    vertices = torch.stack([base * (1 - 0.1 * b) for b in range(batch)])
    return vertices, torch.tensor([[0, 1, 2], [0, 2, 3]])


def textures_for(vertices, faces, texture_type="surface", seed=1):
    """Random textures: ``[B, F, 4, 3]`` surface texels or ``[B, V, 3]`` vertex colours."""
    batch, nv = vertices.shape[:2]
    shape = (batch, faces.shape[-2], 4, 3) if texture_type == "surface" else (batch, nv, 3)
    return torch.rand(shape, generator=torch.Generator().manual_seed(seed), dtype=vertices.dtype)


class OwnLighting(sr.Lighting):
    """SoftRas's lighting, subclassed as a user would: ``SoftRenderer`` takes the composed
    steps for it."""


def renderer_for(path, texture_type="surface", image_size=SIZE, **kw):
    renderer = sr.SoftRenderer(image_size=image_size, camera_mode="look_at", sigma_val=SIGMA,
                               background_color=list(BACKGROUND), texture_type=texture_type, **kw)
    if path == "composed_replaced":
        renderer.lighting = OwnLighting(texture_type)
    return renderer


def screen(vertices, faces):
    """Screen-space faces ``[B, F, 3, 3]`` for ``soft_rasterize``: the vertices moved to depth 2."""
    return vertices[:, faces] + torch.tensor([0.0, 0.0, 2.0], dtype=vertices.dtype)


def render(path, vertices, faces, textures=None, texture_type="surface", image_size=SIZE, **kw):
    """RGBA ``[B, 4, H, W]`` of a mesh (vertices ``[B, V, 3]``, faces ``[F, 3]`` or ``[B, F, 3]``)
    through ``path``."""
    if path.startswith("soft_rasterize"):
        if textures is None:
            textures = torch.ones(vertices.shape[0], faces.shape[-2], 1, 3, dtype=vertices.dtype)
        if texture_type == "vertex":
            textures = textures[:, faces]
        return st.soft_rasterize(screen(vertices, faces), textures, image_size=image_size,
                                 background_color=list(BACKGROUND), sigma_val=SIGMA,
                                 texture_type=texture_type, **kw)
    if path == "render_mesh":
        return st.render_mesh(vertices, faces, textures, image_size=image_size,
                              background_color=list(BACKGROUND), sigma_val=SIGMA,
                              texture_type=texture_type, **kw)
    if faces.dim() == 2:
        faces = faces.expand(vertices.shape[0], -1, -1)
    renderer = renderer_for(path, texture_type, image_size, **kw)
    return renderer(vertices, faces, textures, texture_type=texture_type)


class PackedMeshes(StandInMeshes):
    """``test_pytorch3d``'s stand-in for PyTorch3D's ``Meshes``, also saying where each mesh's
    vertices are (its first vertex and count), as ``Meshes`` does."""

    def mesh_to_verts_packed_first_idx(self):
        return torch.tensor(np.cumsum([0] + self.vert_counts[:-1]), dtype=torch.int64)

    def num_verts_per_mesh(self):
        return torch.tensor(self.vert_counts, dtype=torch.int64)


def packed(vertices, faces):
    """The batch as PyTorch3D packs it: NDC vertices (depth 2) and faces offset by each mesh's
    first vertex (faces ``[F, 3]`` shared or ``[B, F, 3]``, in each mesh's own numbering)."""
    batch, nv = vertices.shape[:2]
    if faces.dim() == 2:
        faces = faces.expand(batch, -1, -1)
    offsets = torch.arange(batch)[:, None, None] * nv
    verts = (vertices + torch.tensor([0.0, 0.0, 2.0], dtype=vertices.dtype)).reshape(-1, 3)
    faces = faces + offsets.to(faces.dtype) if faces.is_floating_point() else faces + offsets
    return PackedMeshes(verts, faces.reshape(-1, 3), [faces.shape[1]] * batch, [nv] * batch)


def rasterize_p3d(vertices, faces, image_size=SIZE):
    return sp.rasterize_meshes(packed(vertices, faces), image_size=image_size, faces_per_pixel=2,
                               blur_radius=1e-3)


def any_path(path, vertices, faces, textures=None, **kw):
    """``render`` for the RGBA paths, ``rasterize_p3d`` for PyTorch3D's (``zbuf``)."""
    if path.startswith("pytorch3d"):
        return rasterize_p3d(vertices, faces, **kw)[1]
    return render(path, vertices, faces, textures, **kw)


# --- NaN or infinite textures, colours and lights ---------------------------------------------


@pytest.mark.parametrize("texture_type,bad", [("surface", math.nan), ("vertex", math.inf)])
@pytest.mark.parametrize("path", RGBA_PATHS)
def test_textures_that_are_not_finite_are_refused(gpu, path, texture_type, bad):
    vertices, faces = quad(dtype=dtype_of(path))
    textures = textures_for(vertices, faces, texture_type)
    textures[0, 1, 0] = bad
    with pytest.raises(ValueError, match="textures has a value that is not finite"):
        render(path, vertices, faces, textures, texture_type)


@pytest.mark.parametrize("path", RGBA_PATHS + ["pytorch3d", "pytorch3d_f64"])
def test_positions_that_are_not_finite_are_refused_as_positions(gpu, path):
    # Checked before the textures: on the composed steps a NaN position makes NaN lit
    # textures, which must not be blamed.
    vertices, faces = quad(dtype=dtype_of(path))
    vertices[0, 1, 0] = math.nan
    match = "face_vertices has a value|NaN or infinite coordinate|coordinate that is not finite"
    with pytest.raises(ValueError, match=match):
        any_path(path, vertices, faces)


def set_light(renderer, setting, value):
    if setting == "light_color_ambient":
        renderer.lighting.ambient.light_color = value
    else:
        renderer.lighting.directionals[0].light_direction = value


@pytest.mark.parametrize("setting,value", [("light_color_ambient", [math.nan, 1.0, 1.0]),
                                           ("light_directions", [0.0, math.inf, 0.0])])
@pytest.mark.parametrize("path", MESH_PATHS)
def test_lights_that_are_not_finite_are_refused(gpu, path, setting, value):
    vertices, faces = quad(dtype=dtype_of(path))
    match = r"light_(color|direction)\w* has a value that is not finite"
    if path == "render_mesh":
        with pytest.raises(ValueError, match=match):
            st.render_mesh(vertices, faces, image_size=SIZE, **{setting: value})
        return
    renderer = renderer_for(path)
    set_light(renderer, setting, value)
    with pytest.raises(ValueError, match=match):
        renderer(vertices, faces[None])


# --- Face indices: integers, within their own mesh's vertices ----------------------------------


@pytest.mark.parametrize("path", FACE_PATHS)
def test_float_face_indices_are_refused(gpu, path):
    vertices, faces = quad(dtype=dtype_of(path))
    with pytest.raises(TypeError, match="faces\\w* must be an integer tensor, got torch.float32"):
        any_path(path, vertices, faces.float() + 0.25)


def test_a_mesh_of_float_numpy_faces_is_refused():
    vertices, faces = quad()
    with pytest.raises(TypeError, match="faces must be an integer array, got float64"):
        sr.Mesh(vertices[0].numpy(), faces.numpy() + 0.25)


# (batch, mesh, index): where a face's corner points, in its own mesh's numbering.
OUTSIDE = {"negative": (1, 0, -1), "past the end": (1, 0, 4), "another mesh's": (2, 0, 4),
           "the mesh before's": (2, 1, -1)}


@pytest.mark.parametrize("case", OUTSIDE)
@pytest.mark.parametrize("path", FACE_PATHS)
def test_face_indices_outside_their_mesh_are_refused(gpu, path, case):
    batch, mesh, index = OUTSIDE[case]
    vertices, faces = quad(batch, dtype_of(path))
    faces = faces.expand(batch, -1, -1).clone()
    faces[mesh, 1, 2] = index
    if path == "render_mesh":  # the same faces for every mesh
        faces = faces[mesh]
    with pytest.raises(ValueError, match=rf"faces\w* has index {index}\b.*outside"):
        any_path(path, vertices, faces)


# --- A module of the user's in place of SoftRas's: called, never inspected ---------------------


class Darken(nn.Module):
    """A lighting module as a user writes it: no ``ambient``, no ``directionals``."""

    def forward(self, mesh):
        mesh.textures = mesh.textures * 0.5
        return mesh


class PlainCamera(nn.Module):
    """A camera module as a user writes it: no ``transformer``."""

    def forward(self, mesh):
        mesh.vertices = srf.perspective(srf.look_at(mesh.vertices, [0.3, 0.4, -2.5]))
        return mesh


class PlainRasterizer(nn.Module):
    """A rasterizer module as a user writes it: none of ``SoftRasterizer``'s attributes."""

    def forward(self, mesh, mode=None):
        return srf.soft_rasterize(mesh.face_vertices, mesh.face_textures, SIZE, BACKGROUND,
                                  sigma_val=SIGMA)


@pytest.mark.parametrize("module", ["lighting", "transform", "rasterizer"])
def test_a_plain_module_in_place_of_softras_s_is_called_as_softras_calls_it(gpu, module,
                                                                           engine_calls):
    vertices, faces = quad(batch=2)
    textures = textures_for(vertices, faces)
    renderer = renderer_for("engine")
    setattr(renderer, module, {"lighting": Darken, "transform": PlainCamera,
                               "rasterizer": PlainRasterizer}[module]())
    images = renderer(vertices, faces.expand(2, -1, -1), textures)
    mesh = sr.Mesh(vertices, faces.expand(2, -1, -1), textures)
    want = renderer.rasterizer(renderer.transform(renderer.lighting(mesh)))
    assert torch.equal(images, want)
    assert not engine_calls


# --- A mesh without faces: the background, as SoftRas renders it -------------------------------


@pytest.mark.parametrize("path", RGBA_PATHS)
def test_a_mesh_without_faces_renders_the_background(gpu, path):
    vertices, faces = quad(batch=2, dtype=dtype_of(path))
    faces = faces[:0]
    textures = textures_for(vertices, faces).requires_grad_(True)
    vertices.requires_grad_(True)
    images = render(path, vertices, faces, textures)
    assert images.shape == (2, 4, SIZE, SIZE) and images.dtype == vertices.dtype
    want = torch.tensor(BACKGROUND, dtype=images.dtype)[None, :, None, None].expand(2, 3, SIZE,
                                                                                    SIZE)
    assert torch.equal(images[:, :3], want)
    assert bool((images[:, 3] == 0).all())
    (images * torch.rand(images.shape, dtype=images.dtype)).sum().backward()
    for t in (vertices, textures):
        assert t.grad is not None and t.grad.shape == t.shape and not bool(t.grad.any())


@pytest.mark.parametrize("path", ["engine", "composed_f64"])
def test_a_mesh_without_faces_has_no_silhouette_and_the_far_depth(gpu, path):
    vertices, faces = quad(batch=2, dtype=dtype_of(path))
    mesh = sr.Mesh(vertices, faces[:0].expand(2, -1, -1))
    renderer = renderer_for(path)
    assert torch.equal(st.render(renderer, mesh, "silhouettes"),
                       torch.zeros(2, SIZE, SIZE, dtype=vertices.dtype))
    assert torch.equal(st.render(renderer, mesh, "depth"),
                       torch.full((2, SIZE, SIZE), 100.0, dtype=vertices.dtype))


@pytest.mark.parametrize("path", ["pytorch3d", "pytorch3d_f64"])
def test_pytorch3d_a_mesh_without_faces_has_no_fragments(gpu, path):
    vertices, faces = quad(batch=2, dtype=dtype_of(path))
    vertices.requires_grad_(True)
    pix_to_face, zbuf, bary, dists = rasterize_p3d(vertices, faces[:0])
    assert pix_to_face.shape == (2, SIZE, SIZE, 2) and bary.shape == (2, SIZE, SIZE, 2, 3)
    for t in (pix_to_face, zbuf, bary, dists):
        assert bool((t == -1).all())
    (zbuf.sum() + bary.sum() + dists.sum()).backward()
    assert vertices.grad is not None and not bool(vertices.grad.any())


# --- Image sizes ---------------------------------------------------------------------------------

BAD_SIZES = {"zero": (0, ValueError), "negative": (-4, ValueError),
             "a zero side": ((16, 0), ValueError), "2**40": (2 ** 40, ValueError),
             "a million": (10 ** 6, ValueError), "a float": (16.5, TypeError),
             "a string": ("16", TypeError), "three sides": ((16, 16, 16), ValueError)}


@pytest.mark.parametrize("size", BAD_SIZES)
@pytest.mark.parametrize("path", RGBA_PATHS + ["pytorch3d"])
def test_a_bad_image_size_is_one_clear_error(gpu, path, size):
    value, error = BAD_SIZES[size]
    if path == "pytorch3d" and error is TypeError:
        error = ValueError  # PyTorch3D's own parse_image_size raises ValueError for these
    vertices, faces = quad(dtype=dtype_of(path))
    with pytest.raises(error, match="(?i)image.?size") as info:
        any_path(path, vertices, faces, image_size=value)
    assert type(info.value) in (ValueError, TypeError)


@pytest.mark.parametrize("path", ["soft_rasterize", "render_mesh", "engine", "pytorch3d"])
def test_an_image_beyond_the_device_is_a_value_error(gpu, path):
    # 8 images of 16384² pixels: 32 GiB of RGBA (PyTorch3D's one: 6 GiB of barycentrics for 2
    # faces a pixel), over any device's maxStorageBufferRange (a 32-bit count of bytes); refused
    # before anything is allocated. (The f64 twin's images would be host memory: not tried.)
    vertices, faces = quad(batch=1 if path == "pytorch3d" else 8)
    with pytest.raises(ValueError, match=r"needs? \d+ bytes.*, over "):
        any_path(path, vertices, faces, image_size=16384)


# --- Strided tensors, and tensors that require a gradient none can reach -------------------------


def strided(tensor):
    """``tensor``'s values in a tensor of other strides (every other element of a larger one),
    and the leaf it is a view of."""
    leaf = torch.stack([tensor, torch.zeros_like(tensor)], dim=-1).detach().requires_grad_(True)
    return leaf[..., 0], leaf


@pytest.mark.parametrize("texture_type", ["surface", "vertex"])
@pytest.mark.parametrize("path", RGBA_PATHS + ["pytorch3d", "pytorch3d_f64"])
def test_strided_inputs_give_what_contiguous_ones_give(gpu, path, texture_type):
    if path.startswith("pytorch3d") and texture_type == "vertex":
        pytest.skip("PyTorch3D's rasterizer takes no textures")
    vertices, faces = quad(batch=2, dtype=dtype_of(path))
    textures = textures_for(vertices, faces, texture_type)
    if path.startswith("soft_rasterize"):  # the screen-space faces themselves strided
        vertices = screen(vertices, faces)
        if texture_type == "vertex":
            textures = textures[:, faces]
    elif path.startswith("pytorch3d"):  # the packed vertices and faces themselves strided
        meshes = packed(vertices, faces)
        vertices, faces = meshes.verts, meshes.faces
    weights = torch.rand(2, 4, SIZE, SIZE, generator=torch.Generator().manual_seed(3),
                         dtype=vertices.dtype)

    def run(v, f, t):
        if path.startswith("soft_rasterize"):
            return st.soft_rasterize(v, t, image_size=SIZE, sigma_val=SIGMA,
                                     texture_type=texture_type)
        if path.startswith("pytorch3d"):
            meshes = PackedMeshes(v, f, [2, 2], [4, 4])
            zbuf = sp.rasterize_meshes(meshes, image_size=SIZE, faces_per_pixel=2,
                                       blur_radius=1e-3)[1]
            return zbuf.permute(0, 3, 1, 2)
        return render(path, v, f, t, texture_type)

    plain_v = vertices.clone().requires_grad_(True)
    plain_t = textures[:1].repeat(2, *[1] * (textures.dim() - 1)).requires_grad_(True)
    want = run(plain_v, faces, plain_t)
    (want * weights[:, :want.shape[1]]).sum().backward()

    view_v, leaf_v = strided(vertices)
    one_t = textures[:1].clone().requires_grad_(True)
    view_t = one_t.expand(2, *textures.shape[1:])  # stride 0 across the batch
    view_f = faces.t().contiguous().t()  # column-major
    assert not (view_v.is_contiguous() or view_t.is_contiguous() or view_f.is_contiguous())
    got = run(view_v, view_f, view_t)
    assert torch.equal(got, want)
    (got * weights[:, :got.shape[1]]).sum().backward()
    assert torch.equal(leaf_v.grad[..., 0], plain_v.grad)
    assert not bool(leaf_v.grad[..., 1].any())
    if not path.startswith("pytorch3d"):
        assert torch.equal(one_t.grad[0], plain_t.grad.sum(0))


@pytest.mark.parametrize("mode", ["silhouettes", "depth"])
@pytest.mark.parametrize("path", ["engine", "composed_f64", "composed_replaced"])
def test_textures_that_require_a_gradient_none_reaches_change_nothing(gpu, path, mode):
    vertices, faces = quad(batch=2, dtype=dtype_of(path))
    faces = faces.expand(2, -1, -1)
    textures = textures_for(vertices, faces)
    results = []
    for asks in (False, True):
        v = vertices.clone().requires_grad_(True)
        t = textures.clone().requires_grad_(asks)
        out = st.render(renderer_for(path), sr.Mesh(v, faces, t), mode)
        ramp = torch.linspace(0, 1, out.numel(), dtype=out.dtype).reshape(out.shape)
        (out * ramp).sum().backward()
        results.append((out, v.grad, t.grad))
    (out0, grad0, _), (out1, grad1, tex_grad) = results
    assert torch.equal(out0, out1) and torch.equal(grad0, grad1)
    assert tex_grad is None or not bool(tex_grad.any())
