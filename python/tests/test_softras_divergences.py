"""Called as SoftRas is called, ``softvk.soft_renderer`` returns what SoftRas returns, or raises one
clear error: never something else in silence.

- ``mode=`` is ignored, as SoftRas ignores it (test_compat_renderer.py, with a fake engine);
- ``SoftRenderer`` takes the engine's fast path only when it computes what SoftRas's composed
  steps compute: replaced, subclassed or hooked modules, replaced functions and float64 meshes
  take the composed steps; attributes changed after construction are read at each call;
- float64 is computed in double (the f64 twin), as SoftRas's kernels compute doubles;
- a tensor ``viewing_angle`` (batched, or requiring a gradient), non-square images with and
  without anti-aliasing, ``fill_back``, ``near``/``far``, ``background_color`` and ``eps`` hold in
  every path.
"""

import numpy as np
import pytest
import torch

import softvk
import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf
import softvk.torch as st


def sphere(assets, batch=2, dtype=torch.float32, seed=0):
    """SoftRas's 642-vertex sphere, squashed and shifted so that no view is symmetric, with
    random 2×2 surface textures."""
    mesh = sr.Mesh.from_obj(str(assets / "sphere_642.obj"))
    vertices = mesh.vertices * torch.tensor([0.9, 0.6, 0.75]) + torch.tensor([0.1, 0.05, 0.0])
    textures = torch.rand(1, mesh.num_faces, 4, 3, generator=torch.Generator().manual_seed(seed))
    return (vertices.repeat(batch, 1, 1).to(dtype), mesh.faces.repeat(batch, 1, 1),
            textures.repeat(batch, 1, 1, 1).to(dtype))


def look_at_renderer(batch=2, **kw):
    renderer = sr.SoftRenderer(**{**dict(image_size=24, camera_mode="look_at", sigma_val=1e-4,
                                         gamma_val=1e-3), **kw})
    renderer.transform.set_eyes_from_angles(2.7, torch.tensor([20.0, -30.0][:batch]),
                                            torch.tensor([40.0, 200.0][:batch]))
    return renderer


def composed(renderer, mesh):
    """SoftRas's steps one by one, through the renderer's own modules."""
    copy = sr.Mesh(mesh.vertices, mesh.faces, mesh.textures, texture_type=mesh.texture_type)
    renderer.set_texture_mode(mesh.texture_type)
    return renderer.rasterizer(renderer.transform(renderer.lighting(copy)))


def render_both(renderer, vertices, faces, textures):
    mesh = sr.Mesh(vertices, faces, textures)
    return renderer.render_mesh(mesh), composed(renderer, mesh)


# Fast path against composed steps in float32: the projection rounds differently (the engine's
# face set-up against torch's), which moves a pixel by about 1e-5 at most (test_fast_path.py).
ATOL = 1e-4


# --- Replaced, subclassed or hooked modules and functions take the composed steps ---------------

class DoubledLight(sr.Lighting):
    def forward(self, mesh):
        mesh = super().forward(mesh)
        mesh.textures = mesh.textures * 2
        return mesh


class ShiftedCamera(sr.Transform):
    def forward(self, mesh):
        mesh = super().forward(mesh)
        mesh.vertices = mesh.vertices + torch.tensor([0.25, 0.0, 0.0])
        return mesh


class MirroredRasterizer(sr.SoftRasterizer):
    def forward(self, mesh, mode=None):
        return super().forward(mesh, mode).flip(-1)


def replace_lighting(renderer, monkeypatch):
    lighting = DoubledLight()
    lighting.light_mode = renderer.lighting.light_mode
    renderer.lighting = lighting


def replace_transform(renderer, monkeypatch):
    transform = ShiftedCamera("look_at")
    transform.transformer = renderer.transform.transformer
    renderer.transform = transform


def replace_rasterizer(renderer, monkeypatch):
    mirrored = MirroredRasterizer()
    mirrored.__dict__.update({k: v for k, v in vars(renderer.rasterizer).items()
                              if not k.startswith("_")})
    renderer.rasterizer = mirrored


