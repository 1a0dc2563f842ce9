"""softvk.nvdiffrast.torch's ``texture`` with ``boundary_mode='cube'`` and
``texture_construct_mip(cube_mode=True)`` against a reference written here in float64 torch
operations, whose autograd gives the reference gradients: OpenGL's face table, the face's
coordinates, ``uv_da`` carried onto the face through the projection's Jacobian (so the direction
takes the level's gradient too), and 2D filtering of the face with this folder's 2D reference.

The reference filters within a face, so the directions here stay away from the face edges by
more than a tap on every level used (the seamless taps across edges and corners are held to
softvk's f64 twin in ``tests/hard_texture_cube.rs``); they are exact in float32 (a major
component of a power of two, the others on a grid), so both take the same faces, texels and
fractions. Lookups within 1e-4 of an integer mip level are left out of the comparison.
"""

import pytest
import torch

import softvk.nvdiffrast.torch as dr
from test_nvdiffrast_texture import compare, gather, leaf, ref_bilinear, ref_level, ref_pyramid

FILTERS = ["nearest", "linear", "linear-mipmap-nearest", "linear-mipmap-linear"]

# For face f: (major axis, the axes and signs of the numerators of s and t).
FACES = [
    (0, (2, -1.0), (1, -1.0)),
    (0, (2, 1.0), (1, -1.0)),
    (1, (0, 1.0), (2, 1.0)),
    (1, (0, 1.0), (2, -1.0)),
    (2, (0, 1.0), (1, -1.0)),
    (2, (0, -1.0), (1, -1.0)),
]


def ref_face(d):
    """The face of each direction [..., 3] (OpenGL's table; ties to x, then y), long."""
    a = d.detach().abs()
    major = torch.where(a[..., 2] > torch.maximum(a[..., 0], a[..., 1]), 2,
                        torch.where(a[..., 1] > a[..., 0], 1, 0))
    negative = torch.gather(d.detach(), -1, major[..., None])[..., 0] < 0
    return 2 * major + negative.long()


def ref_coords(d, face):
    """(s, t) of each direction on its face, differentiable."""
    s = torch.zeros(d.shape[:-1], dtype=d.dtype)
    t = torch.zeros_like(s)
    for f, (major, (sa, ss), (ta, ts)) in enumerate(FACES):
        on = face == f
        m = d[..., major].abs()
        s = torch.where(on, ss * d[..., sa] / (2 * m) + 0.5, s)
        t = torch.where(on, ts * d[..., ta] / (2 * m) + 0.5, t)
    return s, t


def ref_face_derivatives(d, da, face):
    """uv_da (dx/dX, dx/dY, dy/dX, dy/dY, dz/dX, dz/dY) on the face: (ds/dX, ds/dY, dt/dX,
    dt/dY), through the projection's Jacobian (differentiable in d and da)."""
    dx = da[..., 0::2]
    dy = da[..., 1::2]
    # The Jacobian written out: s = 1/2 + k a / m, k = ±1/2 signed by m.
    def directional(v):
        s, t = torch.zeros(d.shape[:-1], dtype=d.dtype), torch.zeros(d.shape[:-1], dtype=d.dtype)
        for f, (major, (sa, ss), (ta, ts)) in enumerate(FACES):
            on = face == f
            m = d[..., major]
            sign = torch.where(m < 0, -1.0, 1.0).to(d.dtype)
            for (axis, k0), out in (((sa, ss), "s"), ((ta, ts), "t")):
                k = 0.5 * k0 * sign
                value = k / m * v[..., axis] - k * d[..., axis] / (m * m) * v[..., major]
                if out == "s":
                    s = torch.where(on, value, s)
                else:
                    t = torch.where(on, value, t)
        return s, t

    s_x, t_x = directional(dx)
    s_y, t_y = directional(dy)
    return torch.stack([s_x, s_y, t_x, t_y], -1)


