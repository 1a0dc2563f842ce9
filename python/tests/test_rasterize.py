"""softvk.torch.soft_rasterize: SoftRas's operation on the engine, against the f64 CPU twin and
central finite differences of it."""

import itertools

import numpy as np
import pytest
import torch

import softvk
import softvk.torch as st


def random_faces(seed, batch=2, faces=6, size=0.8):
    """Faces scattered over the screen, a mix of sizes and facings, depths in [2, 5]."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-0.7, 0.7, (batch, faces, 1, 2))
    corners = rng.uniform(-size, size, (batch, faces, 3, 2)) * rng.uniform(0.3, 1, (batch, faces, 1, 1))
    depth = rng.uniform(2, 5, (batch, faces, 3, 1))
    return np.concatenate([centres + corners, depth], axis=-1)


def random_textures(seed, batch, faces, texture_type, res=2):
    rng = np.random.default_rng(seed + 1000)
    per_face = res * res if texture_type == "surface" else 3
    return rng.uniform(0, 1, (batch, faces, per_face, 3))


def render(fv, tex, **kw):
    fv = torch.tensor(fv, dtype=torch.float32)
    tex = torch.tensor(tex, dtype=torch.float32)
    return st.soft_rasterize(fv, tex, **kw)


def twin(fv, tex, image_size=16, **kw):
    names = {
        "sigma_val": "sigma",
        "gamma_val": "gamma",
        "background_color": "background_color",
    }
    settings = softvk.Settings(
        image_size, image_size, **{names.get(k, k): (tuple(v) if isinstance(v, list) else v) for k, v in kw.items()}
    )
    return softvk.reference_rasterize(np.asarray(fv, np.float64), np.asarray(tex, np.float64), settings).transpose(0, 3, 1, 2)


def f32(a):
    """The values the GPU renders: ``a`` rounded to float32 (kept in float64)."""
    return np.asarray(a, np.float32).astype(np.float64)


MODES = list(
    itertools.product(
        ["euclidean", "barycentric", "hard"],
        ["softmax", "hard"],
        ["prod", "sum", "hard"],
        ["surface", "vertex"],
    )
)


@pytest.mark.parametrize("dist,rgb,alpha,texture_type", MODES)
def test_forward_matches_the_f64_twin_in_every_mode(gpu, dist, rgb, alpha, texture_type):
    fv = f32(random_faces(7))
    tex = f32(random_textures(7, 2, 6, texture_type))
    kw = dict(
        sigma_val=2e-3,
        gamma_val=3e-2,
        dist_func=dist,
        aggr_func_rgb=rgb,
        aggr_func_alpha=alpha,
        texture_type=texture_type,
        background_color=[0.2, 0.4, 0.6],
    )
    image = render(fv, tex, image_size=16, **kw)
    assert image.shape == (2, 4, 16, 16) and image.dtype == torch.float32
    expected = twin(fv, tex, 16, **kw)
    # Every mode must draw something, or the comparison proves nothing.
    assert (expected[:, 3] > 0.1).sum() > 10
    np.testing.assert_allclose(image.numpy(), expected, atol=1e-4, rtol=0)


def test_forward_keeps_the_input_dtype_and_takes_a_height_width_pair(gpu):
    fv, tex = random_faces(3, batch=1), random_textures(3, 1, 6, "surface", res=1)
    image = st.soft_rasterize(torch.tensor(fv), torch.tensor(tex), image_size=(12, 20), sigma_val=1e-3)
    assert image.shape == (1, 4, 12, 20) and image.dtype == torch.float64


def test_dist_eps_sets_how_far_a_face_reaches(gpu):
    # One face; the pixel column left of it lies at a distance where the coverage is about 1e-6:
    # ignored at SoftRas's default ε_d = 1e-4, counted at its reconstruction's 1e-10.
    fv = np.array([[[[0.0, -0.9, 2.0], [0.9, -0.9, 2.0], [0.0, 0.9, 2.0]]]])
    tex = np.ones((1, 1, 1, 3))
    kw = dict(image_size=16, sigma_val=1e-3)
    default = render(fv, tex, **kw)[0, 3].numpy()
    wide = render(fv, tex, dist_eps=1e-10, **kw)[0, 3].numpy()
    reach = (wide > 0) & (default == 0)
    assert reach.sum() >= 4, reach
    np.testing.assert_allclose(wide, twin(fv, tex, dist_eps=1e-10, sigma_val=1e-3)[0, 3], atol=1e-6)


def loss_weights(seed, shape):
    return np.random.default_rng(seed).uniform(-1, 1, shape)


def forward_backward(fv, tex, weights, **kw):
    fv_t = torch.tensor(fv, dtype=torch.float32, requires_grad=True)
    tex_t = torch.tensor(tex, dtype=torch.float32, requires_grad=True)
    image = st.soft_rasterize(fv_t, tex_t, **kw)
    (image * weights).sum().backward()
    return image.detach(), fv_t.grad, tex_t.grad


def test_reruns_are_bit_identical(gpu):
    fv, tex = random_faces(21, faces=40, size=0.5), random_textures(21, 2, 40, "surface", res=3)
    weights = torch.tensor(loss_weights(2, (2, 4, 32, 32)), dtype=torch.float32)
    kw = dict(image_size=32, sigma_val=1e-3, gamma_val=1e-2)
    first = forward_backward(fv, tex, weights, **kw)
    # The second render reuses the first's scene (a spare); the third makes a new one.
    for release in (False, True):
        if release:
            softvk.release_cached_scenes()
        again = forward_backward(fv, tex, weights, **kw)
        for a, b in zip(first, again):
            assert torch.equal(a, b)


def test_only_the_gradients_asked_for_are_returned(gpu):
    fv, tex = random_faces(4), random_textures(4, 2, 6, "surface")
    weights = torch.tensor(loss_weights(3, (2, 4, 16, 16)), dtype=torch.float32)
    kw = dict(image_size=16, sigma_val=1e-3)
    _, full_v, full_t = forward_backward(fv, tex, weights, **kw)

    fv_t = torch.tensor(fv, dtype=torch.float32, requires_grad=True)
    tex_t = torch.tensor(tex, dtype=torch.float32)
    image = st.soft_rasterize(fv_t, tex_t, **kw)
    (image * weights).sum().backward()
    assert tex_t.grad is None and torch.equal(fv_t.grad, full_v)

    fv_t = torch.tensor(fv, dtype=torch.float32)
    tex_t = torch.tensor(tex, dtype=torch.float32, requires_grad=True)
    image = st.soft_rasterize(fv_t, tex_t, **kw)
    (image * weights).sum().backward()
    assert fv_t.grad is None and torch.equal(tex_t.grad, full_t)

    # Nothing asked: no graph at all.
    image = st.soft_rasterize(torch.tensor(fv), torch.tensor(tex), **kw)
    assert image.grad_fn is None


def test_the_backward_returns_none_for_inputs_that_need_no_gradient(gpu):
    fv = torch.tensor(random_faces(4), dtype=torch.float32, requires_grad=True)
    tex = torch.tensor(random_textures(4, 2, 6, "surface"), dtype=torch.float32)
    image = st.soft_rasterize(fv, tex, image_size=16, sigma_val=1e-3)
    grads = image.grad_fn.apply(torch.ones_like(image))
    assert grads[0] is not None and grads[1] is None and grads[2] is None


def test_a_silhouette_loss_takes_the_alpha_only_backward_with_the_same_bits(gpu):
    fv, tex = random_faces(9), random_textures(9, 2, 6, "surface")
    fv_t = torch.tensor(fv, dtype=torch.float32, requires_grad=True)
    image = st.soft_rasterize(fv_t, torch.tensor(tex, dtype=torch.float32), image_size=16, sigma_val=1e-3)
    upstream = torch.zeros_like(image)
    upstream[:, 3] = torch.tensor(loss_weights(8, (2, 16, 16)), dtype=torch.float32)
    image.backward(upstream)
    raster = image.grad_fn.raster
    host = np.ascontiguousarray(upstream.permute(0, 2, 3, 1).numpy())
    alpha_only = raster.backward(host, True)
    full = raster.backward(host, False)
    assert torch.equal(fv_t.grad, torch.from_numpy(alpha_only[0]))
    np.testing.assert_array_equal(alpha_only[0], full[0])
    assert np.abs(full[0]).max() > 0


def test_bad_input_is_one_clear_exception(gpu):
    fv = torch.tensor(random_faces(1), dtype=torch.float32)
    tex = torch.ones(2, 6, 1, 3)
    with pytest.raises(ValueError, match="face_vertices has shape"):
        st.soft_rasterize(fv[..., :2], tex)
    with pytest.raises(ValueError, match="R² texels"):
        st.soft_rasterize(fv, torch.ones(2, 6, 3, 3))
    with pytest.raises(ValueError, match="dist_func must be one of"):
        st.soft_rasterize(fv, tex, dist_func="manhattan")
    bad = fv.clone()
    bad[0, 0, 0, 0] = float("nan")
    with pytest.raises(ValueError, match="finite"):
        st.soft_rasterize(bad, tex)
    with pytest.raises(ValueError, match="sigma"):
        st.soft_rasterize(fv, tex, sigma_val=-1.0)
