"""softvk.pytorch3d: PyTorch3D's rasterizer on softvk.

Without PyTorch3D (CI): the golden files of PyTorch3D 0.7.9's own CPU rasterizer
(``tests/data/pytorch3d``, made by its ``make_goldens.py``) through ``rasterize_meshes`` with a
stand-in for ``Meshes`` that has only what the rasterizer reads; ``MeshRasterizer`` with stand-in
cameras; float64 against central differences. With PyTorch3D importable: ``MeshRasterizer``
against PyTorch3D's, projection and near-plane clipping included, and a whole
``MeshRenderer`` with PyTorch3D's shaders.
"""

import importlib.util
import math
import pathlib

import numpy as np
import pytest
import torch

import softvk.pytorch3d as sp

GOLDENS = pathlib.Path(__file__).resolve().parents[2] / "tests" / "data" / "pytorch3d"

# As tests/pytorch3d_fragments.rs: gradient components within 1e-4 of themselves plus this
# fraction of the scene's largest (PyTorch3D's f32 sums over pixels round relative to the terms).
GRAD_FLOOR = 1e-5


class StandInMeshes:
    """What ``rasterize_meshes`` reads of PyTorch3D's ``Meshes`` (packed accessors), and what
    ``MeshRasterizer`` reads (padded vertices, ``update_padded``, ``len``): one mesh per entry of
    ``counts`` over the packed vertices and faces."""

    def __init__(self, verts, faces, face_counts, vert_counts=None):
        self.verts = verts
        self.faces = faces
        self.face_counts = list(face_counts)
        self.vert_counts = vert_counts

    def __len__(self):
        return len(self.face_counts)

    def verts_packed(self):
        return self.verts

    def faces_packed(self):
        return self.faces

    def mesh_to_faces_packed_first_idx(self):
        return torch.tensor(np.cumsum([0] + self.face_counts[:-1]), dtype=torch.int64)

    def num_faces_per_mesh(self):
        return torch.tensor(self.face_counts, dtype=torch.int64)

    # One mesh only, for MeshRasterizer.
    def verts_padded(self):
        return self.verts[None]

    def update_padded(self, new_verts_padded):
        return StandInMeshes(new_verts_padded[0], self.faces, self.face_counts)


class Identity:
    def transform_points(self, points, eps=None):
        return points.clone()

    def compose(self, other):
        return self


class StandInCameras:
    """Cameras whose world, view and NDC spaces are one: what ``MeshRasterizer`` calls."""

    def __len__(self):
        return 1

    def get_world_to_view_transform(self, **kwargs):
        return Identity()

    def get_ndc_camera_transform(self, **kwargs):
        return Identity()

    def get_projection_transform(self, **kwargs):
        raise NotImplementedError

    def transform_points(self, points, eps=None):
        return points.clone()

    def is_perspective(self):
        return False

    def get_znear(self):
        return None

    def to(self, device):
        return self


def golden(name):
    data = np.load(GOLDENS / name)
    return {k: data[k] for k in data.files}


def golden_names():
    names = sorted(p.name for p in GOLDENS.glob("*.npz"))
    assert len(names) >= 8, "golden files missing"
    return names


def scene(g, dtype=torch.float32):
    verts = torch.tensor(g["verts_packed"], dtype=dtype, requires_grad=True)
    faces = torch.tensor(g["faces_packed"], dtype=torch.int64)
    meshes = StandInMeshes(verts, faces, [int(c) for c in g["num_faces_per_mesh"]])
    firsts = [int(f) for f in g["mesh_to_face_first_idx"]]
    assert firsts == np.cumsum([0] + meshes.face_counts[:-1]).tolist()
    settings = dict(
        image_size=tuple(int(s) for s in g["image_size"]),
        blur_radius=float(g["blur_radius"]),
        faces_per_pixel=int(g["faces_per_pixel"]),
        perspective_correct=bool(g["perspective_correct"]),
        clip_barycentric_coords=bool(g["clip_barycentric_coords"]),
        cull_backfaces=bool(g["cull_backfaces"]),
    )
    return verts, meshes, settings


