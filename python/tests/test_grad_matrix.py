"""Gradients of ``soft_rasterize`` in every mode — ``dist_func`` × ``aggr_func_rgb`` ×
``aggr_func_alpha`` × texture type, SoftRas's ``aggr_func_rgb='hard'`` (its demo and
reconstruction) included — component by component, at two sharpnesses and on a real mesh:

- **wide** (σ 4e-3, γ 5e-2): four faces over a 10×13 image, where every pixel near an edge is
  well inside the soft band;
- **sharp**, SoftRas's defaults (σ 1e-5, γ 1e-4): the same four faces over 16×21, every mode;
- **spot** at SoftRas's defaults: the 5856-face cow over 32×32, in SoftRas's default mode and
  with its ``aggr_func_rgb='hard'``.

What the gradients are held against:

- On the four faces, central differences of the f64 twin's forward
  (``softvk.reference_rasterize``) in double, every component; the float64 path (what
  ``soft_rasterize`` computes for float64 tensors, the twin's backward) and the float32 path (the
  GPU's kernels) are both held against them.
- The differences' step: 1e-6 at σ 4e-3. At σ 1e-5 the coverage ``sigmoid(±d²/σ)`` goes from 0
  to 1 within about 0.01 of an edge, a band 20 times narrower than at σ 4e-3, and each
  derivative in a vertex brings a factor of that: the third, which sets the differences'
  truncation error h²·f'''/6, is some 8000 times larger. At a step of 1e-6 the positions'
  differences are then off by up to 2e-4 (of 130, barycentric coverage, whose ``min(w)`` moves
  fastest; 1.2e-3 of 273 over 10×13), 2.7e-6 of a component. At 1e-7 the truncation is below the
  rounding, about ε·|loss|/h: the f64 backward agrees with the differences to 1.3e-7 of a
  component with a floor of 3.6e-7. Smaller steps make it worse (3e-8: 7.7e-7; 1.3e-6). The
  image is linear in the colours (texels, or corner colours): their differences have no
  truncation error at all, and take a step of 1e-4 there, which keeps their rounding down.
- On spot the differences of every component would take ~250 000 renders: they are taken for a
  sample (the largest components, random non-zero ones and zero ones), against the float64 path;
  the float32 path is held against the float64 path's gradient on **every** component. That is
  a second implementation (the CPU twin's backward, in double) checked against the differences
  here and in tests/raster_backward.rs, not the kernels checked against themselves.

Each component is held to ``|got − want| ≤ rel·|want| + floor``, ``floor`` an absolute error
measured near zero. How each bar below was measured: ``rel`` is the worst relative error of the
components at or above 1e-2 of their family's largest, then ``floor`` the smallest absolute
floor with which every component passes at that ``rel``; both are set at about 3 times that.
"""

import itertools

import numpy as np
import pytest
import torch

import softvk
import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf
import softvk.torch as st

MODES = list(itertools.product(["euclidean", "barycentric", "hard"], ["softmax", "hard"],
                               ["prod", "sum", "hard"], ["surface", "vertex"]))
WIDE = dict(size=(10, 13), sigma_val=4e-3, gamma_val=5e-2, step=1e-6)  # non-square: H, W
SHARP = dict(size=(16, 21), sigma_val=1e-5, gamma_val=1e-4, step=(1e-7, 1e-4))  # SoftRas's σ, γ

# Bars per (sharpness, dtype, family), ``barycentric`` coverage's f32 positions apart. Measured
# over the 36 modes of this file's scene, against the differences (the figures: rel; floor):
#
# wide, f64: positions 4.4e-8 (barycentric, sum) of a component; 2.2e-9. Colours 1.1e-8;
#   8.1e-10. What is left is the differences' own truncation and rounding.
# wide, f32: positions 5.6e-5 (euclidean); 2.8e-6. Barycentric 3e-5; 1.3e-5: its clip of the
#   barycentrics is a kink that a pixel near it resolves differently in f32 and f64
#   (tests/raster_backward.rs, KINKED). Colours 8.9e-6; 2.8e-7.
# sharp, f64: positions 1.3e-7; 3.6e-7 (euclidean, softmax colour, hard alpha: the differences'
#   rounding, 2.8e-6 of a 0.13 component). Colours (step 1e-4) 1.4e-10; 4.6e-12.
# sharp, f32: positions 2.9e-3 (euclidean, hard colour, prod: a component 1/16 of its pixel's
#   largest); 1.1e-4 (euclidean, softmax colour, hard alpha, a component that is 1e-13 in
#   f64). Both are f32's resolution of a pixel's offset from an edge: about 6e-8 (an ulp of
#   the coordinates), which σ 1e-5 turns into 6e-8 · 2/σ · D(1 − D) ≈ 3e-3 of gradient per
#   pixel term, whatever the size of the component it lands on. Barycentric 5.7e-5; 1.3e-4.
#   Colours 2.3e-5; 1.8e-7.
BARS = {
    ("wide", torch.float64, "positions"): dict(rel=1.5e-7, floor=7e-9),
    ("wide", torch.float64, "colours"): dict(rel=4e-8, floor=2.5e-9),
    ("wide", torch.float32, "positions"): dict(rel=1.7e-4, floor=9e-6),
    ("wide", torch.float32, "positions", "barycentric"): dict(rel=1e-4, floor=4e-5),
    ("wide", torch.float32, "colours"): dict(rel=3e-5, floor=9e-7),
    ("sharp", torch.float64, "positions"): dict(rel=4e-7, floor=1.1e-6),
    ("sharp", torch.float64, "colours"): dict(rel=4e-10, floor=1.4e-11),
    ("sharp", torch.float32, "positions"): dict(rel=9e-3, floor=3.3e-4),
    ("sharp", torch.float32, "positions", "barycentric"): dict(rel=1.7e-4, floor=4e-4),
    ("sharp", torch.float32, "colours"): dict(rel=7e-5, floor=5.4e-7),
}


