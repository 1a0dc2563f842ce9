"""Called as SoftRas is called, ``softvk.soft_renderer`` returns what SoftRas returns, or raises one
clear error: never something else in silence.

- ``mode=`` is ignored, as SoftRas ignores it (here with the engine, test_compat_renderer.py
  with a fake);
- ``SoftRenderer`` takes the engine's fast path only when it computes what SoftRas's composed
  steps compute: replaced, subclassed or hooked modules, replaced functions and float64 meshes
  take the composed steps; attributes changed after construction are read at each call;
- float64 is computed in double (the f64 twin), as SoftRas's kernels compute doubles;
- a tensor ``viewing_angle`` (batched, or requiring a gradient), non-square images with and
  without anti-aliasing, ``fill_back``, ``near``/``far``, ``background_color`` and ``eps`` hold in
  every path.

What "what SoftRas returns" is: besides one path against another (the engine's against the
composed steps), the composed steps, the f64 twin and the fall-backs are held against SoftRas's
steps written out below in plain torch from SPEC §1–2 (``softras_render``, ``softras_rasterize``,
``nearest_depth``; test_fast_path.py uses them too), which share no code with softvk.
"""

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

import softvk
import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf
import softvk.torch as st


# --- SoftRas's steps written out in plain torch (SPEC §1, §2): the independent reference ---------
#
# Nothing of softvk is used here: the camera, the lights and the rasterizer are SPEC's formulas in
# float64, differentiable by autograd. The renderer's paths are held against them below. On
# this file's sphere the rasterizer agrees with the f64 twin to 1e-13 (image), across the
# settings of test_each_setting_holds_in_every_path; its one borrowing is the tie rule of
# SoftRas's texel lookup, where SoftRas itself flips between two texels (see below).

def _size(image_size):
    return (image_size, image_size) if isinstance(image_size, int) else tuple(image_size)


