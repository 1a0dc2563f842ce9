"""SoftRenderer / SoftRasterizer plumbing with the engine replaced by a recording fake.

What reaches ``soft_rasterize`` (screen-space faces, lit textures, every setting, in the engine's
argument order), anti-aliasing, the output modes and the untouched input mesh are checked here
without a renderer; the engine's images are tested with the engine.
"""

import math

import numpy as np
import pytest
import torch

import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf

SOFTRAS_RASTER_DEFAULTS = dict(
    image_size=256, background_color=[0, 0, 0], near=1, far=100, anti_aliasing=False,
    fill_back=True, eps=1e-3, sigma_val=1e-5, dist_func="euclidean", dist_eps=1e-4,
    gamma_val=1e-4, aggr_func_rgb="softmax", aggr_func_alpha="prod", texture_type="surface",
)
ENGINE_ARGS = ["face_vertices", "textures", "image_size", "background_color", "near", "far",
               "fill_back", "eps", "sigma_val", "dist_func", "dist_eps", "gamma_val",
               "aggr_func_rgb", "aggr_func_alpha", "texture_type"]


class FakeEngine:
    """Records each call; returns [B, 4, S, S] images: RGB = the first face's first texel (or
    corner colour), alpha = 1 on the left half, background colour where alpha is 0."""

    def __init__(self):
        self.calls = []

    def __call__(self, *args):
        assert len(args) == len(ENGINE_ARGS), "soft_rasterize takes its 15 arguments positionally"
        call = dict(zip(ENGINE_ARGS, args))
        self.calls.append(call)
        textures, size = call["textures"], call["image_size"]
        batch = textures.shape[0]
        alpha = torch.zeros(batch, 1, size, size, dtype=textures.dtype)
        alpha[:, :, :, : size // 2] = 1
        color = textures[:, 0, 0, :][:, :, None, None]
        background = torch.tensor(call["background_color"], dtype=textures.dtype)
        background = background[None, :, None, None]
        rgb = alpha * color + (1 - alpha) * background
        return torch.cat([rgb, alpha], dim=1)


@pytest.fixture
def engine(monkeypatch):
    """Records the composed steps' call of ``soft_rasterize`` (the engine's fast path, which
    test_fast_path.py compares with these steps, is turned off here)."""
    fake = FakeEngine()
    monkeypatch.setattr(srf, "soft_rasterize", fake)
    monkeypatch.setattr(sr.SoftRenderer, "_engine_arguments", lambda self, mesh: None)
    return fake


def triangle_mesh(dtype=torch.float64):
    vertices = torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5], [0.5, 0.0, 0.0],
                             [0.0, 0.5, 0.0]], dtype=dtype)
    faces = torch.tensor([[0, 1, 2], [0, 3, 2]])
    textures = torch.tensor([[[0.2, 0.4, 0.6]], [[1.0, 1.0, 1.0]]], dtype=dtype)
    return sr.Mesh(vertices, faces, textures=textures)


