"""softvk.nvdiffrast.torch: nvdiffrast's PyTorch API on softvk.

Tiny images throughout. What each test proves is in its name: the shapes, dtypes and return
values of every function in instanced and range mode; ``rast`` and ``rast_db`` of one
triangle against a hand computation; depth peeling's layers; ``interpolate``'s pixel
derivatives; every backward against central differences; ``antialias`` touching silhouettes
only; one clear error for each bad input; an nvdiffrast-style optimisation loop with only the
import changed; CUDA tensors (where there is CUDA) coming back on CUDA; a forked child's clear
error; the same bits on a rerun.
"""

import os

import numpy as np
import pytest
import torch

import softvk.nvdiffrast.torch as dr


@pytest.fixture(scope="module")
def glctx(gpu):
    return dr.RasterizeCudaContext()


def f32(values):
    return torch.tensor(values, dtype=torch.float32)


def i32(values):
    return torch.tensor(values, dtype=torch.int32)


# One triangle whose second vertex has w = 2 (the same point in NDC as (0.8, -0.8) at w = 1),
# so perspective-correct barycentrics differ from screen-space ones.
TRI_POS = [[-0.8, -0.8, 0.2, 1.0], [1.6, -1.6, -0.4, 2.0], [-0.8, 0.8, 0.6, 1.0]]
TRI = [[0, 1, 2]]


def pixel_ndc(x, y, width, height):
    """Pixel (column x, row y)'s centre in NDC, row 0 at the bottom."""
    return (2 * x + 1) / width - 1, (2 * y + 1) / height - 1