@pytest.mark.parametrize("name", golden_names())
def test_fragments_and_gradients_are_pytorch3ds_on_the_golden_scenes(gpu, name):
    g = golden(name)
    verts, meshes, settings = scene(g)
    if "clipped_faces_neighbor_idx" in g:
        # After PyTorch3D's near-plane clip: its C++ rasterizer's inputs, cut faces' halves named.
        out = sp._rasterize_face_verts(
            verts[meshes.faces],
            [(0, len(meshes.faces))],
            torch.from_numpy(g["clipped_faces_neighbor_idx"]),
            settings.pop("image_size"),
            **settings,
        )
    else:
        out = sp.rasterize_meshes(meshes, **settings)
    pix_to_face, zbuf, bary, dists = out
    assert pix_to_face.dtype == torch.int64
    assert tuple(pix_to_face.shape) == g["pix_to_face"].shape
    assert tuple(bary.shape) == g["bary_coords"].shape
    assert np.array_equal(pix_to_face.numpy(), g["pix_to_face"])
    for got, want in ((zbuf, g["zbuf"]), (bary, g["bary_coords"]), (dists, g["dists"])):
        assert np.abs(got.detach().numpy() - want).max() <= 1e-5
    loss = (
        (zbuf * torch.from_numpy(g["grad_zbuf"])).sum()
        + (bary * torch.from_numpy(g["grad_bary"])).sum()
        + (dists * torch.from_numpy(g["grad_dists"])).sum()
    )
    loss.backward()
    got = verts.grad.numpy().astype(np.float64)
    want = g["grad_verts"].astype(np.float64)
    bar = 1e-4 * np.abs(want) + GRAD_FLOOR * np.abs(want).max()
    assert np.all(np.abs(got - want) <= bar), np.abs(got - want).max()


def test_bin_settings_change_nothing_and_reruns_are_the_same_bits(gpu):
    g = golden("batched.npz")
    verts, meshes, settings = scene(g)
    first = sp.rasterize_meshes(meshes, **settings)
    binned = sp.rasterize_meshes(meshes, bin_size=4, max_faces_per_bin=1, **settings)
    for a, b in zip(first, binned):
        assert torch.equal(a, b)
    grads = []
    for _ in range(2):
        verts.grad = None
        _, zbuf, bary, dists = sp.rasterize_meshes(meshes, **settings)
        (zbuf.sum() + (bary * bary).sum() + dists.sum()).backward()
        grads.append(verts.grad.clone())
    assert torch.equal(grads[0].view(torch.int32), grads[1].view(torch.int32))


def test_outputs_stay_valid_while_later_calls_run_and_their_memory_is_reused(gpu):
    # The arrays view the memory the device wrote; it goes back to the pool only when they die.
    a = golden("batched.npz")
    b = golden("non_square.npz")
    _, meshes_a, settings_a = scene(a)
    _, meshes_b, settings_b = scene(b)
    first = [t.detach().clone() for t in sp.rasterize_meshes(meshes_a, **settings_a)]
    kept = sp.rasterize_meshes(meshes_a, **settings_a)
    for _ in range(3):
        out_b = sp.rasterize_meshes(meshes_b, **settings_b)
        assert np.array_equal(out_b[0].numpy(), b["pix_to_face"])
        del out_b
    for x, y in zip(kept, first):
        assert torch.equal(x, y)
    # In-place changes to one call's outputs do not reach the next call's.
    kept[1].fill_(7.0)
    del kept
    again = sp.rasterize_meshes(meshes_a, **settings_a)
    for x, y in zip(again, first):
        assert torch.equal(x, y)


def test_float64_runs_the_twin_and_matches_central_differences(gpu):
    # Two faces off the pixel grid's lines (no pixel on an edge line, where the clip's kink is).
    verts = torch.tensor(
        [
            [0.613, -0.487, 2.0],
            [-0.391, 0.722, 2.6],
            [-0.688, -0.579, 3.1],
            [0.207, 0.813, 1.5],
            [0.917, -0.183, 2.2],
            [-0.286, -0.094, 1.8],
        ],
        dtype=torch.float64,
        requires_grad=True,
    )
    faces = torch.tensor([[0, 1, 2], [3, 4, 5]])
    settings = dict(
        image_size=(5, 7),
        blur_radius=0.03,
        faces_per_pixel=2,
        perspective_correct=True,
        clip_barycentric_coords=True,
    )
    out = sp.rasterize_meshes(StandInMeshes(verts, faces, [2]), **settings)
    assert out[1].dtype == torch.float64
    gen = torch.Generator().manual_seed(0)
    weights = [torch.rand(o.shape, generator=gen, dtype=torch.float64) for o in out[1:]]

    def loss(v):
        p2f, zbuf, bary, dists = sp.rasterize_meshes(StandInMeshes(v, faces, [2]), **settings)
        assert torch.equal(p2f, out[0])  # the same selection: a derivative, not a jump
        return sum((o * w).sum() for o, w in zip((zbuf, bary, dists), weights))

    (grad,) = torch.autograd.grad(loss(verts), verts)
    h = 1e-6
    for i in range(verts.shape[0]):
        for a in range(3):
            up = verts.detach().clone()
            down = verts.detach().clone()
            up[i, a] += h
            down[i, a] -= h
            fd = (loss(up) - loss(down)).item() / (2 * h)
            assert abs(grad[i, a].item() - fd) <= 1e-6 * abs(fd) + 1e-6, (i, a)
    # float32 (the kernels) agrees with float64 (the twin).
    v32 = verts.detach().float()
    out32 = sp.rasterize_meshes(StandInMeshes(v32, faces, [2]), **settings)
    assert torch.equal(out32[0], out[0])
    assert (out32[1].double() - out[1]).abs().max() <= 1e-5