def _area(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (cx - ax) * (by - ay)


def softras_rasterize(face_vertices, textures, image_size, background_color=(0, 0, 0), near=1,
                      far=100, fill_back=True, eps=1e-3, sigma_val=1e-5, dist_eps=1e-4,
                      gamma_val=1e-4):
    """SoftRas's forward as SPEC §2 writes it — euclidean coverage, prod alpha, softmax colour,
    surface textures of R×R texels — in plain torch (float64, differentiable by autograd).
    ``face_vertices`` [B, F, 3, 3] in screen space, ``textures`` [B, F, R², 3] lit: [B, 4, H, W].
    Each pixel looks only at the faces whose screen box, grown by √T (the cut-off distance),
    holds it: the others are ignored at that pixel (SPEC §2's cut-off)."""
    fv, tex = face_vertices.double(), textures.double()
    batch, nf = fv.shape[:2]
    height, width = _size(image_size)
    s = min(height, width)
    rows, cols = torch.meshgrid(torch.arange(height, dtype=torch.float64),
                                torch.arange(width, dtype=torch.float64), indexing="ij")
    px = ((2 * cols + 1 - width) / s).reshape(1, -1, 1)  # [1, P, 1]
    py = ((2 * (height - 1 - rows) + 1 - height) / s).reshape(1, -1, 1)
    cutoff = sigma_val * math.log(1 / dist_eps - 1)
    grow = math.sqrt(cutoff)
    with torch.no_grad():
        lo, hi = fv[..., :2].amin(2) - grow, fv[..., :2].amax(2) + grow  # [B, F, 2]
        near_box = ((px >= lo[:, None, :, 0]) & (px <= hi[:, None, :, 0])
                    & (py >= lo[:, None, :, 1]) & (py <= hi[:, None, :, 1]))  # [B, P, F]
        count = near_box.sum(-1)
        k = max(int(count.max()), 1)
        order = torch.argsort((~near_box).to(torch.int8), dim=-1, stable=True)[..., :k]
        valid = torch.arange(k) < count[..., None]  # [B, P, K]
    b = torch.arange(batch)[:, None, None]
    f = fv[b, order]  # [B, P, K, 3, 3]
    t = tex[b, order]  # [B, P, K, R², 3]
    x0, x1, x2 = f[..., 0, 0], f[..., 1, 0], f[..., 2, 0]
    y0, y1, y2 = f[..., 0, 1], f[..., 1, 1], f[..., 2, 1]
    det = _area(x0, y0, x1, y1, x2, y2)
    det = torch.where(det.abs() < 1e-10, torch.where(det < 0, -1e-10, 1e-10), det)
    w = torch.stack([_area(px, py, x1, y1, x2, y2), _area(x0, y0, px, py, x2, y2),
                     _area(x0, y0, x1, y1, px, py)], -1) / det[..., None]  # [B, P, K, 3]
    inside = (w > 0).all(-1)
    d2 = None
    for (ax, ay), (bx, by) in (((x0, y0), (x1, y1)), ((x1, y1), (x2, y2)), ((x2, y2), (x0, y0))):
        ex, ey = bx - ax, by - ay
        along = (((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey)).clamp(0, 1)
        e2 = (px - ax - along * ex) ** 2 + (py - ay - along * ey) ** 2
        d2 = e2 if d2 is None else torch.minimum(d2, e2)
    kept = valid & (inside | (d2 < cutoff))
    coverage = torch.where(kept, torch.sigmoid(torch.where(inside, d2, -d2) / sigma_val), 0.0)
    alpha = 1 - torch.prod(1 - coverage, dim=-1)  # [B, P]

    clipped = w.clamp(0, 1)
    clipped = clipped / clipped.sum(-1, keepdim=True).clamp(min=1e-5)
    depth = 1 / (clipped / f[..., 2]).sum(-1)
    front = _area(x0, y0, x1, y1, x2, y2) < 0  # SPEC: (y2 − y0)(x1 − x0) < (y1 − y0)(x2 − x0)
    shown = kept & (depth >= near) & (depth <= far) & (front | fill_back)
    res = round(math.sqrt(tex.shape[2]))
    a = (clipped[..., 0] * res).floor().clamp(max=res - 1)
    c = (clipped[..., 1] * res).floor().clamp(max=res - 1)
    # SoftRas's texel rule, its tie ((w̃0 + w̃1)R − a − b = 1, on the edge w̃2 = 0) sent to the
    # lower texel as the engine sends it (src/raster/reference/color.rs).
    lower = (clipped[..., 0] + clipped[..., 1]) * res - a - c <= 1 + 8 * res * 2.0 ** -52
    index = torch.where(lower, c * res + a, (res - 1 - c) * res + (res - 1 - a)).long()
    colour = torch.gather(t, 3, index[..., None, None].expand(*index.shape, 1, 3))[..., 0, :]
    zbar = (far - depth) / (far - near)
    top = torch.where(shown, zbar, -math.inf).amax(-1, keepdim=True).clamp(min=eps).detach()
    weight = torch.where(shown, coverage * torch.exp((zbar - top) / gamma_val), 0.0)
    back = torch.exp((eps - top) / gamma_val)
    background = torch.tensor(background_color, dtype=torch.float64)
    rgb = ((weight[..., None] * colour).sum(-2) + back * background) / (
        weight.sum(-1, keepdim=True) + back)
    image = torch.cat([rgb, alpha[..., None]], -1)
    return image.reshape(batch, height, width, 4).permute(0, 3, 1, 2)


def softras_render(vertices, faces, textures, eyes, viewing_angle=30.0, anti_aliasing=False,
                   light=None, before_light=None, after_light=None, screen=None, image=None,
                   image_size=24, **raster):
    """SoftRas's ``SoftRenderer`` (surface textures, look_at) as SPEC §1–2 write it: light ×
    textures, look_at(eye) and perspective, then :func:`softras_rasterize`. ``light(normals)``
    replaces the default lights (ambient 0.5 + directional 0.5 from +y, white); the other hooks
    change the textures before or after lighting, the screen-space vertices, or the image."""
    vertices = vertices.double()
    faces = faces.long() if faces.dim() == 3 else faces.long()[None].expand(vertices.shape[0], -1, -1)
    b = torch.arange(vertices.shape[0])[:, None, None]
    corners = vertices[b, faces]  # [B, F, 3, 3]
    normals = F.normalize(torch.cross(corners[:, :, 2] - corners[:, :, 1],
                                      corners[:, :, 0] - corners[:, :, 1], dim=-1), dim=-1)
    lights = (0.5 + 0.5 * normals[..., 1:2].clamp(min=0)) if light is None else light(normals)
    textures = textures.double() if before_light is None else before_light(textures.double())
    lit = textures * lights[:, :, None, :]
    lit = lit if after_light is None else after_light(lit)
    projected = softras_screen(vertices, eyes, viewing_angle)
    projected = projected if screen is None else screen(projected)
    height, wide = _size(image_size)
    factor = 2 if anti_aliasing else 1
    images = softras_rasterize(projected[b, faces], lit, (height * factor, wide * factor), **raster)
    images = F.avg_pool2d(images, 2) if anti_aliasing else images
    return images if image is None else image(images)


def softras_screen(vertices, eyes, viewing_angle=30.0):
    """SPEC §1: look_at(eye, at 0, up +y), then perspective: [B, V, 3] screen x, y and depth."""
    eyes = torch.as_tensor(eyes, dtype=torch.float64).reshape(-1, 3)
    z = F.normalize(-eyes, dim=-1)
    x = F.normalize(torch.cross(torch.tensor([[0.0, 1.0, 0.0]], dtype=torch.float64).expand_as(z),
                                z, dim=-1), dim=-1)
    y = torch.cross(z, x, dim=-1)
    camera = torch.einsum("bvk,bjk->bvj", vertices.double() - eyes[:, None],
                          torch.stack([x, y, z], 1))
    angle = torch.as_tensor(viewing_angle, dtype=torch.float64).reshape(-1, 1)
    width = torch.tan(angle * (math.pi / 180))
    return torch.stack([camera[..., 0] / (camera[..., 2] * width),
                        camera[..., 1] / (camera[..., 2] * width), camera[..., 2]], -1)


def nearest_depth(vertices, faces, eye, size, near=1.0, far=100.0):
    """[B, size, size]: SPEC §2's depth ``1 / Σ w_k / z_k`` of the nearest face each pixel is
    inside (``far`` where none is), both facings, written out in plain torch float64 through
    SPEC §1's look_at and perspective: what ``softvk.torch.render(..., 'depth')`` renders."""
    screen = softras_screen(vertices, eye)
    fv = screen[torch.arange(screen.shape[0])[:, None, None], faces.long()]  # [B, F, 3, 3]
    rows, cols = torch.meshgrid(torch.arange(size, dtype=torch.float64),
                                torch.arange(size, dtype=torch.float64), indexing="ij")
    px = ((2 * cols + 1 - size) / size).reshape(1, -1, 1)
    py = ((2 * (size - 1 - rows) + 1 - size) / size).reshape(1, -1, 1)
    x, y, z = (fv[..., k][:, None] for k in range(3))  # [B, 1, F, 3]
    x0, x1, x2, y0, y1, y2 = x[..., 0], x[..., 1], x[..., 2], y[..., 0], y[..., 1], y[..., 2]
    w = torch.stack([_area(px, py, x1, y1, x2, y2), _area(x0, y0, px, py, x2, y2),
                     _area(x0, y0, x1, y1, px, py)], -1) / _area(x0, y0, x1, y1, x2, y2)[..., None]
    depth = 1 / (w / z).sum(-1)
    seen = ((w >= 0) & (w <= 1)).all(-1) & (depth >= near) & (depth <= far)
    nearest = torch.where(seen, depth, torch.full_like(depth, math.inf)).amin(-1)
    return torch.where(torch.isinf(nearest), torch.full_like(nearest, far), nearest).reshape(
        -1, size, size)


def eyes_from_angles(distance, elevations, azimuths):
    """SPEC §1: ``(d cos(el) sin(az), d sin(el), −d cos(el) cos(az))``, degrees."""
    el, az = np.radians(elevations), np.radians(azimuths)
    return torch.tensor(np.stack([distance * np.cos(el) * np.sin(az), distance * np.sin(el),
                                  -distance * np.cos(el) * np.cos(az)], -1), dtype=torch.float64)


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


# What each change makes of SoftRas's steps, in the reference's terms.
WITH_CHANGE = {
    replace_lighting: dict(after_light=lambda lit: lit * 2),
    replace_transform: dict(screen=lambda v: v + torch.tensor([0.25, 0.0, 0.0], dtype=torch.float64)),
    replace_rasterizer: dict(image=lambda images: images.flip(-1)),
    replace_soft_rasterize: dict(image=lambda images: images * 0.5),
    replace_perspective: dict(screen=lambda v: v * 1.2),
    hook_rasterizer: dict(image=lambda images: 1 - images),
    hook_lighting_before: dict(before_light=lambda textures: textures + 0.5),
    instance_forward: dict(light=lambda normals: torch.ones_like(normals[..., :1])),
    # directional_lighting adds to the light in place and returns it: halving what it returns
    # halves the ambient light too.
    replace_directional: dict(light=lambda n: 0.5 * (0.5 + 0.5 * n[..., 1:2].clamp(min=0))),
}
# look_at_renderer's eyes and settings, for the reference.
EYES = eyes_from_angles(2.7, [20.0, -30.0], [40.0, 200.0])
SHARPNESS = dict(sigma_val=1e-4, gamma_val=1e-3)
# The renderer's float32 paths against the float64 reference: the composed steps' f32 camera
# moves a pixel by 1.6e-5 at most on these scenes (the engine's own camera by 3.9e-6). ATOL
# above holds both with a margin of 6.


@pytest.mark.parametrize("change", list(WITH_CHANGE), ids=lambda f: f.__name__)
def test_a_replaced_step_takes_the_composed_steps(gpu, assets, engine_calls, monkeypatch, change):
    renderer = look_at_renderer()
    vertices, faces, textures = sphere(assets)
    before = renderer.render_mesh(sr.Mesh(vertices, faces, textures)).detach()
    assert len(engine_calls) == 1
    change(renderer, monkeypatch)
    images, expected = render_both(renderer, vertices, faces, textures)
    assert len(engine_calls) == 1, "the engine's path ignored the change"
    assert torch.equal(images, expected)
    # What SoftRas computes with that change, written out in the test.
    softras = softras_render(vertices, faces[0], textures, EYES, **SHARPNESS, **WITH_CHANGE[change])
    np.testing.assert_allclose(images.numpy(), softras.numpy(), atol=ATOL, rtol=0)
    assert (images - before).abs().max() > 0.05, "the change should show in the images"


def test_a_mesh_subclass_or_filled_back_faces_take_the_composed_steps(gpu, assets, engine_calls):
    class Other(sr.Mesh):
        pass

    renderer = look_at_renderer()
    vertices, faces, textures = sphere(assets)
    other = renderer.render_mesh(Other(vertices, faces, textures))
    filled = sr.Mesh(vertices, faces, textures)
    filled.fill_back_()
    doubled = renderer.render_mesh(filled)
    assert engine_calls == []
    # A subclass renders what SoftRas renders of the mesh; filled back faces, what it renders of
    # every face twice (the second time wound the other way, alpha taking both).
    softras = softras_render(vertices, faces[0], textures, EYES, **SHARPNESS)
    np.testing.assert_allclose(other.numpy(), softras.numpy(), atol=ATOL, rtol=0)
    twice = softras_render(vertices, torch.cat([faces[0], faces[0][:, [2, 1, 0]]]),
                           torch.cat([textures, textures], 1), EYES, **SHARPNESS)
    np.testing.assert_allclose(doubled.numpy(), twice.numpy(), atol=ATOL, rtol=0)
    assert (twice - softras)[:, 3].abs().max() > 0.05  # the doubled faces show in alpha


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


def test_mode_is_ignored_and_render_gives_softras_s_alpha_and_depth(gpu, assets, engine_calls):
    """With the engine (test_compat_renderer.py checks the plumbing with a fake): whatever
    ``mode`` says, the renderer returns SoftRas's RGBA; ``softvk.torch.render``'s alpha-only
    path gives its alpha and ``'depth'`` the nearest face's depth, both written out here."""
    renderer = look_at_renderer()
    vertices, faces, textures = sphere(assets)
    mesh = sr.Mesh(vertices, faces, textures)
    softras = softras_render(vertices, faces[0], textures, EYES, **SHARPNESS)
    for mode in (None, "rgb", "silhouettes", "depth", "normals"):
        images = renderer(vertices, faces, textures, mode=mode)
        assert images.shape == (2, 4, 24, 24)
        np.testing.assert_allclose(images.numpy(), softras.numpy(), atol=ATOL, rtol=0)
    silhouettes = st.render(renderer, mesh, "silhouettes")
    np.testing.assert_allclose(silhouettes.numpy(), softras[:, 3].numpy(), atol=ATOL, rtol=0)
    assert len(engine_calls) == 6
    # Measured: 3.9e-6 (images, alpha); 1.6e-6 (depths of 1.8 to 2.6, against nearest_depth).
    depth = st.render(renderer, mesh, "depth")
    want = nearest_depth(vertices, faces, EYES, 24)
    assert 200 < (want < 100).sum() < want.numel()
    np.testing.assert_allclose(depth.numpy(), want.numpy(), atol=5e-6, rtol=0)


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
    # The twin against SoftRas's formulas written out in plain torch, the image and autograd's
    # gradient of it. Measured: 2.2e-16 (image), 1.9e-14 (positions, largest 2.4, 3.3e-13 of a
    # component), 4.4e-16 (texels).
    ref_f, ref_t = (torch.tensor(a, requires_grad=True) for a in (faces, textures))
    softras = softras_rasterize(ref_f, ref_t, **kw)
    torch.testing.assert_close(images, softras, atol=1e-15, rtol=0)
    weights = torch.rand(images.shape, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    (images * weights).sum().backward()
    (softras * weights).sum().backward()
    torch.testing.assert_close(f.grad, ref_f.grad, atol=6e-14, rtol=1e-12)
    torch.testing.assert_close(t.grad, ref_t.grad, atol=2e-15, rtol=1e-12)


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
    # The image and every gradient component against SoftRas's steps written out in plain torch
    # (the renderer's eye as set_eyes_from_angles made it, in float32). Measured: 1.8e-15
    # (image), 1.6e-14 (gradient, largest 2.0; 3.7e-12 of a component above 1e-6).
    ref_v = vertices.clone().requires_grad_(True)
    softras = softras_render(ref_v, faces[0], textures, renderer.transform.transformer._eye,
                             image_size=8, sigma_val=1e-2, gamma_val=1e-1, dist_eps=1e-10)
    torch.testing.assert_close(images.detach(), softras.detach(), atol=6e-15, rtol=0)
    (softras * weights).sum().backward()
    torch.testing.assert_close(v.grad, ref_v.grad, atol=5e-14, rtol=1e-11)


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
    # Against autograd through SoftRas's steps written out in plain torch: measured 1.5e-15 of
    # itself.
    ref_angle = torch.tensor(30.0, dtype=torch.float64, requires_grad=True)
    softras = softras_render(vertices, faces[0], textures, renderer.transform.transformer._eye,
                             viewing_angle=ref_angle, image_size=8, sigma_val=1e-2,
                             gamma_val=1e-1, dist_eps=1e-10)
    (softras * weights).sum().backward()
    assert abs(angle.grad.item() - ref_angle.grad.item()) <= 1e-13 * abs(ref_angle.grad.item())
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