def bars(sharpness, dtype, family, dist):
    return BARS.get((sharpness, dtype, family, dist), BARS[(sharpness, dtype, family)])


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
    return [f32(a) for a in (faces, textures)]


def f32(a):
    # The float32 path renders these values: keep them representable in float32.
    return np.asarray(a, np.float32).astype(np.float64)


def settings(dist, rgb, alpha, texture_type, size, sigma_val, gamma_val, step=None):
    # dist_eps 1e-10 puts the cut-off's jump (of dist_eps in the coverage) far below the
    # differences' resolution.
    return dict(image_size=size, sigma_val=sigma_val, gamma_val=gamma_val, dist_func=dist,
                aggr_func_rgb=rgb, aggr_func_alpha=alpha, texture_type=texture_type,
                dist_eps=1e-10, background_color=[0.3, 0.2, 0.1])


def central_differences(faces, textures, weights, kw, step, picks=None):
    """d(Σ weights · image)/d(each component), the image the twin's, in double; of the
    components ``picks`` (family, index) alone when given. ``step``: one for both families, or
    (positions, colours)."""
    engine = st.rasterize_settings(**kw)
    inputs = (faces, textures)
    steps = step if isinstance(step, tuple) else (step, step)

    def difference(family, i):
        x, h = inputs[family], steps[family]
        keep = x[i]
        x[i] = keep + h
        up = float((softvk.reference_rasterize(faces, textures, engine) * weights).sum())
        x[i] = keep - h
        down = float((softvk.reference_rasterize(faces, textures, engine) * weights).sum())
        x[i] = keep
        return (up - down) / (2 * h)

    if picks is not None:
        return np.array([difference(family, i) for family, i in picks])
    grads = []
    for family, x in enumerate(inputs):
        g = np.zeros_like(x)
        for i in np.ndindex(x.shape):
            g[i] = difference(family, i)
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
    share = np.abs(got - want) / (rel * np.abs(want) + floor)
    i = np.unravel_index(np.argmax(share), share.shape)
    return share[i], (f"component {i}: {got[i]:.9g} against {want[i]:.9g} "
                      f"(largest {np.abs(want).max():.3g})")


@pytest.mark.parametrize("sharpness", ["wide", "sharp"])
@pytest.mark.parametrize("dist,rgb,alpha,texture_type", MODES)
def test_gradients_match_central_differences_in_every_mode(gpu, dist, rgb, alpha, texture_type,
                                                           sharpness):
    config = WIDE if sharpness == "wide" else SHARP
    faces, textures = scene(17, texture_type)
    kw = settings(dist, rgb, alpha, texture_type, **config)
    weights = np.random.default_rng(5).uniform(-1, 1, (1, *config["size"], 4))
    fd_faces, fd_textures = central_differences(faces, textures, weights, kw, config["step"])
    # Every family must depend on its inputs, or the comparison proves nothing: colours always;
    # positions unless nothing soft reaches them (the nearest face's texel with a hard alpha or
    # coverage: then the gradient must be exactly zero, and is checked so below), or, at γ 1e-4,
    # a hard coverage reaches them only through the depth softmax's e^(−Δz̄/γ), below double's
    # resolution of the image (the float64 backward gives 2.3e-11 there, held to the floor).
    assert np.abs(fd_textures).max() > 0.1
    unreached = rgb == "hard" and texture_type == "surface" and "hard" in (alpha, dist)
    if not (unreached or (sharpness == "sharp" and dist == "hard" and texture_type == "surface")):
        assert np.abs(fd_faces).max() > 0.01

    for dtype in (torch.float64, torch.float32):
        got_faces, got_textures = analytic(faces, textures, weights, kw, dtype)
        if unreached:
            assert np.abs(got_faces).max() == 0 and np.abs(fd_faces).max() == 0, dtype
        for name, got, want in (("positions", got_faces, fd_faces),
                                ("colours", got_textures, fd_textures)):
            share, where = worst(got, want, **bars(sharpness, dtype, name, dist))
            assert share <= 1, f"{dtype} {name}: {where}"


