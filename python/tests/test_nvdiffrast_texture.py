"""softvk.nvdiffrast.torch's ``texture`` and ``texture_construct_mip`` against a reference
written here in float64 torch operations (gathers, its own mip pyramid, nvdiffrast's level of
detail), whose autograd gives the reference gradients: every filter mode x boundary mode, a
shared texture and one per minibatch item, sizes that are not powers of two, ``uv_da`` and
``mip_level_bias``, a prebuilt stack and a custom one; 'auto' and ``max_mip_level=0`` as
nvdiffrast resolves them; one clear error for each bad input.

``uv`` lies on a grid of 1/4096, where float32 and float64 take the same texels and fractions
(the gradients' kinks at texel centres fall on the same side); lookups within 1e-4 of an integer
mip level, where the two may take different levels, are left out of the comparison.
"""

import math

import pytest
import torch

import softvk.nvdiffrast.torch as dr

FILTERS = ["nearest", "linear", "linear-mipmap-nearest", "linear-mipmap-linear"]
BOUNDARIES = ["wrap", "clamp", "zero"]


# ---------------------------------------------------------------------------------------------
# The reference, float64.


def ref_pyramid(tex, levels):
    """``levels`` levels of ``tex`` [N, H, W, C]: each the mean of 2 x 2 (or 2 x 1) texels."""
    out = [tex]
    for _ in range(levels - 1):
        t = out[-1]
        n, h, w, c = t.shape
        if h == 1:
            t = t.reshape(n, 1, w // 2, 2, c).mean(3)
        elif w == 1:
            t = t.reshape(n, h // 2, 2, 1, c).mean(2)
        else:
            t = t.reshape(n, h // 2, 2, w // 2, 2, c).mean((2, 4))
        out.append(t)
    return out


def ref_level(uv_da, bias, width, height):
    """nvdiffrast's λ: ½ log2 of the footprint's major axis squared (in base texels), plus the
    bias."""
    lam = 0.0
    if uv_da is not None:
        sx, sy = uv_da[..., 0] * width, uv_da[..., 1] * width
        tx, ty = uv_da[..., 2] * height, uv_da[..., 3] * height
        a = sx * sx + tx * tx
        b = sy * sy + ty * ty
        c = sx * sy + tx * ty
        major = 0.5 * (a + b) + torch.sqrt(0.25 * (a - b) ** 2 + c * c)
        lam = 0.5 * torch.log2(major)
    if bias is not None:
        lam = lam + bias
    return lam


def gather(level, item, x, y):
    """level[item, y, x, :] per lookup."""
    return level[item, y, x]


def ref_bilinear(level, item, u, v, boundary):
    n, h, w, c = level.shape
    if boundary == "wrap":
        u = u - torch.floor(u.detach())
        v = v - torch.floor(v.detach())
    s, t = u * w - 0.5, v * h - 0.5
    if boundary == "clamp":
        s, t = s.clamp(0, w - 1), t.clamp(0, h - 1)
    s0, t0 = torch.floor(s.detach()), torch.floor(t.detach())
    fs, ft = (s - s0)[..., None], (t - t0)[..., None]
    taps = []
    for dy in (0, 1):
        for dx in (0, 1):
            x, y = (s0 + dx).long(), (t0 + dy).long()
            if boundary == "wrap":
                x, y = x % w, y % h
            inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
            value = gather(level, item, x.clamp(0, w - 1), y.clamp(0, h - 1))
            taps.append(value * inside[..., None])
    a00, a10, a01, a11 = taps
    top = a00 + fs * (a10 - a00)
    bottom = a01 + fs * (a11 - a01)
    return top + ft * (bottom - top)


def ref_texture(tex, uv, uv_da, bias, filter_mode, boundary, levels=None, max_mip_level=None):
    """The reference of ``texture``; ``levels``: a custom stack below ``tex``."""
    b, hh, ww, _ = uv.shape
    n, h, w, c = tex.shape
    item = (torch.arange(b).view(b, 1, 1).expand(b, hh, ww)) if n > 1 else torch.zeros(
        b, hh, ww, dtype=torch.long)
    u, v = uv[..., 0], uv[..., 1]
    if filter_mode == "nearest":
        if boundary == "wrap":
            u, v = u - torch.floor(u), v - torch.floor(v)
        x, y = torch.floor(u * w).long(), torch.floor(v * h).long()
        inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
        value = gather(tex, item, x.clamp(0, w - 1), y.clamp(0, h - 1))
        return value * inside[..., None] if boundary == "zero" else value
    if filter_mode == "linear":
        return ref_bilinear(tex, item, u, v, boundary)
    if levels is None:
        count = 1
        while max_mip_level is None or count - 1 < max_mip_level:
            lw, lh = max(w >> (count - 1), 1), max(h >> (count - 1), 1)
            if lw == 1 and lh == 1:
                break
            count += 1
        stack = ref_pyramid(tex, count)
    else:
        stack = [tex] + list(levels)
    top = len(stack) - 1
    lam = ref_level(uv_da, bias, w, h)
    lam = torch.as_tensor(lam, dtype=torch.float64).expand(b, hh, ww).clamp(0, top)
    l0 = torch.floor(lam.detach()).long()
    frac = (lam - l0).unsqueeze(-1) if filter_mode == "linear-mipmap-linear" else None
    out = torch.zeros(b, hh, ww, c, dtype=torch.float64)
    for k in range(len(stack)):
        at = ref_bilinear(stack[k], item, u, v, boundary)
        on = (l0 == k).unsqueeze(-1)
        if frac is None:
            out = out + at * on
        else:
            above = ref_bilinear(stack[min(k + 1, top)], item, u, v, boundary)
            out = out + (at + frac * (above - at)) * on
    return out


# ---------------------------------------------------------------------------------------------
# Cases.


def case(seed, tex_shape, batch=2, size=(6, 7), uv_da=True, bias=True):
    g = torch.Generator().manual_seed(seed)
    hh, ww = size
    tex = torch.rand(tex_shape, generator=g) * 2 - 1
    uv = torch.round((torch.rand(batch, hh, ww, 2, generator=g) * 2.2 - 0.6) * 4096) / 4096
    w, h = tex_shape[2], tex_shape[1]
    da = None
    if uv_da:
        scale = 2.0 ** (torch.rand(batch, hh, ww, 1, generator=g) * 4.5 - 3.5) / max(w, h)
        da = (torch.rand(batch, hh, ww, 4, generator=g) * 2 - 1) * scale
    mb = torch.rand(batch, hh, ww, generator=g) * 4 - 1 if bias else None
    dy = torch.rand(batch, hh, ww, tex_shape[3], generator=g) * 2 - 1
    return tex, uv, da, mb, dy


def leaf(t, dtype=torch.float32):
    return None if t is None else t.detach().to(dtype).requires_grad_()


def far_from_integer_levels(tex, uv_da, bias, filter_mode):
    """Lookups whose λ is not within 1e-4 of an integer (all of them without mipmaps)."""
    shape = (uv_da if uv_da is not None else bias).shape[:3] if "mipmap" in filter_mode else None
    if shape is None:
        return None
    lam = ref_level(None if uv_da is None else uv_da.double(),
                    None if bias is None else bias.double(), tex.shape[2], tex.shape[1])
    lam = torch.as_tensor(lam, dtype=torch.float64).expand(shape)
    return (lam - torch.round(lam)).abs() >= 1e-4


def compare(name, got, want, mask, rtol, atol):
    got, want = got.double(), want.double()
    if mask is not None and got.dim() >= 3 and got.shape[:3] == mask.shape:
        keep = mask.reshape(mask.shape + (1,) * (got.dim() - 3)).expand_as(got)
        got, want = got[keep], want[keep]
    err = (got - want).abs()
    bound = atol + rtol * want.abs()
    worst = int(torch.argmax(err - bound))
    assert bool((err <= bound).all()), (
        f"{name}: got {got.reshape(-1)[worst]} want {want.reshape(-1)[worst]}"
    )


@pytest.mark.parametrize("filter_mode", FILTERS)
@pytest.mark.parametrize("boundary", BOUNDARIES)
@pytest.mark.parametrize("tex_shape", [(1, 12, 20, 3), (2, 4, 16, 1)])
def test_texture_and_its_gradients_match_the_reference(gpu, filter_mode, boundary, tex_shape):
    mips = "mipmap" in filter_mode
    max_mip_level = 2 if tex_shape[1] == 12 else None  # 12 x 20 halves twice, then 5 is odd
    for inputs in ([(True, False), (False, True), (True, True)] if mips else [(False, False)]):
        tex, uv, da, mb, dy = case(7, tex_shape, uv_da=inputs[0], bias=inputs[1])
        args = dict(filter_mode=filter_mode, boundary_mode=boundary, max_mip_level=max_mip_level)
        got_in = [leaf(t) for t in (tex, uv, da, mb)]
        got = dr.texture(*got_in[:2], uv_da=got_in[2], mip_level_bias=got_in[3], **args)
        want_in = [leaf(t, torch.float64) for t in (tex, uv, da, mb)]
        want = ref_texture(*want_in, filter_mode, boundary, max_mip_level=max_mip_level)
        mask = far_from_integer_levels(tex, da, mb, filter_mode)
        what = f"{filter_mode}/{boundary} {list(tex_shape)} {inputs}"
        compare(f"{what} out", got, want, mask, 1e-5, 1e-6)
        if mask is not None:
            # Leave the lookups near an integer level out of the gradients too.
            dy = dy * mask[..., None]
        (got * dy).sum().backward()
        (want * dy.double()).sum().backward()
        names = ["tex", "uv", "uv_da", "mip_level_bias"]
        for name, g, w in zip(names, got_in, want_in):
            if g is None:
                continue
            w_grad = w.grad if w.grad is not None else torch.zeros_like(w)
            g_grad = g.grad if g.grad is not None else torch.zeros_like(g)
            # nvdiffrast gives uv no gradient in 'nearest', the level inputs none but in
            # 'linear-mipmap-linear'; the reference's autograd agrees (floors have none).
            compare(f"{what} d/d{name}", g_grad, w_grad, None, 1e-4, 1e-5)


def test_a_prebuilt_stack_gives_what_one_built_in_the_call_gives(gpu):
    tex, uv, da, mb, dy = case(3, (1, 16, 8, 3))
    a, b = leaf(tex), leaf(tex)
    mip = dr.texture_construct_mip(b)
    assert mip.texture_shape == [1, 16, 8, 3] and mip.max_mip_level == 4
    built = dr.texture(a, uv, da, mb)
    prebuilt = dr.texture(b, uv, da, mb, mip=mip)
    assert torch.equal(built, prebuilt)
    (built * dy).sum().backward()
    (prebuilt * dy).sum().backward()
    assert torch.equal(a.grad, b.grad)  # both through the pyramid into tex
    # Limited: max_mip_level levels, and the stack's own limit rules a prebuilt one.
    limited = dr.texture_construct_mip(tex, max_mip_level=1)
    assert limited.max_mip_level == 1
    one = dr.texture(tex, uv, da, mb, max_mip_level=1)
    assert torch.equal(one, dr.texture(tex, uv, da, mb, mip=limited))
    with pytest.raises(ValueError, match="mip was built for"):
        dr.texture(tex[:, :8], uv, da, mb, mip=mip)


def test_a_custom_stack_takes_its_own_levels_and_gives_each_its_gradient(gpu):
    tex, uv, da, mb, dy = case(4, (2, 8, 12, 2))
    g = torch.Generator().manual_seed(9)
    levels = [torch.rand(2, 4, 6, 2, generator=g), torch.rand(2, 2, 3, 2, generator=g)]
    got_levels = [leaf(t) for t in levels]
    got_tex = leaf(tex)
    got = dr.texture(got_tex, uv, da, mb, mip=got_levels, filter_mode="linear-mipmap-linear")
    want_levels = [leaf(t, torch.float64) for t in levels]
    want_tex = leaf(tex, torch.float64)
    want = ref_texture(want_tex, uv.double(), da.double(), mb.double(), "linear-mipmap-linear",
                       "wrap", levels=want_levels)
    mask = far_from_integer_levels(tex, da, mb, "linear-mipmap-linear")
    compare("custom out", got, want, mask, 1e-5, 1e-6)
    dy = dy * mask[..., None]
    (got * dy).sum().backward()
    (want * dy.double()).sum().backward()
    compare("custom d/dtex", got_tex.grad, want_tex.grad, None, 1e-4, 1e-5)
    for k, (g_, w_) in enumerate(zip(got_levels, want_levels)):
        compare(f"custom d/dlevel {k + 1}", g_.grad, w_.grad, None, 1e-4, 1e-5)
    with pytest.raises(ValueError, match="mip level 2"):
        dr.texture(tex, uv, da, mb, mip=[levels[0], levels[0]])


def test_auto_and_max_mip_level_zero_resolve_as_nvdiffrast(gpu):
    tex, uv, da, mb, _ = case(5, (1, 8, 8, 3))
    assert torch.equal(dr.texture(tex, uv), dr.texture(tex, uv, filter_mode="linear"))
    assert torch.equal(
        dr.texture(tex, uv, da), dr.texture(tex, uv, da, filter_mode="linear-mipmap-linear")
    )
    assert torch.equal(
        dr.texture(tex, uv, mip_level_bias=mb),
        dr.texture(tex, uv, mip_level_bias=mb, filter_mode="linear-mipmap-linear"),
    )
    assert torch.equal(
        dr.texture(tex, uv, da, filter_mode="linear-mipmap-nearest", max_mip_level=0),
        dr.texture(tex, uv, filter_mode="linear"),
    )
    # A mode with no mipmaps ignores the level inputs (and an odd size is then fine).
    odd = torch.rand(1, 5, 7, 2)
    assert torch.equal(dr.texture(odd, uv, da, filter_mode="linear"),
                       dr.texture(odd, uv, filter_mode="linear"))


def test_every_bad_input_to_texture_raises_one_clear_error(gpu):
    tex, uv, da, mb, _ = case(6, (1, 8, 8, 3))

    def raises(kind, match, *args, **kwargs):
        with pytest.raises(kind, match=match):
            dr.texture(*args, **kwargs)

    raises(ValueError, "filter_mode", tex, uv, filter_mode="bilinear")
    raises(ValueError, "boundary_mode", tex, uv, boundary_mode="mirror")
    raises(ValueError, "requires uv_da", tex, uv, filter_mode="linear-mipmap-linear")
    raises(ValueError, "max_mip_level", tex, uv, da, max_mip_level=-1)
    raises(TypeError, "max_mip_level", tex, uv, da, max_mip_level=1.5)
    raises(TypeError, "tex", tex.double(), uv)
    raises(TypeError, "uv", tex, uv.half())
    raises(TypeError, "tex", tex.numpy(), uv)
    raises(ValueError, "tex", tex[0], uv)
    raises(ValueError, "uv", tex, uv[..., :1])
    raises(ValueError, "minibatch", torch.rand(3, 8, 8, 3), uv)
    raises(ValueError, "uv_da", tex, uv, da[..., :3])
    raises(ValueError, "mip_level_bias", tex, uv, mip_level_bias=mb[:1])
    raises(TypeError, "mip", tex, uv, da, mip="stack")
    raises(ValueError, "odd extent", torch.rand(1, 12, 20, 3), uv, da)
    bad = uv.clone()
    bad[0, 1, 2, 0] = math.nan
    raises(ValueError, "uv has a value that is not finite", tex, bad)
    bad_tex = tex.clone()
    bad_tex[0, 3, 3, 1] = math.inf
    raises(ValueError, "tex has a value that is not finite", bad_tex, uv)
    bad_da = da.clone()
    bad_da[1, 0, 0, 3] = math.nan
    raises(ValueError, "uv_da has a value that is not finite", tex, uv, bad_da)
    with pytest.raises(TypeError, match="cube_mode"):
        dr.texture_construct_mip(tex, cube_mode=1)
    with pytest.raises(ValueError, match="odd extent"):
        dr.texture_construct_mip(torch.rand(1, 6, 6, 1))


def test_non_contiguous_inputs_give_the_contiguous_result(gpu):
    tex, uv, da, mb, _ = case(8, (1, 8, 16, 3))
    strided_tex = tex.repeat_interleave(2, 2)[:, :, ::2]
    strided_uv = uv.repeat_interleave(2, -1)[..., ::2]
    assert not strided_tex.is_contiguous() and not strided_uv.is_contiguous()
    assert torch.equal(dr.texture(tex, uv, da, mb), dr.texture(strided_tex, strided_uv, da, mb))