def ref_cube(tex, d, da, bias, filter_mode, max_mip_level=None):
    """The reference of ``texture(..., boundary_mode='cube')`` for lookups inside a face."""
    b, hh, ww, _ = d.shape
    n, _, size, _, c = tex.shape
    faces = tex.reshape(n * 6, size, size, c)
    face = ref_face(d)
    cube = torch.arange(b).view(b, 1, 1).expand(b, hh, ww) if n > 1 else torch.zeros(
        b, hh, ww, dtype=torch.long)
    item = cube * 6 + face
    s, t = ref_coords(d, face)
    if filter_mode == "nearest":
        x = torch.floor(s * size).long().clamp(0, size - 1)
        y = torch.floor(t * size).long().clamp(0, size - 1)
        return gather(faces, item, x, y)
    if filter_mode == "linear":
        return ref_bilinear(faces, item, s, t, "clamp")
    count = 1
    while (max_mip_level is None or count - 1 < max_mip_level) and size >> (count - 1) > 1:
        count += 1
    stack = ref_pyramid(faces, count)
    top = len(stack) - 1
    face_da = None if da is None else ref_face_derivatives(d, da, face)
    lam = ref_level(face_da, bias, size, size)
    lam = torch.as_tensor(lam, dtype=torch.float64).expand(b, hh, ww).clamp(0, top)
    l0 = torch.floor(lam.detach()).long()
    frac = (lam - l0).unsqueeze(-1) if filter_mode == "linear-mipmap-linear" else None
    out = torch.zeros(b, hh, ww, c, dtype=torch.float64)
    for k in range(len(stack)):
        at = ref_bilinear(stack[k], item, s, t, "clamp")
        on = (l0 == k).unsqueeze(-1)
        if frac is None:
            out = out + at * on
        else:
            above = ref_bilinear(stack[min(k + 1, top)], item, s, t, "clamp")
            out = out + (at + frac * (above - at)) * on
    return out


def cube_case(seed, cubes, size, channels, batch=2, grid=(6, 7), uv_da=True, bias=True):
    """A cube map and directions inside its faces: s, t in [0.2, 0.8] on a grid of 1/4096, the
    major component ±2^k."""
    g = torch.Generator().manual_seed(seed)
    hh, ww = grid
    tex = torch.rand(cubes, 6, size, size, channels, generator=g) * 2 - 1
    face = torch.randint(0, 6, (batch, hh, ww), generator=g)
    st = torch.round((torch.rand(batch, hh, ww, 2, generator=g) * 0.6 + 0.2) * 4096) / 4096
    a, bb = 2 * st[..., 0] - 1, 2 * st[..., 1] - 1
    one = torch.ones_like(a)
    table = [(one, -bb, -a), (-one, -bb, a), (a, one, bb), (a, -one, -bb), (a, -bb, one),
             (-a, -bb, -one)]
    d = torch.zeros(batch, hh, ww, 3)
    for f, comps in enumerate(table):
        d = torch.where((face == f)[..., None], torch.stack(comps, -1), d)
    d = d * 2.0 ** torch.randint(-1, 3, (batch, hh, ww, 1), generator=g).float()
    da = None
    if uv_da:
        m = d.abs().amax(-1, keepdim=True)
        scale = 2 * m * 2.0 ** (torch.rand(batch, hh, ww, 1, generator=g) * 5 - 3.5) / size
        da = (torch.rand(batch, hh, ww, 6, generator=g) * 2 - 1) * scale
    mb = torch.rand(batch, hh, ww, generator=g) * 4 - 1 if bias else None
    dy = torch.rand(batch, hh, ww, channels, generator=g) * 2 - 1
    return tex, d, da, mb, dy


def far_from_integer_levels(tex, d, da, bias, filter_mode):
    if "mipmap" not in filter_mode:
        return None
    size = tex.shape[2]
    dd = d.double()
    face_da = None if da is None else ref_face_derivatives(dd, da.double(), ref_face(dd))
    lam = ref_level(face_da, None if bias is None else bias.double(), size, size)
    lam = torch.as_tensor(lam, dtype=torch.float64).expand(d.shape[:3])
    return (lam - torch.round(lam)).abs() >= 1e-4