def replace_soft_rasterize(renderer, monkeypatch):
    original = srf.soft_rasterize
    monkeypatch.setattr(srf, "soft_rasterize", lambda *args: original(*args) * 0.5)


def replace_perspective(renderer, monkeypatch):
    original = srf.perspective
    monkeypatch.setattr(srf, "perspective", lambda v, angle=30: original(v, angle) * 1.2)


def hook_rasterizer(renderer, monkeypatch):
    renderer.rasterizer.register_forward_hook(lambda module, inputs, output: 1 - output)


def hook_lighting_before(renderer, monkeypatch):
    def brighten(module, inputs):
        (mesh,) = inputs
        mesh.textures = mesh.textures + 0.5
        return (mesh,)

    renderer.lighting.register_forward_pre_hook(brighten)


def instance_forward(renderer, monkeypatch):
    renderer.lighting.forward = lambda mesh: mesh  # unlit


def replace_directional(renderer, monkeypatch):
    class Dimmed(sr.DirectionalLighting):
        def forward(self, light, normals):
            return super().forward(light, normals) * 0.5

    renderer.lighting.directionals[0] = Dimmed(0.5, [1, 1, 1], [0, 1, 0])


@pytest.mark.parametrize("change", [
    replace_lighting, replace_transform, replace_rasterizer, replace_soft_rasterize,
    replace_perspective, hook_rasterizer, hook_lighting_before, instance_forward,
    replace_directional,
], ids=lambda f: f.__name__)
def test_a_replaced_step_takes_the_composed_steps(gpu, assets, engine_calls, monkeypatch, change):
    renderer = look_at_renderer()
    vertices, faces, textures = sphere(assets)
    before = renderer.render_mesh(sr.Mesh(vertices, faces, textures)).detach()
    assert len(engine_calls) == 1
    change(renderer, monkeypatch)
    images, expected = render_both(renderer, vertices, faces, textures)
    assert len(engine_calls) == 1, "the engine's path ignored the change"
    assert torch.equal(images, expected)
    assert (images - before).abs().max() > 0.05, "the change should show in the images"


def test_a_mesh_subclass_or_filled_back_faces_take_the_composed_steps(gpu, assets, engine_calls):
    class Other(sr.Mesh):
        pass

    renderer = look_at_renderer()
    vertices, faces, textures = sphere(assets)
    renderer.render_mesh(Other(vertices, faces, textures))
    filled = sr.Mesh(vertices, faces, textures)
    filled.fill_back_()
    renderer.render_mesh(filled)
    assert engine_calls == []


def test_attributes_changed_after_construction_are_read_at_the_call(gpu, assets, engine_calls):
    renderer = look_at_renderer()
    vertices, faces, textures = sphere(assets)
    first = renderer.render_mesh(sr.Mesh(vertices, faces, textures)).detach()
    renderer.lighting.ambient.light_intensity = 0.3
    renderer.lighting.ambient.light_color = [1.0, 0.8, 0.6]
    renderer.lighting.directionals[0].light_direction = [1.0, 0.5, 0.0]
    renderer.lighting.directionals[0].light_intensity = 0.9
    renderer.transform.transformer.viewing_angle = 24
    r = renderer.rasterizer
    r.background_color, r.near, r.far, r.eps, r.fill_back = [0.2, 0.3, 0.4], 2.1, 3.4, 1e-2, False
    r.sigma_val, r.gamma_val, r.aggr_func_alpha = 3e-4, 1e-2, "sum"
    images, expected = render_both(renderer, vertices, faces, textures)
    assert len(engine_calls) == 2  # both renders took the engine's path
    np.testing.assert_allclose(images.numpy(), expected.numpy(), atol=ATOL, rtol=0)
    assert (images - first).abs().max() > 0.1