# --- spot --------------------------------------------------------------------------------------

# Colours at a step of 1e-4, as at "sharp" (their rounding at 1e-7 was 1.7e-8 here).
SPOT = dict(size=(32, 32), sigma_val=1e-5, gamma_val=1e-4, step=(1e-7, 1e-4))
SPOT_MODES = [("euclidean", "softmax", "prod", "surface"),  # SoftRas's default
              ("euclidean", "hard", "prod", "surface")]  # its demo's and reconstruction's
# Measured (rel; floor), over both modes. f64 against the differences, on this sample and on a
# larger one (100 largest, 500 random non-zero, 50 zero components per family): positions
# 1.3e-7; 4.3e-8 (the differences' rounding), colours 5.9e-10; 1.5e-11. f32 against f64, every
# component: positions 1.7e-4 (hard colour); 2.8e-4 (f32's offsets from edges, as at "sharp"
# above), colours 7.5e-5; 1.4e-10. The bars are 3 times these.
SPOT_BARS = {
    (torch.float64, "positions"): dict(rel=4e-7, floor=1.3e-7),
    (torch.float64, "colours"): dict(rel=2e-9, floor=5e-11),
    (torch.float32, "positions"): dict(rel=5e-4, floor=9e-4),
    (torch.float32, "colours"): dict(rel=2.3e-4, floor=5e-10),
}


def spot_scene(assets):
    """spot in screen space, seen from above one side (SoftRas's look_at and perspective, in
    double, rounded to float32), with 2×2 texels read from its texture."""
    mesh = sr.Mesh.from_obj(str(assets / "spot_triangulated.obj"), load_texture=True,
                            texture_res=2)
    eye = srf.get_points_from_angles(2.732, 25.0, 60.0)
    screen = srf.perspective(srf.look_at(mesh.vertices.double(), eye), 30.0)
    faces = srf.face_vertices(screen, mesh.faces)
    return f32(faces.numpy()), f32(mesh.textures.double().numpy())


def sample(grads, rng, largest=16, nonzero=16, zero=4):
    """Components of each family for the differences: the largest, random non-zero ones (most
    of them small: the floor's regime) and zero ones."""
    picks = []
    for family, g in enumerate(grads):
        size = np.abs(g).ravel()
        chosen = list(np.argsort(-size)[:largest])
        rest = np.setdiff1d(np.flatnonzero(size > 0), chosen)
        chosen += list(rng.choice(rest, min(nonzero, rest.size), replace=False))
        chosen += list(rng.choice(np.flatnonzero(size == 0), zero, replace=False))
        picks += [(family, np.unravel_index(j, g.shape)) for j in chosen]
    return picks


def spot_gradients(assets, mode):
    faces, textures = spot_scene(assets)
    kw = settings(*mode, **SPOT)
    weights = np.random.default_rng(5).uniform(-1, 1, (1, *SPOT["size"], 4))
    double = analytic(faces, textures, weights, kw, torch.float64)
    single = analytic(faces, textures, weights, kw, torch.float32)
    picks = sample(double, np.random.default_rng(0))
    differences = central_differences(faces, textures, weights, kw, SPOT["step"], picks)
    return double, single, picks, differences


@pytest.mark.parametrize("mode", SPOT_MODES, ids="-".join)
def test_gradients_on_spot_at_softras_sharpness(gpu, assets, mode):
    double, single, picks, differences = spot_gradients(assets, mode)
    for family, name in enumerate(("positions", "colours")):
        # Enough of each family takes part for the comparison to mean something.
        assert (np.abs(double[family]) > 1e-3 * np.abs(double[family]).max()).sum() > 300
        rows = [k for k, (f, _) in enumerate(picks) if f == family]
        got = np.array([double[family][picks[k][1]] for k in rows])
        share, where = worst(got, differences[rows], **SPOT_BARS[(torch.float64, name)])
        assert share <= 1, f"float64 {name}, sample {where}"
        share, where = worst(single[family], double[family], **SPOT_BARS[(torch.float32, name)])
        assert share <= 1, f"float32 {name} against float64: {where}"
