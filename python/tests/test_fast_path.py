"""SoftRenderer's fast path (camera, lighting and face set-up in the engine) renders and
differentiates what SoftRas's composed steps (lighting → transform → soft_rasterize) do."""

import numpy as np
import pytest
import torch

import softvk.soft_renderer as sr
import softvk.torch as st


def composed(renderer, mesh):
    """SoftRas's steps one by one, through the public modules."""
    copy = sr.Mesh(mesh.vertices, mesh.faces, mesh.textures, texture_type=mesh.texture_type)
    renderer.set_texture_mode(mesh.texture_type)
    return renderer.rasterizer(renderer.transform(renderer.lighting(copy)))


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


def screen_determinants(renderer, vertices, faces):
    """[B, F] each face's signed screen-space determinant, the camera in float64."""
    with torch.no_grad():
        mesh = sr.Mesh(vertices.double(), faces)
        v = renderer.transform(mesh).face_vertices
        e1, e2 = v[..., 1, :2] - v[..., 0, :2], v[..., 2, :2] - v[..., 0, :2]
        return e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]


# Faces seen edge-on: below this |screen determinant| (in NDC², about 1e-5 of a pixel at 32²) a
# face's barycentrics are the ratio of two roundings, so its coverage and colour are
# discontinuous in its vertices, and the fast path's f32 projection gives its pixels other terms
# than an exact one. Measured on these scenes: spot's face 548 in view 1 of the first test
# (|det| 3.2e-9) is the only face below it.
EDGE_ON = 1e-7
# Every other component: |fast − reference| ≤ REL·|reference| + FLOOR·scale (scale the family's
# largest), the reference being SoftRas's composed steps in float64 (the f64 twin). What is left
# is the fast path's f32 rounding. Spot's faces are sub-pixel at these sizes, where the distance
# has kinks (the nearest point leaving an edge for its end): a pixel near one gives its term to
# one vertex in f32 and another in f64, so a component fed by few pixels can be off by about one
# pixel's term (tests/raster_backward.rs, KINKED: the same bars). The composed steps in float32
# show it: against float64 they are off by 5.6e-3 of the largest on vertex 1265 of the second
# test. Measured, the fast path's worst component uses a fifth of these bars.
REL, FLOOR = 5e-2, 2e-4


def compare(renderer, vertices, faces, textures, texture_type, mode, engine_calls, atol=3e-4):
    """The fast path (``renderer.render_mesh``, or ``softvk.torch.render`` for silhouettes)
    against SoftRas's steps one by one, in float32 (images) and float64 (images and every
    gradient component but those of edge-on faces and their vertices)."""
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

    edge_on = screen_determinants(renderer, vertices, faces).abs() < EDGE_ON  # [B, F]
    vertex_mask = torch.zeros(v_r.shape[:2], dtype=torch.bool)
    for b, f in edge_on.nonzero().tolist():
        vertex_mask[b, faces[b, f].long()] = True
    texel_mask = edge_on if texture_type == "surface" else vertex_mask
    shares = {}
    for name, fast_grad, reference, skip in (("vertices", v_f, v_r, vertex_mask),
                                             ("textures", t_f, t_r, texel_mask)):
        scale = reference.abs().max().item()
        if name == "textures" and mode == "silhouettes":
            assert scale == 0 and fast_grad.abs().max() == 0  # alpha has no colour gradient
            continue
        assert scale > 0
        share = (fast_grad - reference).abs() / (REL * reference.abs() + FLOOR * scale)
        share[skip] = 0
        shares[name] = worst = share.max().item()
        where = np.unravel_index(share.argmax().item(), share.shape)
        assert worst <= 1, (f"{name} {where}: {fast_grad[where].item()} against "
                            f"{reference[where].item()} (largest {scale})")
    return edge_on, shares


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
    compare(renderer, vertices, faces, colours, "vertex", None, engine_calls)


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
    st.render(depth, mesh, "depth")
    per_mesh_light = sr.SoftRenderer(image_size=16, camera_mode="look_at",
                                     light_directions=torch.tensor([[0.0, 1, 0], [1, 0, 0]]))
    per_mesh_light.render_mesh(mesh)
    assert engine_calls == []