def test_a_camera_swapped_after_construction_is_the_one_used(gpu, assets, engine_calls):
    # Built as look_at, then given a projection camera: the camera the composed steps use (the
    # transformer), not the mode named at construction.
    renderer = look_at_renderer()
    K = torch.tensor([[60.0, 0, 32], [0, 60.0, 32], [0, 0, 1]])
    Rt = torch.tensor([[1.0, 0, 0, 0.1], [0, 1.0, 0, -0.05], [0, 0, 1.0, 2.5]])
    renderer.transform.transformer = sr.Projection((K @ Rt)[None].repeat(2, 1, 1), orig_size=64)
    images, expected = render_both(renderer, *sphere(assets))
    assert len(engine_calls) == 1
    np.testing.assert_allclose(images.numpy(), expected.numpy(), atol=ATOL, rtol=0)


# --- float64 is computed in double ---------------------------------------------------------------

def test_float64_soft_rasterize_is_the_f64_twin_and_passes_gradcheck(gpu):
    rng = np.random.default_rng(3)
    faces = np.concatenate([rng.uniform(-0.8, 0.8, (1, 2, 3, 2)), rng.uniform(2, 4, (1, 2, 3, 1))], -1)
    textures = rng.uniform(0, 1, (1, 2, 4, 3))
    kw = dict(image_size=(5, 6), sigma_val=1e-2, gamma_val=5e-2, dist_eps=1e-10)
    f = torch.tensor(faces, requires_grad=True)
    t = torch.tensor(textures, requires_grad=True)
    images = st.soft_rasterize(f, t, **kw)
    assert images.dtype == torch.float64
    twin = softvk.reference_rasterize(faces, textures, st.rasterize_settings(**kw))
    assert torch.equal(images, torch.from_numpy(twin).permute(0, 3, 1, 2))
    assert torch.autograd.gradcheck(lambda a, b: st.soft_rasterize(a, b, **kw), (f, t),
                                    eps=1e-6, atol=1e-6, rtol=1e-4)


def test_float64_meshes_render_in_double_through_softrenderer(gpu, assets, engine_calls):
    renderer = look_at_renderer(batch=1, image_size=8, sigma_val=1e-2, gamma_val=1e-1,
                                dist_eps=1e-10)
    vertices, faces, textures = sphere(assets, batch=1, dtype=torch.float64)
    v = vertices.clone().requires_grad_(True)
    images = renderer(v, faces, textures)
    assert images.dtype == torch.float64 and engine_calls == []
    # In double, the gradient to the vertices matches central differences of the forward.
    weights = torch.rand(images.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(2))
    (images * weights).sum().backward()
    picks = [(0, 3, 0), (0, 100, 1), (0, 321, 2), (0, 500, 0)]
    for i in picks:
        up, down = vertices.clone(), vertices.clone()
        up[i] += 1e-6
        down[i] -= 1e-6
        fd = ((renderer(up, faces, textures) - renderer(down, faces, textures)) * weights).sum() / 2e-6
        assert abs(v.grad[i] - fd) <= 1e-5 * abs(fd) + 1e-7 * v.grad.abs().max(), (i, v.grad[i], fd)
    assert v.grad.abs().max() > 1e-3


def test_mixed_or_unsupported_dtypes_are_one_clear_error(gpu):
    faces, textures = torch.rand(1, 2, 3, 3, dtype=torch.float64), torch.rand(1, 2, 1, 3)
    with pytest.raises(TypeError, match="one dtype"):
        st.soft_rasterize(faces, textures)
    with pytest.raises(TypeError, match="float32"):
        st.soft_rasterize(faces.half(), textures.half())
    with pytest.raises(TypeError, match="render_mesh takes torch.float32"):
        st.render_mesh(torch.rand(1, 3, 3, dtype=torch.float64), torch.tensor([[0, 1, 2]]))


# --- Settings in every path ----------------------------------------------------------------------

def test_a_batched_tensor_viewing_angle_gives_each_mesh_its_own(gpu, assets, engine_calls):
    angles = torch.tensor([20.0, 35.0])
    renderer = look_at_renderer(viewing_angle=angles)
    vertices, faces, textures = sphere(assets)
    images, expected = render_both(renderer, vertices, faces, textures)
    assert len(engine_calls) == 1
    np.testing.assert_allclose(images.numpy(), expected.numpy(), atol=ATOL, rtol=0)
    for b, angle in enumerate(angles.tolist()):
        single = look_at_renderer(viewing_angle=angle)
        alone = single.render_mesh(sr.Mesh(vertices, faces, textures))
        assert torch.equal(images[b], alone[b])


