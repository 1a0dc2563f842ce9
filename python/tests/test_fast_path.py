"""SoftRenderer's fast path (camera, lighting and face set-up in the engine) renders and
differentiates what SoftRas's composed steps (lighting → transform → soft_rasterize) do."""

import math

import numpy as np
import torch

import softvk.soft_renderer as sr
import softvk.torch as st
from test_softras_divergences import nearest_depth


def composed(renderer, mesh):
    """SoftRas's steps one by one, through the public modules."""
    copy = sr.Mesh(mesh.vertices, mesh.faces, mesh.textures, texture_type=mesh.texture_type)
    renderer.set_texture_mode(mesh.texture_type)
    return renderer.rasterizer(renderer.transform(renderer.lighting(copy)))


def spot(assets, views, texture_res=2):
    mesh = sr.Mesh.from_obj(str(assets / "spot_triangulated.obj"), load_texture=True, texture_res=texture_res)
    return mesh.vertices.repeat(views, 1, 1), mesh.faces.repeat(views, 1, 1), mesh.textures.repeat(views, 1, 1, 1)


# Every component: |fast − reference| ≤ REL·|reference| + FLOOR·scale (scale the family's
# largest), the reference being SoftRas's composed steps in float64 (the f64 twin); no face is
# left out, edge-on slivers included (spot's face 548 in the first test's second view, |screen
# determinant| 3.2e-9, whose sign the engine once got wrong from f32 screen vertices and so moved
# its neighbours' colour gradients by 7.5 %: face_setup.comp's look_at_det). What is left is the
# fast path's f32 projection against the exact one, amplified where a pixel's depth softmax is
# sharp (γ 1e-3). Measured on these scenes: the worst component above the floor is off by
# 3.1e-4 of itself, the worst below it by 8.5e-6 of the largest (orthographic, vertex colours):
# margins of 6 and 2.4. The composed steps in float32 would not pass these bars (5.6e-3 of the
# largest on one vertex of the second test: sub-pixel faces, whose distance kinks send a pixel's
# term to one vertex or another by rounding), which is why the reference is float64.
REL, FLOOR = 2e-3, 2e-5


def compare(renderer, vertices, faces, textures, texture_type, mode, engine_calls, atol=3e-4):
    """The fast path (``renderer.render_mesh``, or ``softvk.torch.render`` for silhouettes)
    against SoftRas's steps one by one, in float32 (images) and float64 (images and every
    gradient component)."""
    height, width = renderer.rasterizer.image_size, renderer.rasterizer.image_size
    weights = torch.rand(3, 4, height, width, generator=torch.Generator().manual_seed(0))
    weights = weights[: vertices.shape[0]]
    results = []
    for way in ("fast", "float32", "float64"):
        dtype = torch.float64 if way == "float64" else torch.float32
        v = vertices.to(dtype).clone().requires_grad_(True)
        t = textures.to(dtype).clone().requires_grad_(True)
        mesh = sr.Mesh(v, faces, t, texture_type=texture_type)
        calls = len(engine_calls)
        if way == "fast":
            images = st.render(renderer, mesh, "silhouettes" if mode == "silhouettes" else "rgba")
        else:
            images = composed(renderer, mesh)
            images = images[:, 3] if mode == "silhouettes" else images
        assert len(engine_calls) == calls + (1 if way == "fast" else 0)
        w = weights[:, 3] if mode == "silhouettes" else weights
        (images * w.to(dtype)).sum().backward()
        results.append((images.detach().double(), v.grad.double(), t.grad.double()))
    (image_f, v_f, t_f), (image_32, _, _), (image_64, v_r, t_r) = results
    np.testing.assert_allclose(image_f.numpy(), image_32.numpy(), atol=atol, rtol=0)
    np.testing.assert_allclose(image_f.numpy(), image_64.numpy(), atol=atol, rtol=0)

    shares = {}
    for name, fast_grad, reference in (("vertices", v_f, v_r), ("textures", t_f, t_r)):
        scale = reference.abs().max().item()
        if name == "textures" and mode == "silhouettes":
            assert scale == 0 and fast_grad.abs().max() == 0  # alpha has no colour gradient
            continue
        assert scale > 0
        share = (fast_grad - reference).abs() / (REL * reference.abs() + FLOOR * scale)
        shares[name] = worst = share.max().item()
        where = np.unravel_index(share.argmax().item(), share.shape)
        assert worst <= 1, (f"{name} {where}: {fast_grad[where].item()} against "
                            f"{reference[where].item()} (largest {scale})")
    return shares


