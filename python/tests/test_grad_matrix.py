"""Gradients of ``soft_rasterize`` in every mode — ``dist_func`` × ``aggr_func_rgb`` ×
``aggr_func_alpha`` × texture type, SoftRas's ``aggr_func_rgb='hard'`` (its demo and
reconstruction) included — against central differences, component by component.

The differences are taken of the f64 twin's forward (``softvk.reference_rasterize``), in double,
so they resolve every component; then

- the float64 path (what ``soft_rasterize`` computes for float64 tensors, the twin's backward)
  must match them to double precision, and
- the float32 path (the GPU's kernels) to float precision,

each component held to ``|got − want| ≤ rel·|want| + floor·scale`` (``scale`` the largest
|want| of its family, positions or colours): above ``floor / rel`` of the largest a component is
held to ``rel`` of itself, below it to the floor.
"""

import itertools

import numpy as np
import pytest
import torch

import softvk
import softvk.torch as st

MODES = list(itertools.product(["euclidean", "barycentric", "hard"], ["softmax", "hard"],
                               ["prod", "sum", "hard"], ["surface", "vertex"]))
SIZE = (10, 13)  # non-square: height, width
H = 1e-6  # the central differences' step (positions and colours are O(1))

# Float64 against the differences. Measured over the 36 modes (this file's scene): the worst
# component is off by 1.8e-8 of its family's largest (barycentric coverage; the differences' own
# truncation, O(h²), and rounding, O(ε/h)), and a component above 1e-3 of the largest by 5.6e-6
# of itself (hard coverage, whose positions move the image only through depth and colour). The
# bars leave a margin of about 9.
DOUBLE = dict(rel=5e-5, floor=2e-7)
# Float32 (the GPU) against the differences: what is left is f32 rounding in the kernels' sums.
# Measured over the 36 modes: a component above 1e-3 of the largest is off by at most 1.3e-4 of
# itself; below that, by 1.4e-6 of the largest with Euclidean or hard coverage (the floor: about
# 12 f32 ulps of the largest, under which a sum of terms as large as the largest cannot resolve
# a component) and 6.4e-6 with barycentric coverage, whose clip of the barycentrics is a kink
# that a pixel near it resolves differently in f32 and f64 (tests/raster_backward.rs, KINKED).
# The bars leave a margin of 3 or more.
SINGLE = dict(rel=1e-3, floor=5e-6)
SINGLE_BARYCENTRIC = dict(rel=1e-3, floor=2e-5)


def scene(seed, texture_type):
    """Four faces over a small non-square image, of mixed sizes and facings, overlapping, depths
    in [2, 5]; surface textures of 2×2 texels or corner colours."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-0.5, 0.5, (1, 4, 1, 2))
    corners = rng.uniform(-0.7, 0.7, (1, 4, 3, 2))
    depth = rng.uniform(2, 5, (1, 4, 3, 1))
    faces = np.concatenate([centres + corners, depth], axis=-1)
    per_face = 4 if texture_type == "surface" else 3
    textures = rng.uniform(0, 1, (1, 4, per_face, 3))
    # The float32 path renders these values: keep them representable in float32.
    return [np.asarray(a, np.float32).astype(np.float64) for a in (faces, textures)]


def settings(dist, rgb, alpha, texture_type):
    # σ and γ wide enough that the differences resolve the coverage and the softmax; dist_eps
    # 1e-10 puts the cut-off's jump far below them.
    return dict(image_size=SIZE, sigma_val=4e-3, gamma_val=5e-2, dist_func=dist,
                aggr_func_rgb=rgb, aggr_func_alpha=alpha, texture_type=texture_type,
                dist_eps=1e-10, background_color=[0.3, 0.2, 0.1])


def central_differences(faces, textures, weights, kw):
    engine = st.rasterize_settings(**kw)

    def loss(f, t):
        return float((softvk.reference_rasterize(f, t, engine) * weights).sum())

    grads = []
    for x in (faces, textures):
        g = np.zeros_like(x)
        for i in np.ndindex(x.shape):
            keep = x[i]
            x[i] = keep + H
            up = loss(faces, textures)
            x[i] = keep - H
            down = loss(faces, textures)
            x[i] = keep
            g[i] = (up - down) / (2 * H)
        grads.append(g)
    return grads


def analytic(faces, textures, weights, kw, dtype):
    f = torch.tensor(faces, dtype=dtype, requires_grad=True)
    t = torch.tensor(textures, dtype=dtype, requires_grad=True)
    image = st.soft_rasterize(f, t, **kw)
    assert image.dtype == dtype
    (image * torch.tensor(weights, dtype=dtype).permute(0, 3, 1, 2)).sum().backward()
    return f.grad.double().numpy(), t.grad.double().numpy()


def worst(got, want, rel, floor):
    """The largest share of its bar any component uses (≤ 1 passes), and where."""
    scale = np.abs(want).max()
    share = np.abs(got - want) / (rel * np.abs(want) + floor * scale)
    i = np.unravel_index(np.argmax(share), share.shape)
    return share[i], f"component {i}: {got[i]:.9g} against {want[i]:.9g} (largest {scale:.3g})"


@pytest.mark.parametrize("dist,rgb,alpha,texture_type", MODES)
def test_gradients_match_central_differences_in_every_mode(gpu, dist, rgb, alpha, texture_type):
    faces, textures = scene(17, texture_type)
    kw = settings(dist, rgb, alpha, texture_type)
    weights = np.random.default_rng(5).uniform(-1, 1, (1, *SIZE, 4))
    fd_faces, fd_textures = central_differences(faces, textures, weights, kw)
    # Every family must depend on its inputs, or the comparison proves nothing: colours always;
    # positions unless nothing soft reaches them (the nearest face's texel, with a hard alpha
    # or coverage: then the gradient must be zero, and is checked so below).
    assert np.abs(fd_textures).max() > 0.1
    if not (rgb == "hard" and texture_type == "surface" and "hard" in (alpha, dist)):
        assert np.abs(fd_faces).max() > 0.01

    single = SINGLE_BARYCENTRIC if dist == "barycentric" else SINGLE
    for dtype, bars in ((torch.float64, DOUBLE), (torch.float32, single)):
        got_faces, got_textures = analytic(faces, textures, weights, kw, dtype)
        for name, got, want in (("positions", got_faces, fd_faces),
                                ("colours", got_textures, fd_textures)):
            if np.abs(want).max() == 0:
                assert np.abs(got).max() == 0, (dtype, name)
                continue
            share, where = worst(got, want, **bars)
            assert share <= 1, f"{dtype} {name}: {where}"