def test_mesh_rasterizer_projects_and_takes_pytorch3ds_defaults_and_overrides(gpu):
    g = golden("square_blur_k4.npz")
    verts, meshes, settings = scene(g)
    rs = sp.RasterizationSettings(
        image_size=settings["image_size"],
        blur_radius=settings["blur_radius"],
        faces_per_pixel=settings["faces_per_pixel"],
    )
    rasterizer = sp.MeshRasterizer(cameras=StandInCameras(), raster_settings=rs)
    fragments = rasterizer(meshes)
    # blur_radius > 0 and clip_barycentric_coords None: clipped, as PyTorch3D defaults; an
    # orthographic camera: not perspective-corrected; no z clip.
    want = sp.rasterize_meshes(
        meshes,
        image_size=settings["image_size"],
        blur_radius=settings["blur_radius"],
        faces_per_pixel=settings["faces_per_pixel"],
        clip_barycentric_coords=True,
    )
    for got, w in zip(
        (fragments.pix_to_face, fragments.zbuf, fragments.bary_coords, fragments.dists), want
    ):
        assert torch.equal(got, w)
    # Keyword overrides, as PyTorch3D's: other settings for one call.
    other = sp.RasterizationSettings(image_size=(6, 9), faces_per_pixel=2)
    assert tuple(rasterizer(meshes, raster_settings=other).zbuf.shape) == (1, 6, 9, 2)
    with pytest.raises(ValueError, match="Cameras must be specified"):
        sp.MeshRasterizer(raster_settings=rs)(meshes)


def test_bad_input_gets_one_clear_error(gpu):
    g = golden("square_basic.npz")
    verts, meshes, settings = scene(g)
    with pytest.raises(ValueError, match="Image size"):
        sp.rasterize_meshes(meshes, image_size=(1, 2, 3))
    with pytest.raises(ValueError, match="greater than 0"):
        sp.rasterize_meshes(meshes, image_size=(0, 8))
    with pytest.raises(ValueError, match="faces_per_pixel"):
        sp.rasterize_meshes(meshes, image_size=8, faces_per_pixel=0)
    half = StandInMeshes(verts.detach().half(), meshes.faces, meshes.face_counts)
    with pytest.raises(TypeError, match="float32"):
        sp.rasterize_meshes(half, image_size=8)
    with pytest.raises(ValueError, match="blur_radius"):
        sp.rasterize_meshes(meshes, image_size=8, blur_radius=math.nan)
    # A non-finite coordinate: PyTorch3D makes NaN fragments of its faces; softvk says so.
    vertex = int(meshes.faces[3, 1])
    first = min(f for f in range(len(meshes.faces)) if vertex in meshes.faces[f].tolist())
    for dtype in (torch.float32, torch.float64):
        bad = verts.detach().to(dtype).clone()
        bad[vertex] = math.nan
        holed = StandInMeshes(bad, meshes.faces, meshes.face_counts)
        with pytest.raises(ValueError, match=f"face {first} has a coordinate that is not finite"):
            sp.rasterize_meshes(holed, **settings)


def test_a_batch_with_an_empty_mesh_rasterizes_the_others(gpu):
    g = golden("batched.npz")
    verts, meshes, settings = scene(g)
    # The middle mesh's faces removed: an empty mesh between two others.
    counts = meshes.face_counts
    keep = torch.cat([meshes.faces[: counts[0]], meshes.faces[counts[0] + counts[1]:]])
    holed = StandInMeshes(verts, keep, [counts[0], 0, counts[2]])
    p2f, zbuf, bary, dists = holed_out = sp.rasterize_meshes(holed, **settings)
    want = torch.from_numpy(g["pix_to_face"])
    assert torch.equal(p2f[0], want[0])
    assert bool((p2f[1] == -1).all()) and bool((zbuf[1] == -1).all())
    shifted = torch.where(want[2] >= 0, want[2] - counts[1], want[2])
    assert torch.equal(p2f[2], shifted)
    (zbuf.sum() + bary.sum() + dists.sum()).backward()
    assert bool(verts.grad.isfinite().all())
    del holed_out
    nothing = StandInMeshes(verts, meshes.faces[:0], [0])
    out = sp.rasterize_meshes(nothing, **settings)
    assert bool((out[0] == -1).all())