@pytest.mark.parametrize("filter_mode", FILTERS)
@pytest.mark.parametrize("shape", [(1, 16, 3), (2, 8, 1)])
def test_cube_texture_and_its_gradients_match_the_reference(gpu, filter_mode, shape):
    mips = "mipmap" in filter_mode
    cubes, size, channels = shape
    max_mip_level = 2 if size == 16 else 1  # the coarsest level used stays 4 texels across
    for inputs in ([(True, False), (False, True), (True, True)] if mips else [(False, False)]):
        tex, d, da, mb, dy = cube_case(11, cubes, size, channels, uv_da=inputs[0],
                                       bias=inputs[1])
        args = dict(filter_mode=filter_mode, boundary_mode="cube", max_mip_level=max_mip_level)
        got_in = [leaf(t) for t in (tex, d, da, mb)]
        got = dr.texture(*got_in[:2], uv_da=got_in[2], mip_level_bias=got_in[3], **args)
        want_in = [leaf(t, torch.float64) for t in (tex, d, da, mb)]
        want = ref_cube(*want_in, filter_mode, max_mip_level=max_mip_level)
        mask = far_from_integer_levels(tex, d, da, mb, filter_mode)
        what = f"cube {filter_mode} {list(shape)} {inputs}"
        compare(f"{what} out", got, want, mask, 1e-5, 1e-6)
        if mask is not None:
            dy = dy * mask[..., None]
        (got * dy).sum().backward()
        (want * dy.double()).sum().backward()
        for name, g, w in zip(["tex", "uv", "uv_da", "mip_level_bias"], got_in, want_in):
            if g is None:
                continue
            w_grad = w.grad if w.grad is not None else torch.zeros_like(w)
            g_grad = g.grad if g.grad is not None else torch.zeros_like(g)
            compare(f"{what} d/d{name}", g_grad, w_grad, None, 1e-4, 1e-5)


def test_a_prebuilt_cube_stack_gives_what_one_built_in_the_call_gives(gpu):
    tex, d, da, mb, dy = cube_case(3, 1, 8, 3)
    a, b = leaf(tex), leaf(tex)
    mip = dr.texture_construct_mip(b, cube_mode=True)
    assert mip.texture_shape == [1, 6, 8, 8, 3] and mip.max_mip_level == 3 and mip.cube_mode
    built = dr.texture(a, d, da, mb, boundary_mode="cube")
    prebuilt = dr.texture(b, d, da, mb, mip=mip, boundary_mode="cube")
    assert torch.equal(built, prebuilt)
    (built * dy).sum().backward()
    (prebuilt * dy).sum().backward()
    assert torch.equal(a.grad, b.grad)
    # A custom stack of cube levels, each [1, 6, s, s, 3], takes its own gradients.
    levels = [leaf(torch.rand(1, 6, 8 >> k, 8 >> k, 3)) for k in (1, 2, 3)]
    out = dr.texture(tex, d, da, mb, mip=levels, boundary_mode="cube")
    (out * dy).sum().backward()
    assert all(lv.grad is not None and lv.grad.shape == lv.shape for lv in levels)
    with pytest.raises(ValueError, match="cube_mode"):
        dr.texture(tex, d, da, mb, mip=dr.texture_construct_mip(tex[:, 0]), boundary_mode="cube")
    with pytest.raises(ValueError, match="cube_mode"):
        dr.texture(tex[:, 0], d[..., :2].contiguous(), da[..., :4].contiguous(), mip=mip)


def test_every_bad_cube_input_raises_one_clear_error(gpu):
    tex, d, da, mb, _ = cube_case(6, 1, 8, 3)

    def raises(kind, match, *args, **kwargs):
        with pytest.raises(kind, match=match):
            dr.texture(*args, boundary_mode="cube", **kwargs)

    raises(ValueError, "tex", tex[:, :5], d)
    raises(ValueError, "tex", tex[0], d)
    raises(ValueError, "square", torch.rand(1, 6, 8, 4, 3), d)
    raises(ValueError, "uv", tex, d[..., :2])
    raises(ValueError, "uv_da", tex, d, da[..., :4])
    raises(ValueError, "minibatch", torch.rand(3, 6, 8, 8, 3), d)
    raises(ValueError, "odd extent", torch.rand(1, 6, 6, 6, 3), d, da)
    with pytest.raises(ValueError, match="tex"):
        dr.texture_construct_mip(torch.rand(1, 8, 8, 3), cube_mode=True)