def hand_rast(pos, f):
    """(u, v, z/w) of the triangle `pos` (clip space, float64) at NDC point `f`: screen-space
    barycentrics made perspective-correct by dividing by w."""
    pos = np.asarray(pos, dtype=np.float64)
    ndc = pos[:, :2] / pos[:, 3:4]

    def area(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    p = np.asarray(f, dtype=np.float64)
    total = area(ndc[0], ndc[1], ndc[2])
    lam = np.array([area(p, ndc[1], ndc[2]), area(ndc[0], p, ndc[2]), area(ndc[0], ndc[1], p)])
    lam /= total
    persp = lam / pos[:, 3]
    persp /= persp.sum()
    zw = float(np.dot(lam, pos[:, 2] / pos[:, 3]))
    return persp[0], persp[1], zw


# ---------------------------------------------------------------------------------------------
# Shapes, dtypes and return values.


def test_rasterize_interpolate_antialias_shapes_and_dtypes_in_instanced_mode(glctx):
    pos = f32([TRI_POS, TRI_POS])  # [2, 3, 4]
    tri = i32(TRI)
    rast, rast_db = dr.rasterize(glctx, pos, tri, resolution=(4, 6))
    assert rast.shape == (2, 4, 6, 4) and rast_db.shape == (2, 4, 6, 4)
    assert rast.dtype == rast_db.dtype == torch.float32 and rast.device.type == "cpu"
    col = f32([[1, 0, 0], [0, 1, 0], [0, 0, 1]])
    for attr in (col, col[None], col[None].expand(2, 3, 3).contiguous()):
        out, out_da = dr.interpolate(attr, rast, tri)
        assert out.shape == (2, 4, 6, 3) and out_da.shape == (2, 4, 6, 0)
        assert out.dtype == out_da.dtype == torch.float32
    out, out_da = dr.interpolate(col, rast, tri, rast_db=rast_db, diff_attrs=[0, 2])
    assert out_da.shape == (2, 4, 6, 4)
    aa = dr.antialias(out, rast, pos, tri)
    assert aa.shape == out.shape and aa.dtype == torch.float32
    # Both minibatch items see the same triangle.
    assert torch.equal(rast[0], rast[1])


def test_rasterize_interpolate_antialias_shapes_and_ids_in_range_mode(glctx):
    # Two triangles in one vertex array; item 0 draws triangle 1, item 1 both, item 2 none.
    pos = f32([[-1, -1, 0, 1], [1, -1, 0, 1], [-1, 1, 0, 1], [1, 1, 0.5, 1]])
    tri = i32([[0, 1, 2], [1, 3, 2]])
    ranges = i32([[1, 1], [0, 2], [2, 0]])
    rast, rast_db = dr.rasterize(glctx, pos, tri, resolution=(4, 4), ranges=ranges)
    assert rast.shape == (3, 4, 4, 4) and rast_db.shape == (3, 4, 4, 4)
    ids = rast[..., 3]
    # Ids are the global triangle indices + 1.
    assert set(ids[0].unique().tolist()) == {0.0, 2.0}
    assert set(ids[1].unique().tolist()) == {1.0, 2.0}
    assert bool((rast[2] == 0).all()) and bool((rast_db[2] == 0).all())
    col = f32([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    out, out_da = dr.interpolate(col, rast, tri, rast_db=rast_db, diff_attrs="all")
    assert out.shape == (3, 4, 4, 3) and out_da.shape == (3, 4, 4, 6)
    aa = dr.antialias(out, rast, pos, tri)
    assert aa.shape == (3, 4, 4, 3)


def test_a_gl_context_without_output_db_returns_an_empty_rast_db(gpu):
    ctx = dr.RasterizeGLContext(output_db=False)
    assert ctx.output_db is False and ctx.mode == "automatic"
    ctx.set_context()
    ctx.release_context()
    pos = f32([TRI_POS]).requires_grad_()
    rast, rast_db = dr.rasterize(ctx, pos, i32(TRI), resolution=[4, 4])
    assert rast.shape == (1, 4, 4, 4) and rast_db.shape == (1, 4, 4, 0)
    rast[..., :2].sum().backward()
    assert pos.grad is not None and bool(pos.grad.abs().sum() > 0)
    # With output_db (the default) it is the CUDA context's.
    rast2, rast_db2 = dr.rasterize(dr.RasterizeGLContext(), pos, i32(TRI), resolution=[4, 4])
    assert torch.equal(rast, rast2) and rast_db2.shape == (1, 4, 4, 4)


def test_the_log_level_round_trips_and_the_public_names_are_nvdiffrasts():
    assert dr.get_log_level() == 1
    dr.set_log_level(2)
    assert dr.get_log_level() == 2
    dr.set_log_level(1)
    with pytest.raises(TypeError):
        dr.set_log_level("loud")
    assert set(dr.__all__) == {
        "RasterizeCudaContext", "get_log_level", "set_log_level", "rasterize", "DepthPeeler",
        "interpolate", "texture", "texture_construct_mip", "antialias",
        "antialias_construct_topology_hash", "RasterizeGLContext",
    }
    assert issubclass(dr.RasterizeGLContext, dr.RasterizeCudaContext)


# ---------------------------------------------------------------------------------------------
# Values.


def test_one_triangle_rast_against_a_hand_computation(glctx):
    width, height = 6, 4
    rast, rast_db = dr.rasterize(glctx, f32([TRI_POS]), i32(TRI), resolution=(height, width))
    rast, rast_db = rast[0].numpy().astype(np.float64), rast_db[0].numpy().astype(np.float64)
    # Pixel (1, 0), bottom row: inside the triangle (which covers the lower left half).
    x, y = 1, 0
    u, v, zw = hand_rast(TRI_POS, pixel_ndc(x, y, width, height))
    np.testing.assert_allclose(rast[y, x], [u, v, zw, 1.0], atol=1e-6)
    # The same column in the top row lies past the hypotenuse: nothing drawn. (Were row 0 the
    # top, these two would swap.)
    assert np.all(rast[height - 1, x] == 0)
    # rast_db: central differences of the hand (u, v) over one pixel (2/W, 2/H in NDC).
    h = 1e-4
    fx, fy = pixel_ndc(x, y, width, height)
    du_dx = (np.array(hand_rast(TRI_POS, (fx + h, fy))) -
             np.array(hand_rast(TRI_POS, (fx - h, fy)))) / (2 * h) * (2 / width)
    du_dy = (np.array(hand_rast(TRI_POS, (fx, fy + h))) -
             np.array(hand_rast(TRI_POS, (fx, fy - h)))) / (2 * h) * (2 / height)
    want_db = [du_dx[0], du_dy[0], du_dx[1], du_dy[1]]
    np.testing.assert_allclose(rast_db[y, x], want_db, atol=1e-5)
    # Every drawn pixel: inside by the hand test, and the hand values.
    for yy in range(height):
        for xx in range(width):
            fx, fy = pixel_ndc(xx, yy, width, height)
            inside = fx > -0.8 and fy > -0.8 and fx + fy < 0
            assert (rast[yy, xx, 3] == 1.0) == inside, (xx, yy)
            if inside:
                np.testing.assert_allclose(
                    rast[yy, xx, :3], hand_rast(TRI_POS, (fx, fy)), atol=1e-6
                )


def test_depth_peeler_gives_the_nearer_then_the_farther_triangle_then_nothing(glctx):
    # Two triangles over the same pixels: triangle 0 far (z = 0.5), triangle 1 near (z = -0.3).
    far = [[-0.9, -0.9, 0.5, 1], [0.9, -0.9, 0.5, 1], [-0.9, 0.9, 0.5, 1]]
    near = [[-0.7, -0.7, -0.3, 1], [0.7, -0.7, -0.3, 1], [-0.7, 0.7, -0.3, 1]]
    pos = f32([far + near])
    tri = i32([[0, 1, 2], [3, 4, 5]])
    layers = []
    with dr.DepthPeeler(glctx, pos, tri, resolution=(8, 8)) as peeler:
        with pytest.raises(RuntimeError):
            dr.rasterize(glctx, pos, tri, resolution=(8, 8))
        with pytest.raises(RuntimeError):
            with dr.DepthPeeler(glctx, pos, tri, resolution=(8, 8)):
                pass
        for _ in range(3):
            layers.append(peeler.rasterize_next_layer())
    with pytest.raises(RuntimeError):
        peeler.rasterize_next_layer()
    (r0, db0), (r1, _), (r2, db2) = layers
    assert torch.equal(r0, dr.rasterize(glctx, pos, tri, resolution=(8, 8))[0])
    ids0, ids1 = r0[0, ..., 3], r1[0, ..., 3]
    both = (ids0 == 2) & (ids1 == 1)
    assert int(both.sum()) > 0
    # Where the near one covers, the first layer shows it and the second the far one behind it.
    np.testing.assert_allclose(r0[0, ..., 2][ids0 == 2].numpy(), -0.3, atol=1e-6)
    np.testing.assert_allclose(r1[0, ..., 2][ids1 == 1].numpy(), 0.5, atol=1e-6)
    assert bool(((ids0 == 2) == (ids1 == 1)).all())
    # Where only the far one covers, layer 0 shows it and layer 1 nothing.
    only_far = ids0 == 1
    assert int(only_far.sum()) > 0 and bool((r1[0][only_far] == 0).all())
    assert bool((r2 == 0).all()) and bool((db2 == 0).all())


def test_interpolate_pixel_derivatives_with_all_and_a_list(glctx):
    width, height = 8, 4
    # w = 1 everywhere: attributes linear in NDC interpolate exactly, with constant derivatives.
    pos = f32([[[-1, -1, 0, 1], [3, -1, 0, 1], [-1, 3, 0, 1]]])  # covers the whole viewport
    tri = i32(TRI)
    rast, rast_db = dr.rasterize(glctx, pos, tri, resolution=(height, width))
    ndc = pos[0, :, :2]
    attr = torch.stack([ndc[:, 0], ndc[:, 1], 2 * ndc[:, 0] - ndc[:, 1]], dim=1)  # [3, 3]
    out, da_all = dr.interpolate(attr, rast, tri, rast_db=rast_db, diff_attrs="all")
    ys, xs = np.mgrid[0:height, 0:width]
    fx, fy = (2 * xs + 1) / width - 1, (2 * ys + 1) / height - 1
    np.testing.assert_allclose(out[0, ..., 0].numpy(), fx, atol=1e-5)
    np.testing.assert_allclose(out[0, ..., 1].numpy(), fy, atol=1e-5)
    np.testing.assert_allclose(out[0, ..., 2].numpy(), 2 * fx - fy, atol=1e-5)
    sx, sy = 2 / width, 2 / height  # NDC per pixel
    want = np.array([sx, 0, 0, sy, 2 * sx, -sy])
    np.testing.assert_allclose(da_all[0].numpy(), np.broadcast_to(want, da_all[0].shape),
                               atol=1e-5)
    # A list, negative indices counting from the end: attribute 2, then attribute 0.
    _, da_list = dr.interpolate(attr, rast, tri, rast_db=rast_db, diff_attrs=[-1, 0])
    assert da_list.shape == (1, height, width, 4)
    assert torch.equal(da_list[..., 0:2], da_all[..., 4:6])
    assert torch.equal(da_list[..., 2:4], da_all[..., 0:2])
    # No diff_attrs, or an empty list: an empty out_da, and rast_db is not needed.
    for diff in (None, []):
        out2, da = dr.interpolate(attr, rast, tri, rast_db=rast_db, diff_attrs=diff)
        assert da.shape == (1, height, width, 0) and torch.equal(out2, out)


def test_antialias_changes_only_silhouette_pixels_and_has_a_pos_gradient(glctx):
    size = 16
    # A quad of two triangles with a shared (welded) diagonal, inside the viewport.
    quad = [[-0.61, -0.53, 0, 1], [0.57, -0.66, 0, 1], [0.63, 0.59, 0, 1], [-0.55, 0.62, 0, 1]]
    pos = f32([quad]).requires_grad_()
    tri = i32([[0, 1, 2], [0, 2, 3]])
    rast, _ = dr.rasterize(glctx, pos, tri, resolution=(size, size))
    ids = rast[0, ..., 3]
    # One colour per triangle, so a blend across the diagonal would show.
    color = torch.stack([ids == 1, ids == 2, ids == 0], dim=-1).float()[None]
    out = dr.antialias(color, rast, pos, tri)
    changed = (out != color).any(dim=-1)[0]
    covered = ids > 0
    # A silhouette pixel has a 4-neighbour on the other side of the quad's outline.
    pad = torch.nn.functional.pad(covered[None, None].float(), (1, 1, 1, 1), value=0)[0, 0]
    neighbours = torch.stack([pad[1:-1, :-2], pad[1:-1, 2:], pad[:-2, 1:-1], pad[2:, 1:-1]])
    silhouette = (neighbours != covered.float()).any(dim=0)
    # Pixels at the image border see no pair past the border.
    assert int(changed.sum()) > 0
    assert bool((changed <= silhouette).all()), "antialias changed a pixel off the outline"
    diagonal = covered & ~silhouette & (
        torch.nn.functional.max_pool2d(ids[None, None], 3, 1, 1)[0, 0]
        != -torch.nn.functional.max_pool2d(-ids[None, None], 3, 1, 1)[0, 0])
    assert int(diagonal.sum()) > 0 and not bool(changed[diagonal].any())
    # The position gradient comes from antialias alone (the colours do not depend on u, v).
    weights = torch.rand(out.shape, generator=torch.Generator().manual_seed(1))
    (out * weights).sum().backward()
    assert pos.grad is not None and bool(pos.grad.isfinite().all())
    assert float(pos.grad[0, :, :2].abs().sum()) > 0 and bool((pos.grad[0, :, 2] == 0).all())
    # A prebuilt topology hash gives the same image.
    topology = dr.antialias_construct_topology_hash(tri)
    assert torch.equal(dr.antialias(color, rast, pos, tri, topology_hash=topology), out)
    # Unwelded (the diagonal's vertices duplicated), the diagonal is a silhouette too.
    pos2 = f32([quad + [quad[0], quad[2]]])
    tri2 = i32([[0, 1, 2], [4, 5, 3]])
    rast2, _ = dr.rasterize(glctx, pos2, tri2, resolution=(size, size))
    ids2 = rast2[0, ..., 3]
    color2 = torch.stack([ids2 == 1, ids2 == 2, ids2 == 0], dim=-1).float()[None]
    out2 = dr.antialias(color2, rast2, pos2, tri2)
    assert bool((out2 != color2).any(dim=-1)[0][diagonal].any())


# ---------------------------------------------------------------------------------------------
# Gradients against central differences: float64 differences of the float32 functions.

STEP = 1e-3


def dot(output, weights):
    """A loss: the float32 output against fixed weights, summed in float64 (so the sum adds no
    float32 rounding to the differences)."""
    return (output.double() * weights.double()).sum()


def central_differences(loss, x):
    """d loss / d x by central differences of step STEP, in float64."""
    x0 = x.detach().clone()
    grad = np.zeros(x0.numel())
    for i in range(x0.numel()):
        values = []
        for sign in (1, -1):
            xp = x0.clone().reshape(-1)
            xp[i] += sign * STEP
            with torch.no_grad():
                values.append(float(loss(xp.reshape(x0.shape)).double()))
        grad[i] = (values[0] - values[1]) / (2 * STEP)
    return grad.reshape(x0.shape)


def assert_grad_close(analytic, numeric, rtol=2e-2, atol=None):
    analytic = analytic.detach().double().numpy()
    scale = max(1.0, float(np.abs(numeric).max()))
    atol = 2e-3 * scale if atol is None else atol
    np.testing.assert_allclose(analytic, numeric, rtol=rtol, atol=atol)


# Every pixel centre of the 8×8 and 6×6 images lies over 0.11 pixel from the triangle's edges,
# far more than a step of STEP moves them (no coverage changes, no clamps binding).
GRAD_POS = [[-0.805, -0.729, 0.1, 1.099], [1.49, -1.312, 0.3, 1.803], [-0.71, 0.762, -0.2, 0.962]]


@pytest.mark.parametrize("mode", ["instanced", "range"])
@pytest.mark.parametrize("grad_db", [True, False])
def test_rasterize_backward_matches_central_differences(glctx, mode, grad_db):
    pos0 = f32([GRAD_POS]) if mode == "instanced" else f32(GRAD_POS)
    ranges = None if mode == "instanced" else i32([[0, 1]])
    tri = i32(TRI)
    gen = torch.Generator().manual_seed(0)
    w_rast = torch.rand(1, 8, 8, 4, generator=gen)
    w_db = torch.rand(1, 8, 8, 4, generator=gen)

    def loss(pos):
        rast, rast_db = dr.rasterize(glctx, pos, tri, (8, 8), ranges=ranges, grad_db=grad_db)
        total = dot(rast[..., :2], w_rast[..., :2])
        return total + dot(rast_db, w_db) if grad_db else total

    pos = pos0.clone().requires_grad_()
    loss(pos).backward()
    assert_grad_close(pos.grad, central_differences(loss, pos0))
    assert bool((pos.grad[..., 2] == 0).all())  # z/w and the id carry no gradient


def test_interpolate_backward_matches_central_differences(glctx):
    pos = f32([GRAD_POS])
    tri = i32(TRI)
    rast0, db0 = dr.rasterize(glctx, pos, tri, (6, 6))
    gen = torch.Generator().manual_seed(2)
    attr0 = torch.rand(3, 2, generator=gen)
    w_out = torch.rand(1, 6, 6, 2, generator=gen)
    w_da = torch.rand(1, 6, 6, 4, generator=gen)

    def loss_of(attr, rast, rast_db):
        out, da = dr.interpolate(attr, rast, tri, rast_db=rast_db, diff_attrs=[1, 0])
        return dot(out, w_out) + dot(da, w_da)

    attr = attr0.clone().requires_grad_()
    rast = rast0.clone().requires_grad_()
    rast_db = db0.clone().requires_grad_()
    loss_of(attr, rast, rast_db).backward()
    assert_grad_close(attr.grad, central_differences(lambda a: loss_of(a, rast0, db0), attr0))
    assert_grad_close(rast_db.grad,
                      central_differences(lambda d: loss_of(attr0, rast0, d), db0))
    # rast: only u and v are continuous inputs (the id picks the triangle); z/w takes none.
    uv0 = rast0[..., :2].clone()

    def loss_uv(uv):
        return loss_of(attr0, torch.cat([uv, rast0[..., 2:]], dim=-1), db0)

    assert_grad_close(rast.grad[..., :2], central_differences(loss_uv, uv0))
    assert bool((rast.grad[..., 2:] == 0).all())
    # Broadcast attributes [1, V, A] over a minibatch of 2: the gradient sums the items.
    rast2, db2 = dr.rasterize(glctx, pos.expand(2, 3, 4).contiguous(), tri, (6, 6))
    attr_b = attr0[None].clone().requires_grad_()
    dr.interpolate(attr_b, rast2, tri)[0].sum().backward()
    attr_1 = attr0.clone().requires_grad_()
    dr.interpolate(attr_1, rast0, tri)[0].sum().backward()
    assert attr_b.grad.shape == (1, 3, 2)
    np.testing.assert_allclose(attr_b.grad[0].numpy(), 2 * attr_1.grad.numpy(), rtol=1e-6)


def test_antialias_backward_matches_central_differences(glctx):
    size = 12
    # Chosen so that no blend decision (a crossing at 0, 1/2 or 1 pixel, or past the slack)
    # lies within a few steps of STEP: one-sided differences of 3e-3 agree with the gradient
    # to 0.2 %.
    quad = [[-0.562, -0.553, 0.1, 1.019], [0.611, -0.69, 0.2, 1.111], [0.665, 0.557, 0.0, 0.915],
            [-0.545, 0.586, 0.1, 0.989]]
    pos0 = f32([quad])
    tri = i32([[0, 1, 2], [0, 2, 3]])
    rast, _ = dr.rasterize(glctx, pos0, tri, resolution=(size, size))
    gen = torch.Generator().manual_seed(3)
    color0 = torch.rand(1, size, size, 3, generator=gen)
    weights = torch.rand(1, size, size, 3, generator=gen)
    topology = dr.antialias_construct_topology_hash(tri)

    def loss_of(color, pos, boost=1.0):
        out = dr.antialias(color, rast, pos, tri, topology_hash=topology,
                           pos_gradient_boost=boost)
        return dot(out, weights)

    color = color0.clone().requires_grad_()
    pos = pos0.clone().requires_grad_()
    loss_of(color, pos).backward()
    assert_grad_close(color.grad, central_differences(lambda c: loss_of(c, pos0), color0))
    # rast stays fixed: the position gradient is the blend's, through the silhouette edges.
    numeric = central_differences(lambda p: loss_of(color0, p), pos0)
    assert np.abs(numeric).max() > 0.1
    assert_grad_close(pos.grad, numeric)
    # pos_gradient_boost scales the position gradient only.
    color_b = color0.clone().requires_grad_()
    pos_b = pos0.clone().requires_grad_()
    loss_of(color_b, pos_b, boost=2.5).backward()
    np.testing.assert_allclose(pos_b.grad.numpy(), 2.5 * pos.grad.numpy(), rtol=1e-6)
    assert torch.equal(color_b.grad, color.grad)


# ---------------------------------------------------------------------------------------------
# Bad inputs: one clear error each, before anything runs.


def test_every_bad_input_to_rasterize_raises_one_clear_error(glctx):
    pos = f32([TRI_POS])
    tri = i32(TRI)
    ok = dict(resolution=(4, 4))

    def raises(kind, match, *args, **kwargs):
        with pytest.raises(kind, match=match) as info:
            dr.rasterize(*args, **kwargs)
        # nvdiffrast's checks raise RuntimeError: softvk's errors are that too.
        if kind in (TypeError, ValueError):
            assert isinstance(info.value, RuntimeError)

    raises(TypeError, "float32", glctx, pos.double(), tri, **ok)
    raises(TypeError, "int32", glctx, pos, tri.long(), **ok)
    raises(TypeError, "Tensor", glctx, pos.numpy(), tri, **ok)
    raises(TypeError, "Tensor", glctx, pos, [[0, 1, 2]], **ok)
    raises(TypeError, "glctx", object(), pos, tri, **ok)
    raises(TypeError, "grad_db", glctx, pos, tri, grad_db=1, **ok)
    raises(ValueError, r"pos must have shape", glctx, pos[..., :3], tri, **ok)
    raises(ValueError, r"pos must have shape", glctx, pos[:, :0], tri, **ok)
    raises(ValueError, r"tri must have shape", glctx, pos, i32([[0, 1, 2, 0]]), **ok)
    raises(ValueError, r"tri must have shape", glctx, pos, i32([[0, 1, 2]])[:0], **ok)
    raises(ValueError, "vertex index 3", glctx, pos, i32([[0, 1, 3]]), **ok)
    raises(ValueError, "vertex index -1", glctx, pos, i32([[0, -1, 2]]), **ok)
    for bad in (float("nan"), float("inf")):
        bad_pos = pos.clone()
        bad_pos[0, 1, 3] = bad
        raises(ValueError, "not finite", glctx, bad_pos, tri, **ok)
    # Range mode.
    flat = pos[0]
    raises(ValueError, "needs ranges", glctx, flat, tri, **ok)
    raises(TypeError, "int32", glctx, flat, tri, ranges=torch.tensor([[0, 1]]), **ok)
    raises(ValueError, "CPU", glctx, flat, tri,
           ranges=torch.zeros(1, 2, dtype=torch.int32, device="meta"), **ok)
    raises(ValueError, r"ranges must have shape", glctx, flat, tri, ranges=i32([0, 1]), **ok)
    raises(ValueError, "within the 1 triangles", glctx, flat, tri, ranges=i32([[0, 2]]), **ok)
    raises(ValueError, "within the 1 triangles", glctx, flat, tri, ranges=i32([[-1, 1]]), **ok)
    # Resolution.
    raises(ValueError, "resolution", glctx, pos, tri, resolution=(0, 4))
    raises(ValueError, "resolution", glctx, pos, tri, resolution=(4, 1 << 16))
    raises(ValueError, "resolution", glctx, pos, tri, resolution=(4,))
    raises(TypeError, "resolution", glctx, pos, tri, resolution=4)
    raises(TypeError, "resolution", glctx, pos, tri, resolution=(4.0, 4))
    raises(TypeError, "resolution", glctx, pos, tri, resolution=(True, 4))
    # Devices: every tensor but ranges on pos's.
    raises(ValueError, "one device", glctx, pos, tri.to("meta"), **ok)
    # The same checks when a depth peeler is made.
    with pytest.raises(ValueError, match="vertex index 3"):
        dr.DepthPeeler(glctx, pos, i32([[0, 1, 3]]), (4, 4))


def test_every_bad_input_to_interpolate_raises_one_clear_error(glctx):
    pos = f32([TRI_POS, TRI_POS])
    tri = i32(TRI)
    rast, rast_db = dr.rasterize(glctx, pos, tri, (4, 4))
    attr = f32([[1, 0, 0], [0, 1, 0], [0, 0, 1]])

    def raises(kind, match, *args, **kwargs):
        with pytest.raises(kind, match=match):
            dr.interpolate(*args, **kwargs)

    raises(TypeError, "float32", attr.double(), rast, tri)
    raises(TypeError, "float32", attr, rast.double(), tri)
    raises(TypeError, "int32", attr, rast, tri.long())
    raises(TypeError, "float32", attr, rast, tri, rast_db=rast_db.double(), diff_attrs="all")
    raises(ValueError, r"rast must have shape", attr, rast[..., :3], tri)
    raises(ValueError, r"attr must have shape", attr[None, None], rast, tri)
    raises(ValueError, "minibatch of 3", attr[None].expand(3, 3, 3), rast, tri)
    raises(ValueError, "vertex index 3", attr, rast, i32([[0, 1, 3]]))
    raises(ValueError, "outside the 3 attributes", attr, rast, tri, rast_db, diff_attrs=[3])
    raises(ValueError, "outside the 3 attributes", attr, rast, tri, rast_db, diff_attrs=[-4])
    raises(ValueError, "'all'", attr, rast, tri, rast_db, diff_attrs="some")
    raises(ValueError, "1-D", attr, rast, tri, rast_db, diff_attrs=[[0, 1]])
    raises(ValueError, "1-D", attr, rast, tri, rast_db, diff_attrs=1)
    raises(TypeError, "ints", attr, rast, tri, rast_db, diff_attrs=[0.5])
    raises(ValueError, "needs rast_db", attr, rast, tri, diff_attrs="all")
    raises(ValueError, r"rast_db must have shape", attr, rast, tri, rast_db[:1],
           diff_attrs="all")
    raises(ValueError, "one device", attr.to("meta"), rast, tri)


def test_every_bad_input_to_antialias_raises_one_clear_error(glctx):
    pos = f32([TRI_POS])
    tri = i32(TRI)
    rast, _ = dr.rasterize(glctx, pos, tri, (4, 4))
    color = torch.ones(1, 4, 4, 3)

    def raises(kind, match, *args, **kwargs):
        with pytest.raises(kind, match=match):
            dr.antialias(*args, **kwargs)

    raises(TypeError, "float32", color.double(), rast, pos, tri)
    raises(TypeError, "float32", color, rast, pos.double(), tri)
    raises(TypeError, "int32", color, rast, pos, tri.long())
    raises(ValueError, r"color must have shape", color[0], rast, pos, tri)
    raises(ValueError, r"rast must have shape", torch.ones(1, 4, 5, 3), rast, pos, tri)
    raises(ValueError, r"pos must have shape", color, rast, pos.expand(2, 3, 4), tri)
    raises(ValueError, "vertex index 3", color, rast, pos, i32([[0, 1, 3]]))
    nan_pos = pos.clone()
    nan_pos[0, 0, 0] = float("nan")
    raises(ValueError, "not finite", color, rast, nan_pos, tri)
    raises(TypeError, "topology_hash", color, rast, pos, tri, topology_hash=object())
    other = dr.antialias_construct_topology_hash(i32([[0, 1, 2], [0, 2, 1]]))
    raises(ValueError, "built from 2 triangles", color, rast, pos, tri, topology_hash=other)
    raises(TypeError, "pos_gradient_boost", color, rast, pos, tri, pos_gradient_boost="x")
    raises(ValueError, "finite", color, rast, pos, tri, pos_gradient_boost=float("inf"))
    with pytest.raises(TypeError, match="int32"):
        dr.antialias_construct_topology_hash(tri.long())
    with pytest.raises(ValueError, match="negative"):
        dr.antialias_construct_topology_hash(i32([[0, -1, 2]]))


def test_contexts_check_their_arguments(gpu):
    with pytest.raises(TypeError, match="output_db"):
        dr.RasterizeGLContext(output_db=1)
    with pytest.raises(ValueError, match="mode"):
        dr.RasterizeGLContext(mode="eager")
    assert dr.RasterizeCudaContext(device="cuda:1").device == "cuda:1"


# ---------------------------------------------------------------------------------------------
# An nvdiffrast program, with only its import changed.

SAMPLE = '''
import os

import numpy as np
import torch
import nvdiffrast.torch as dr

def render(glctx, pos, pos_idx, vtx_col, resolution):
    rast_out, _ = dr.rasterize(glctx, pos, pos_idx, resolution=[resolution, resolution])
    color, _ = dr.interpolate(vtx_col[None, ...], rast_out, pos_idx)
    color = dr.antialias(color, rast_out, pos, pos_idx)
    return color

glctx = dr.RasterizeCudaContext()
pos_idx = torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32, device=device)
vtx_pos = torch.tensor([[-0.6, -0.6, 0.0, 1.0], [0.6, -0.5, 0.0, 1.0],
                        [0.5, 0.6, 0.0, 1.0], [-0.55, 0.5, 0.0, 1.0]], device=device)
vtx_col = torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 0.0]],
                       device=device)
target = render(glctx, vtx_pos[None], pos_idx, vtx_col, 16)

rng = np.random.RandomState(0)
pos_opt = torch.tensor(vtx_pos.cpu().numpy() + rng.uniform(-0.1, 0.1, size=(4, 4)) *
                       np.array([1, 1, 0, 0]), dtype=torch.float32, device=device,
                       requires_grad=True)
col_opt = torch.tensor(rng.uniform(0.0, 1.0, size=(4, 3)), dtype=torch.float32, device=device,
                       requires_grad=True)
optimizer = torch.optim.Adam([pos_opt, col_opt], lr=2e-2)
losses = []
for it in range(25):
    color_opt = render(glctx, pos_opt[None], pos_idx, col_opt, 16)
    loss = torch.mean((target - color_opt) ** 2)
    optimizer.zero_grad()
    loss.backward()
    optimizer.step()
    losses.append(float(loss))
'''


def test_an_nvdiffrast_sample_runs_with_only_the_import_changed(glctx):
    source = SAMPLE.replace("import nvdiffrast.torch as dr", "import softvk.nvdiffrast.torch as dr")
    assert source != SAMPLE
    scope = {"device": "cpu"}
    exec(compile(source, "nvdiffrast-style sample", "exec"), scope)
    losses = scope["losses"]
    assert all(np.isfinite(losses))
    assert losses[-1] < 0.3 * losses[0], losses
    assert scope["pos_opt"].grad is not None and float(scope["pos_opt"].grad.abs().sum()) > 0


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device to put tensors on")
def test_cuda_tensors_come_back_on_cuda_with_the_cpu_results(glctx):
    pos = f32([TRI_POS])
    tri = i32(TRI)
    col = f32([[1, 0, 0], [0, 1, 0], [0, 0, 1]])

    def run(device):
        p = pos.to(device).requires_grad_()
        rast, rast_db = dr.rasterize(glctx, p, tri.to(device), (4, 4))
        out, _ = dr.interpolate(col.to(device), rast, tri.to(device))
        aa = dr.antialias(out, rast, p, tri.to(device))
        aa.sum().backward()
        assert rast.device == rast_db.device == aa.device == p.grad.device == p.device
        return aa.cpu(), p.grad.cpu()

    for a, b in zip(run("cpu"), run("cuda")):
        assert torch.equal(a, b)


def test_a_forked_child_gets_the_clear_error_and_the_parent_carries_on(glctx):
    pos, tri = f32([TRI_POS]), i32(TRI)
    rast, _ = dr.rasterize(glctx, pos, tri, (4, 4))  # the parent has the device open
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: report what happened, then leave without any clean-up
        try:
            dr.rasterize(glctx, pos, tri, (4, 4))
            message = "rendered"
        except RuntimeError as e:
            message = str(e)
        os.write(write, message.encode())
        os._exit(0)
    os.close(write)
    message = os.read(read, 4096).decode()
    os.close(read)
    os.waitpid(pid, 0)
    assert "was forked from process" in message, message
    assert torch.equal(dr.rasterize(glctx, pos, tri, (4, 4))[0], rast)


# ---------------------------------------------------------------------------------------------
# Determinism.


def test_the_same_inputs_give_the_same_bytes_twice(glctx):
    quad = [[-0.61, -0.53, 0.1, 1.0], [0.57, -0.66, 0.2, 1.1], [0.63, 0.59, 0.0, 0.9],
            [-0.55, 0.62, 0.1, 1.0]]
    tri = i32([[0, 1, 2], [0, 2, 3]])
    attr = f32([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]])
    weights = torch.rand(1, 12, 12, 3, generator=torch.Generator().manual_seed(4))

    def run():
        pos = f32([quad]).requires_grad_()
        col = attr.clone().requires_grad_()
        rast, rast_db = dr.rasterize(glctx, pos, tri, (12, 12))
        out, da = dr.interpolate(col, rast, tri, rast_db=rast_db, diff_attrs="all")
        aa = dr.antialias(out, rast, pos, tri)
        ((aa * weights).sum() + da.sum()).backward()
        return [t.detach().numpy().tobytes() for t in (rast, rast_db, out, da, aa, pos.grad,
                                                       col.grad)]

    assert run() == run()