def test_near_plane_clipping_without_pytorch3d_says_what_is_missing(gpu):
    if importlib.util.find_spec("pytorch3d") is not None:
        pytest.skip("PyTorch3D is installed here")
    _, meshes, settings = scene(golden("square_basic.npz"))
    with pytest.raises(ImportError, match="PyTorch3D"):
        sp.rasterize_meshes(meshes, z_clip_value=0.5, **settings)


# ---- Against PyTorch3D itself, where it is installed ----


def pytorch3d_or_skip():
    return pytest.importorskip("pytorch3d.renderer", reason="PyTorch3D is not installed")


def test_mesh_rasterizer_matches_pytorch3ds_through_its_cameras_and_clipping(gpu):
    r = pytorch3d_or_skip()
    from pytorch3d.utils import ico_sphere

    mesh = ico_sphere(2)
    verts = mesh.verts_packed().detach().clone().requires_grad_(True)
    # The eye inside the sphere's far side: faces cut by the near plane (z_clip_value znear/2).
    for dist, cameras in (
        (2.7, r.FoVPerspectiveCameras),
        (0.9, r.FoVPerspectiveCameras),
        (2.7, r.FoVOrthographicCameras),
        (2.7, r.PerspectiveCameras),
    ):
        R, T = r.look_at_view_transform(dist, 15, 30)
        cams = cameras(R=R, T=T)
        settings = r.RasterizationSettings(
            image_size=(24, 32), blur_radius=1e-3, faces_per_pixel=6
        )
        outs = []
        for rasterizer in (r.MeshRasterizer, sp.MeshRasterizer):
            v = verts.detach().clone().requires_grad_(True)
            m = mesh.update_padded(v[None])
            f = rasterizer(cameras=cams, raster_settings=settings)(m)
            (f.zbuf.sum() + (f.bary_coords ** 2).sum() + f.dists.sum()).backward()
            outs.append((f, v.grad))
        (a, ga), (b, gb) = outs
        assert type(b) is type(a)
        assert torch.equal(a.pix_to_face, b.pix_to_face), (dist, cameras)
        for x, y in ((a.zbuf, b.zbuf), (a.bary_coords, b.bary_coords), (a.dists, b.dists)):
            assert (x - y).abs().max() <= 1e-5
        bar = 1e-4 * ga.abs() + GRAD_FLOOR * ga.abs().max()
        assert torch.all((ga - gb).abs() <= bar), (dist, cameras)


def test_the_readmes_pytorch3d_example_runs(gpu):
    pytorch3d_or_skip()
    import re

    text = (GOLDENS.parents[2] / "README.md").read_text()
    section = text[text.index("\n### PyTorch3D\n"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    scope = {}
    exec(compile(code, "README.md (PyTorch3D)", "exec"), scope)
    assert tuple(scope["images"].shape) == (1, 256, 256, 4)
    grad = scope["verts"].grad
    assert grad is not None and bool(grad.isfinite().all()) and float(grad.abs().max()) > 0


def test_pytorch3d_shaders_render_through_softvks_rasterizer(gpu):
    r = pytorch3d_or_skip()
    from pytorch3d.utils import ico_sphere

    mesh = ico_sphere(2)
    mesh.textures = r.TexturesVertex(verts_features=torch.full_like(mesh.verts_padded(), 0.7))
    R, T = r.look_at_view_transform(2.7, 10, 20)
    cams = r.FoVPerspectiveCameras(R=R, T=T)
    settings = r.RasterizationSettings(image_size=32, blur_radius=1e-4, faces_per_pixel=8)
    images = []
    for rasterizer in (r.MeshRasterizer, sp.MeshRasterizer):
        for shader in (
            r.SoftPhongShader(cameras=cams, lights=r.PointLights(location=[[0, 0, -3]])),
            r.SoftSilhouetteShader(),
            r.HardPhongShader(cameras=cams, lights=r.PointLights(location=[[0, 0, -3]])),
        ):
            renderer = r.MeshRenderer(
                rasterizer=rasterizer(cameras=cams, raster_settings=settings), shader=shader
            )
            images.append(renderer(mesh))
    for a, b in zip(images[:3], images[3:]):
        assert (a - b).abs().max() <= 1e-5