def test_look_at_surface_textures(gpu, assets, engine_calls):
    renderer = sr.SoftRenderer(image_size=32, camera_mode="look_at", sigma_val=1e-4, gamma_val=1e-3)
    renderer.transform.set_eyes_from_angles(torch.tensor([2.732, 2.5, 3.0]),
                                            torch.tensor([30.0, 10.0, -20.0]),
                                            torch.tensor([0.0, 120.0, 240.0]))
    vertices, faces, textures = spot(assets, 3)
    # The second view sees face 548 edge-on: the sliver whose determinant's sign must come out
    # right for its neighbours' colour gradients to (see REL, FLOOR).
    with torch.no_grad():
        v = renderer.transform(sr.Mesh(vertices.double(), faces)).face_vertices[1, 548]
    det = (v[1, 0] - v[0, 0]) * (v[2, 1] - v[0, 1]) - (v[2, 0] - v[0, 0]) * (v[1, 1] - v[0, 1])
    assert abs(det) < 1e-8
    compare(renderer, vertices, faces, textures, "surface", None, engine_calls)


def test_orthographic_vertex_colours_and_two_lights(gpu, assets, engine_calls):
    renderer = sr.SoftRenderer(image_size=32, camera_mode="look_at", perspective=False,
                               viewing_scale=0.8, sigma_val=1e-4, gamma_val=1e-3,
                               light_intensity_ambient=0.3, light_directions=[0.2, 1, -0.3])
    renderer.lighting.directionals.append(sr.lighting.DirectionalLighting(0.4, [1, 0.5, 0.2], [-1, 0, 0]))
    renderer.transform.set_eyes_from_angles(2.732, 25, 60)
    vertices, faces, _ = spot(assets, 2)
    colours = torch.rand(vertices.shape, generator=torch.Generator().manual_seed(1))
    compare(renderer, vertices, faces, colours, "vertex", None, engine_calls)


def test_projection_camera_silhouettes_with_anti_aliasing(gpu, assets, engine_calls):
    K = torch.tensor([[60.0, 0, 32], [0, 60.0, 32], [0, 0, 1]])
    Rt = torch.tensor([[1.0, 0, 0, 0.1], [0, 1.0, 0, -0.05], [0, 0, 1.0, 2.5]])
    renderer = sr.SoftRenderer(image_size=24, camera_mode="projection", P=(K @ Rt)[None].repeat(2, 1, 1),
                               orig_size=64, sigma_val=1e-4, anti_aliasing=True)
    compare(renderer, *spot(assets, 2, texture_res=1), "surface", "silhouettes", engine_calls)


# The fall-backs' results against another path: measured 7.2e-7 (images, against the engine's
# path), 3.7e-7 (depths of 2.1 to 2.8, against nearest_depth), on this scene.
FALLBACK_ATOL = 2e-6


def test_settings_the_engine_cannot_take_fall_back_to_the_composed_steps(gpu, assets, engine_calls):
    vertices, faces, textures = spot(assets, 2)
    mesh = sr.Mesh(vertices, faces, textures)
    look = sr.SoftRenderer(image_size=16, camera_mode="look", viewing_angle=30)
    looked = look.render_mesh(mesh)
    depth = sr.SoftRenderer(image_size=16, camera_mode="look_at")
    depths = st.render(depth, mesh, "depth")
    directions = [[0.0, 1, 0], [1, 0, 0]]
    per_mesh_light = sr.SoftRenderer(image_size=16, camera_mode="look_at",
                                     light_directions=torch.tensor(directions))
    lit = per_mesh_light.render_mesh(mesh)
    assert engine_calls == []

    # And each renders what another path renders. "look" along +z (its default) from the
    # default eye on -z is look_at the origin from there: the engine's path.
    default = sr.SoftRenderer(image_size=16, camera_mode="look_at")
    np.testing.assert_allclose(looked.numpy(), default.render_mesh(mesh).numpy(),
                               atol=FALLBACK_ATOL, rtol=0)
    # Per-mesh lights: each mesh alone, with its light, through the engine's path.
    for b, direction in enumerate(directions):
        alone = sr.SoftRenderer(image_size=16, camera_mode="look_at", light_directions=direction)
        image = alone.render_mesh(sr.Mesh(vertices[b:b + 1], faces[b:b + 1], textures[b:b + 1]))
        np.testing.assert_allclose(lit[b].numpy(), image[0].numpy(), atol=FALLBACK_ATOL, rtol=0)
    assert (lit[0] - lit[1]).abs().max() > 0.1
    assert len(engine_calls) == 3
    # Depth: the nearest face's, written out.
    eye = [0.0, 0.0, -(1 / math.tan(math.radians(30)) + 1)]  # SoftRas's default
    want = nearest_depth(vertices, faces, eye, 16)
    assert (want < 100).sum() > 40
    np.testing.assert_allclose(depths.numpy(), want.numpy(), atol=FALLBACK_ATOL, rtol=0)