def fake_image(colour, size, background=(0.0, 0.0, 0.0)):
    """FakeEngine's image written out from what should reach it: ``colour`` (the first face's
    first colour, lit) and alpha 1 on the left half, the background and alpha 0 on the right."""
    image = torch.zeros(1, 4, size, size, dtype=torch.float64)
    image[:, :3] = torch.tensor(background, dtype=torch.float64)[:, None, None]
    image[:, :3, :, : size // 2] = torch.tensor(colour, dtype=torch.float64)[:, None, None]
    image[:, 3, :, : size // 2] = 1
    return image


# triangle_mesh's first colour, and lit: face 0's normal is +y, which SoftRas's default lights
# (ambient 0.5, directional 0.5 from +y) give 0.5 + 0.5 · 1.
FACE0_UNLIT = [0.2, 0.4, 0.6]
FACE0_LIT = [c * (0.5 + 0.5 * 1.0) for c in FACE0_UNLIT]


def test_softrenderer_keeps_softras_defaults():
    renderer = sr.SoftRenderer(camera_mode="look_at")
    for name, value in SOFTRAS_RASTER_DEFAULTS.items():
        assert getattr(renderer.rasterizer, name) == value, name
    assert renderer.lighting.light_mode == "surface"
    assert renderer.lighting.ambient.light_intensity == 0.5
    assert renderer.lighting.directionals[0].light_direction == [0, 1, 0]
    assert renderer.transform.camera_mode == "look_at"
    assert renderer.transform.transformer.viewing_angle == 30
    # SoftRas's default camera is a projection matrix, which must then be given.
    with pytest.raises(ValueError):
        sr.SoftRenderer()
    with pytest.raises(ValueError):
        sr.SoftRasterizer(dist_func="gaussian")


def test_render_mesh_sends_lit_screen_space_faces_and_every_setting(engine):
    renderer = sr.SoftRenderer(image_size=32, background_color=[0.1, 0.2, 0.3], near=0.5,
                               far=50, fill_back=False, eps=1e-2, sigma_val=3e-4,
                               dist_func="barycentric", dist_eps=1e-6, gamma_val=2e-3,
                               aggr_func_rgb="hard", aggr_func_alpha="sum",
                               camera_mode="look_at", viewing_angle=20)
    renderer.transform.set_eyes_from_angles(2.5, 30, 45)
    mesh = triangle_mesh()
    images = renderer.render_mesh(mesh)
    assert images.shape == (1, 4, 32, 32)
    call = engine.calls[-1]
    assert [call[k] for k in ENGINE_ARGS[2:]] == [
        32, [0.1, 0.2, 0.3], 0.5, 50, False, 1e-2, 3e-4, "barycentric", 1e-6, 2e-3, "hard",
        "sum", "surface"]

    eye = srf.get_points_from_angles(2.5, 30, 45)
    expected = srf.perspective(srf.look_at(mesh.vertices, eye), angle=20)
    assert torch.allclose(call["face_vertices"], srf.face_vertices(expected, mesh.faces))
    # Face 0's normal is +y (lit 0.5 + 0.5), face 1's is ±z (ambient only).
    assert torch.allclose(call["textures"][0, 0], mesh.textures[0, 0] * 1.0)
    assert torch.allclose(call["textures"][0, 1], mesh.textures[0, 1] * 0.5)


def test_render_mesh_leaves_the_mesh_as_it_was(engine):
    renderer = sr.SoftRenderer(camera_mode="look_at")
    mesh = triangle_mesh()
    vertices, textures = mesh.vertices.clone(), mesh.textures.clone()
    first = renderer.render_mesh(mesh)
    second = renderer.render_mesh(mesh)  # no reset_() needed between renders
    assert torch.equal(mesh.vertices, vertices) and torch.equal(mesh.textures, textures)
    assert torch.equal(first, second)
    assert torch.equal(first, fake_image(FACE0_LIT, 256))
    assert torch.equal(engine.calls[0]["face_vertices"], engine.calls[1]["face_vertices"])


def test_forward_builds_vertex_textured_meshes(engine):
    renderer = sr.SoftRenderer(camera_mode="look_at")
    mesh = triangle_mesh()
    colors = torch.rand(1, 4, 3, dtype=torch.float64)
    renderer(mesh.vertices, mesh.faces, colors, texture_type="vertex")
    call = engine.calls[-1]
    assert call["texture_type"] == "vertex" and renderer.lighting.light_mode == "vertex"
    assert call["textures"].shape == (1, 2, 3, 3)
    lit = sr.Lighting("vertex")(sr.Mesh(mesh.vertices, mesh.faces, colors, texture_type="vertex"))
    assert torch.allclose(call["textures"], srf.face_vertices(lit.textures, mesh.faces))


def test_set_sigma_gamma_and_texture_mode(engine):
    renderer = sr.SoftRenderer(camera_mode="look_at")
    renderer.set_sigma(1e-3)
    renderer.set_gamma(1e-2)
    renderer.render_mesh(triangle_mesh())
    assert engine.calls[-1]["sigma_val"] == 1e-3 and engine.calls[-1]["gamma_val"] == 1e-2
    with pytest.raises(ValueError):
        renderer.set_texture_mode("texel")


def test_anti_aliasing_renders_twice_the_size_and_averages_2x2(monkeypatch):
    sizes = []

    def ramp(face_vertices, textures, image_size, *rest):
        sizes.append(image_size)
        pixels = torch.arange(4 * image_size * image_size, dtype=torch.float64)
        return pixels.reshape(1, 4, image_size, image_size)

    monkeypatch.setattr(srf, "soft_rasterize", ramp)
    images = sr.SoftRasterizer(image_size=8, anti_aliasing=True)(triangle_mesh())
    assert sizes == [16] and images.shape == (1, 4, 8, 8)
    full = ramp(None, None, 16)
    block = full[0, 2, 6:8, 10:12]
    assert torch.isclose(images[0, 2, 3, 5], block.mean())


def test_mode_is_ignored_as_softras_ignores_it(engine):
    """SoftRas's rasterizer and renderer return [B, 4, H, W] whatever ``mode`` says, so that
    ``renderer(v, f, mode='silhouettes')[:, 3]`` is alpha (it read a pixel row of a [B, H, W]
    alpha before)."""
    rasterizer = sr.SoftRasterizer(image_size=4, far=80)
    mesh = triangle_mesh()
    rgba = rasterizer(mesh)
    assert rgba.shape == (1, 4, 4, 4)
    # The engine's RGBA itself (not another mode's output): the fake's image of the unlit mesh.
    # test_softras_divergences.py checks the same with the engine against SoftRas's formulas.
    assert torch.equal(rgba, fake_image(FACE0_UNLIT, 4))
    for mode in ("rgb", "silhouettes", "depth", "normals"):
        assert torch.equal(rasterizer(mesh, mode), rgba)
    renderer = sr.SoftRenderer(image_size=4, camera_mode="look_at")
    images = renderer(mesh.vertices, mesh.faces, mesh.textures)
    assert torch.equal(images, fake_image(FACE0_LIT, 4))
    for mode in ("rgb", "silhouettes", "depth"):
        assert torch.equal(renderer(mesh.vertices, mesh.faces, mesh.textures, mode=mode), images)
        assert torch.equal(renderer.render_mesh(mesh, mode), images)
    assert torch.equal(renderer(mesh.vertices, mesh.faces, mode="silhouettes")[:, 3],
                       images[:, 3])


def test_softvk_render_gives_alpha_and_depth(engine):
    import softvk.torch as st

    renderer = sr.SoftRenderer(image_size=4, camera_mode="look_at", far=80)
    mesh = triangle_mesh()
    rgba = renderer.render_mesh(mesh)
    expected = fake_image(FACE0_LIT, 4)
    assert torch.equal(rgba, expected)
    assert torch.equal(st.render(renderer, mesh), expected)
    assert torch.equal(st.render(renderer, mesh, "silhouettes"), expected[:, 3])
    with pytest.raises(ValueError, match="mode"):
        st.render(renderer, mesh, "rgb")

    rasterizer = sr.SoftRasterizer(image_size=4, far=80)
    mesh.vertices = mesh.vertices + torch.tensor([0.0, 0.0, 2.0], dtype=torch.float64)
    depth = sr.rasterizer.render_depth(rasterizer, mesh)
    call = engine.calls[-1]
    # Depth renders inverse depths as vertex colours with the hard colour aggregation.
    assert call["texture_type"] == "vertex" and call["aggr_func_rgb"] == "hard"
    assert call["background_color"] == [0, 0, 0]
    z = mesh.face_vertices[..., 2]
    assert torch.allclose(call["textures"], (1 / z)[..., None].expand(-1, -1, -1, 3))
    assert depth.shape == (1, 4, 4)
    assert torch.allclose(depth[0, :, :2], torch.full((4, 2), 2.0, dtype=torch.float64))
    assert torch.allclose(depth[0, :, 2:], torch.full((4, 2), 80.0, dtype=torch.float64))
    assert st.render(renderer, triangle_mesh(), "depth").shape == (1, 4, 4)


def test_depth_is_differentiable_in_the_vertices(engine):
    rasterizer = sr.SoftRasterizer(image_size=4)
    vertices = torch.tensor([[0.0, 0.0, 3.0], [0.0, 1.0, 3.0], [1.0, 0.0, 3.0]],
                            dtype=torch.float64, requires_grad=True)
    mesh = sr.Mesh(vertices, torch.tensor([[0, 1, 2]]))
    sr.rasterizer.render_depth(rasterizer, mesh).sum().backward()
    # The fake's covered pixels show corner 0's depth: 8 of them, d(depth)/dz0 = 1 each.
    assert torch.allclose(vertices.grad[0], torch.tensor([0.0, 0.0, 8.0], dtype=torch.float64))
    assert torch.isfinite(vertices.grad).all()


def test_functional_soft_rasterize_calls_softvk_torch_with_softras_defaults(monkeypatch):
    import importlib
    import inspect

    engine_module = importlib.import_module("softvk.torch")
    recorded = []
    monkeypatch.setattr(engine_module, "soft_rasterize", lambda *args: recorded.append(args))
    wrapper = importlib.import_module("softvk.soft_renderer.functional.soft_rasterize")
    face_vertices, textures = torch.zeros(1, 2, 3, 3), torch.ones(1, 2, 1, 3)
    wrapper.soft_rasterize(face_vertices, textures, 16, sigma_val=2e-4)

    expected = dict(SOFTRAS_RASTER_DEFAULTS, image_size=16, sigma_val=2e-4)
    expected.pop("anti_aliasing")
    (args,) = recorded
    assert args[0] is face_vertices and args[1] is textures
    assert list(args[2:]) == [expected[name] for name in ENGINE_ARGS[2:]]
    assert list(inspect.signature(wrapper.soft_rasterize).parameters) == ENGINE_ARGS


def test_default_eye_sees_the_unit_sphere_edge_on():
    transform = sr.Transform("look_at")
    d = 1 / math.tan(math.radians(30)) + 1
    mesh = sr.Mesh(torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                dtype=torch.float64), torch.tensor([[0, 1, 2]]))
    out = transform(mesh).vertices[0].numpy()
    assert np.allclose(out[0], [0, 0, d])
    assert np.allclose(out[1, 0], 1 / (d * math.tan(math.radians(30))))
