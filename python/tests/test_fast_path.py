"""SoftRenderer's fast path (camera, lighting and face set-up in the engine) renders and
differentiates what SoftRas's composed steps (lighting → transform → soft_rasterize) do."""

import numpy as np
import pytest
import torch

import softvk.soft_renderer as sr
import softvk.torch as st


def composed(renderer, mesh, mode=None):
    """SoftRas's steps one by one, through the public modules."""
    copy = sr.Mesh(mesh.vertices, mesh.faces, mesh.textures, texture_type=mesh.texture_type)
    renderer.set_texture_mode(mesh.texture_type)
    return renderer.rasterizer(renderer.transform(renderer.lighting(copy)), mode)


@pytest.fixture
def engine_calls(monkeypatch):
    calls = []
    original = st.render_mesh

    def counted(*args, **kwargs):
        calls.append(kwargs)
        return original(*args, **kwargs)

    monkeypatch.setattr(st, "render_mesh", counted)
    return calls


def spot(assets, views, texture_res=2):
    mesh = sr.Mesh.from_obj(str(assets / "spot_triangulated.obj"), load_texture=True, texture_res=texture_res)
    return mesh.vertices.repeat(views, 1, 1), mesh.faces.repeat(views, 1, 1), mesh.textures.repeat(views, 1, 1, 1)


def compare(renderer, vertices, faces, textures, texture_type, mode, engine_calls, atol=3e-4):
    weights = torch.rand(3, 4, renderer.rasterizer.image_size, renderer.rasterizer.image_size,
                         generator=torch.Generator().manual_seed(0))[: vertices.shape[0]]
    results = []
    for fast in (True, False):
        v = vertices.clone().requires_grad_(True)
        t = textures.clone().requires_grad_(True)
        mesh = sr.Mesh(v, faces, t, texture_type=texture_type)
        calls = len(engine_calls)
        images = renderer.render_mesh(mesh, mode) if fast else composed(renderer, mesh, mode)
        assert len(engine_calls) == calls + (1 if fast else 0)
        w = weights[:, 3] if mode == "silhouettes" else weights[:, : images.shape[1]]
        (images * w).sum().backward()
        results.append((images.detach(), v.grad, t.grad))
    (image_f, v_f, t_f), (image_c, v_c, t_c) = results
    np.testing.assert_allclose(image_f.numpy(), image_c.numpy(), atol=atol, rtol=0)
    # The two paths round the projection differently (float32 in the engine's face set-up,
    # torch's float32 ops here). For a face seen nearly edge-on (its screen determinant near
    # SoftRas's 1e-10 clamp) the forward is discontinuous in its vertices, and its share of the
    # gradient jumps between the two roundings (spot has a few in these views). Everywhere else
    # the gradients agree to float rounding.
    for fast_grad, composed_grad in ((v_f, v_c), (t_f, t_c)):
        scale = composed_grad.abs().max().item()
        if fast_grad is t_f and mode == "silhouettes":
            assert scale == 0 and fast_grad.abs().max() == 0  # alpha has no colour gradient
            continue
        assert scale > 0
        close = (fast_grad - composed_grad).abs() <= 1e-3 * scale
        assert close.float().mean() > 0.99, close.float().mean()


def test_look_at_surface_textures(gpu, assets, engine_calls):
    renderer = sr.SoftRenderer(image_size=32, camera_mode="look_at", sigma_val=1e-4, gamma_val=1e-3)
    renderer.transform.set_eyes_from_angles(torch.tensor([2.732, 2.5, 3.0]),
                                            torch.tensor([30.0, 10.0, -20.0]),
                                            torch.tensor([0.0, 120.0, 240.0]))
    compare(renderer, *spot(assets, 3), "surface", None, engine_calls)


def test_orthographic_vertex_colours_and_two_lights(gpu, assets, engine_calls):
    renderer = sr.SoftRenderer(image_size=32, camera_mode="look_at", perspective=False,
                               viewing_scale=0.8, sigma_val=1e-4, gamma_val=1e-3,
                               light_intensity_ambient=0.3, light_directions=[0.2, 1, -0.3])
    renderer.lighting.directionals.append(sr.lighting.DirectionalLighting(0.4, [1, 0.5, 0.2], [-1, 0, 0]))
    renderer.transform.set_eyes_from_angles(2.732, 25, 60)
    vertices, faces, _ = spot(assets, 2)
    colours = torch.rand(vertices.shape, generator=torch.Generator().manual_seed(1))
    compare(renderer, vertices, faces, colours, "vertex", "rgb", engine_calls)


def test_projection_camera_silhouettes_with_anti_aliasing(gpu, assets, engine_calls):
    K = torch.tensor([[60.0, 0, 32], [0, 60.0, 32], [0, 0, 1]])
    Rt = torch.tensor([[1.0, 0, 0, 0.1], [0, 1.0, 0, -0.05], [0, 0, 1.0, 2.5]])
    renderer = sr.SoftRenderer(image_size=24, camera_mode="projection", P=(K @ Rt)[None].repeat(2, 1, 1),
                               orig_size=64, sigma_val=1e-4, anti_aliasing=True)
    compare(renderer, *spot(assets, 2, texture_res=1), "surface", "silhouettes", engine_calls)


def test_settings_the_engine_cannot_take_fall_back_to_the_composed_steps(gpu, assets, engine_calls):
    vertices, faces, textures = spot(assets, 2)
    mesh = sr.Mesh(vertices, faces, textures)
    look = sr.SoftRenderer(image_size=16, camera_mode="look", viewing_angle=30)
    look.render_mesh(mesh)
    depth = sr.SoftRenderer(image_size=16, camera_mode="look_at")
    depth.render_mesh(mesh, mode="depth")
    per_mesh_light = sr.SoftRenderer(image_size=16, camera_mode="look_at",
                                     light_directions=torch.tensor([[0.0, 1, 0], [1, 0, 0]]))
    per_mesh_light.render_mesh(mesh)
    assert engine_calls == []