def test_a_viewing_angle_that_requires_grad_gets_its_gradient(gpu, assets, engine_calls):
    renderer = look_at_renderer(batch=1, image_size=8, sigma_val=1e-2, gamma_val=1e-1,
                                dist_eps=1e-10)
    vertices, faces, textures = sphere(assets, batch=1, dtype=torch.float64)
    angle = torch.tensor(30.0, dtype=torch.float64, requires_grad=True)
    renderer.transform.transformer.viewing_angle = angle
    weights = torch.rand(1, 4, 8, 8, dtype=torch.float64, generator=torch.Generator().manual_seed(4))
    (renderer(vertices, faces, textures) * weights).sum().backward()
    assert engine_calls == [] and angle.grad is not None

    def loss(a):
        renderer.transform.transformer.viewing_angle = torch.tensor(a, dtype=torch.float64)
        return float((renderer(vertices, faces, textures) * weights).sum())

    fd = (loss(30.0 + 1e-5) - loss(30.0 - 1e-5)) / 2e-5
    assert abs(fd) > 1e-3 and abs(angle.grad.item() - fd) <= 1e-5 * abs(fd)
    # In float32 too, the angle's gradient is not dropped by the engine's path.
    angle32 = torch.tensor(30.0, requires_grad=True)
    renderer.transform.transformer.viewing_angle = angle32
    (renderer(vertices.float(), faces, textures.float()) * weights.float()).sum().backward()
    assert engine_calls == [] and abs(angle32.grad.item() - fd) <= 1e-2 * abs(fd)


@pytest.mark.parametrize("anti_aliasing", [False, True])
def test_non_square_images_in_every_path(gpu, assets, engine_calls, anti_aliasing):
    renderer = look_at_renderer(image_size=(20, 28), anti_aliasing=anti_aliasing)
    vertices, faces, textures = sphere(assets)
    images, expected = render_both(renderer, vertices, faces, textures)
    assert images.shape == expected.shape == (2, 4, 20, 28) and len(engine_calls) == 1
    np.testing.assert_allclose(images.numpy(), expected.numpy(), atol=ATOL, rtol=0)
    # The shorter side spans the view: the middle 20 columns are the square 20×20 image.
    square = look_at_renderer(image_size=20, anti_aliasing=anti_aliasing)
    assert torch.equal(images[..., 4:24], square.render_mesh(sr.Mesh(vertices, faces, textures)))
    with torch.no_grad():
        f64 = renderer(vertices.double(), faces, textures.double())
    assert f64.shape == (2, 4, 20, 28)
    np.testing.assert_allclose(f64.numpy(), expected.numpy(), atol=ATOL, rtol=0)


@pytest.mark.parametrize("setting", [
    # near/far through the sphere (depths 1.9–3.5); eps near the faces' normalized depths,
    # (100 − z) / 99 ≈ 0.98, where the background's weight in the softmax shows.
    dict(fill_back=False), dict(near=2.2, far=3.0), dict(background_color=[0.3, 0.6, 0.9]),
    dict(eps=0.99),
], ids=lambda d: ",".join(d))
def test_each_setting_holds_in_every_path(gpu, assets, engine_calls, setting):
    """The engine's path, the composed steps (float32) and the f64 twin (float64) give one image
    for each of these settings, and each setting shows in it."""
    default = look_at_renderer()
    renderer = look_at_renderer(**setting)
    vertices, faces, textures = sphere(assets)
    images, expected = render_both(renderer, vertices, faces, textures)
    assert len(engine_calls) == 1
    np.testing.assert_allclose(images.numpy(), expected.numpy(), atol=ATOL, rtol=0)
    with torch.no_grad():
        double = renderer(vertices.double(), faces, textures.double())
    np.testing.assert_allclose(double.numpy(), expected.numpy(), atol=ATOL, rtol=0)
    plain = default.render_mesh(sr.Mesh(vertices, faces, textures))
    assert (images - plain).abs().max() > 0.02, "the setting should show in the images"
