"""Tensors on other devices (CUDA's): softvk's engine reads host copies, and every result
comes back on its input's device and with its dtype, through one function of the package,
``softvk._host.round_trip``.

On any machine: that function is the only place on the engine's path where a tensor crosses
to the host or back (``Tensor.cpu``, ``Tensor.numpy`` and ``torch.from_numpy`` are called
nowhere else), for every interface (``softvk.torch``, ``softvk.soft_renderer``,
``softvk.pytorch3d``, ``softvk.nvdiffrast.torch``), and what comes back has its input's device,
dtype and shape. Where torch sees a CUDA device: every interface on ``.cuda()`` tensors against
the same on the CPU, bit for bit, outputs and gradients. No CUDA machine has run those yet.
"""

import sys

import numpy as np
import pytest
import torch

import softvk.nvdiffrast.torch as dr
import softvk.pytorch3d as sp
import softvk.soft_renderer as sr
import softvk.torch as st

SIZE = 16
needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")


def leaf(values, device, dtype=None):
    """``values`` as a tensor on ``device`` that requires a gradient (a leaf there)."""
    return values.to(device=device, dtype=dtype or values.dtype).detach().requires_grad_(True)


def weights(shape, dtype, device, seed=7):
    return torch.rand(shape, generator=torch.Generator().manual_seed(seed),
                      dtype=dtype).to(device)


def quad(batch=2):
    base = torch.tensor([[-0.6, -0.5, 0.0], [0.5, -0.6, 0.1], [0.6, 0.5, 0.0], [-0.5, 0.6, -0.1]])
    return (torch.stack([base * (1 - 0.1 * b) for b in range(batch)]),
            torch.tensor([[0, 1, 2], [0, 2, 3]]))


def textures(batch=2, faces=2, seed=1):
    return torch.rand(batch, faces, 4, 3, generator=torch.Generator().manual_seed(seed))


# Each interface: run(device, dtype) -> (inputs, outputs), its loss backpropagated; the inputs
# are the leaves whose gradients it computes.


def run_soft_rasterize(device, dtype):
    vertices, faces = quad()
    fv = leaf(vertices[:, faces] + torch.tensor([0.0, 0.0, 2.0]), device, dtype)
    tex = leaf(textures(), device, dtype)
    images = st.soft_rasterize(fv, tex, image_size=SIZE, sigma_val=1e-4)
    (images * weights(images.shape, dtype, device)).sum().backward()
    return [fv, tex], [images]


def run_render_mesh(device, dtype):
    vertices, faces = quad()
    v, tex = leaf(vertices, device), leaf(textures(), device)
    eyes = leaf(torch.tensor([[0.3, 0.4, -2.5], [-0.2, 0.5, -2.6]]), device)
    images = st.render_mesh(v, faces.to(device), tex, eyes=eyes, image_size=SIZE,
                            sigma_val=1e-4)
    (images * weights(images.shape, torch.float32, device)).sum().backward()
    return [v, tex, eyes], [images]


def run_soft_renderer(device, dtype):
    """The engine's path in float32, the composed steps in float64; and the alpha-only render."""
    vertices, faces = quad()
    v, tex = leaf(vertices, device, dtype), leaf(textures(), device, dtype)
    renderer = sr.SoftRenderer(image_size=SIZE, camera_mode="look_at", sigma_val=1e-4)
    renderer.transform.set_eyes([0.3, 0.4, -2.5])
    mesh = sr.Mesh(v, faces.to(device).expand(2, -1, -1), tex)
    images = renderer.render_mesh(mesh)
    alpha = st.render(renderer, mesh, "silhouettes")
    ((images * weights(images.shape, dtype, device)).sum()
     + (alpha * weights(alpha.shape, dtype, device, seed=8)).sum()).backward()
    return [v, tex], [images, alpha]


class Packed:
    """PyTorch3D's packed meshes, as ``rasterize_meshes`` reads them."""

    def __init__(self, verts, faces, counts):
        self.verts, self.faces, self.counts = verts, faces, counts

    def verts_packed(self):
        return self.verts

    def faces_packed(self):
        return self.faces

    def mesh_to_faces_packed_first_idx(self):
        return torch.tensor([0, self.counts[0]], device=self.verts.device)

    def num_faces_per_mesh(self):
        return torch.tensor(self.counts, device=self.verts.device)


def run_pytorch3d(device, dtype):
    vertices, faces = quad()
    verts = leaf((vertices + torch.tensor([0.0, 0.0, 2.0])).reshape(-1, 3), device, dtype)
    packed = torch.cat([faces, faces + 4]).to(device)
    out = sp.rasterize_meshes(Packed(verts, packed, [2, 2]), image_size=SIZE,
                              faces_per_pixel=2, blur_radius=1e-3)
    _, zbuf, bary, dists = out
    ((zbuf * weights(zbuf.shape, dtype, device)).sum() + bary.sum()
     + (dists * weights(dists.shape, dtype, device, seed=8)).sum()).backward()
    return [verts], list(out)


def run_nvdiffrast(device, dtype):
    pos = leaf(torch.tensor([[[-0.8, -0.7, 0.1, 1.0], [0.7, -0.8, 0.2, 1.0], [0.8, 0.7, 0.3, 1.0],
                              [-0.7, 0.8, 0.2, 1.0]]]), device)
    tri = torch.tensor([[0, 1, 2], [0, 2, 3]], dtype=torch.int32, device=device)
    uv = leaf(torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), device)
    tex = leaf(torch.rand(1, 8, 8, 3, generator=torch.Generator().manual_seed(2)), device)
    glctx = dr.RasterizeCudaContext()
    rast, rast_db = dr.rasterize(glctx, pos, tri, resolution=(SIZE, SIZE))
    texc, texd = dr.interpolate(uv, rast, tri, rast_db=rast_db, diff_attrs="all")
    color = dr.texture(tex, texc, texd, filter_mode="linear-mipmap-linear")
    color = dr.antialias(color, rast, pos, tri)
    (color * weights(color.shape, torch.float32, device)).sum().backward()
    return [pos, uv, tex], [rast, rast_db, texc, texd, color]


INTERFACES = {
    "softvk.torch.soft_rasterize": (run_soft_rasterize, (torch.float32, torch.float64)),
    "softvk.torch.render_mesh": (run_render_mesh, (torch.float32,)),
    "softvk.soft_renderer": (run_soft_renderer, (torch.float32, torch.float64)),
    "softvk.pytorch3d": (run_pytorch3d, (torch.float32, torch.float64)),
    "softvk.nvdiffrast.torch": (run_nvdiffrast, (torch.float32,)),
}
CASES = [(name, dtype) for name, (_, dtypes) in INTERFACES.items() for dtype in dtypes]
IDS = [f"{name}-{str(dtype)[6:]}" for name, dtype in CASES]


@pytest.mark.parametrize("name,dtype", CASES, ids=IDS)
def test_every_host_copy_on_the_engine_s_path_is_the_round_trip_s(gpu, monkeypatch, name,
                                                                  dtype):
    run = INTERFACES[name][0]
    crossings = []

    def watched(what, original):
        def spy(*args, **kwargs):
            frame, inside = sys._getframe(1), False
            caller = f"{frame.f_code.co_filename}:{frame.f_lineno}"
            while frame is not None and not inside:
                code = frame.f_code
                inside = code.co_name == "round_trip" and code.co_filename.endswith("_host.py")
                frame = frame.f_back
            crossings.append((what, inside, caller))
            return original(*args, **kwargs)
        return spy

    monkeypatch.setattr(torch.Tensor, "cpu", watched("Tensor.cpu", torch.Tensor.cpu))
    monkeypatch.setattr(torch.Tensor, "numpy", watched("Tensor.numpy", torch.Tensor.numpy))
    monkeypatch.setattr(torch, "from_numpy", watched("torch.from_numpy", torch.from_numpy))
    run("cpu", dtype)
    outside = [(what, caller) for what, inside, caller in crossings if not inside]
    assert not outside, outside
    assert any(inside for _, inside, _ in crossings)


@pytest.mark.parametrize("name,dtype", CASES, ids=IDS)
def test_results_and_gradients_have_their_input_s_device_and_dtype(gpu, name, dtype):
    inputs, outputs = INTERFACES[name][0]("cpu", dtype)
    for t in inputs:
        assert t.grad is not None
        assert (t.grad.device, t.grad.dtype, t.grad.shape) == (t.device, t.dtype, t.shape)
    for out in outputs:
        assert out.device == inputs[0].device
        assert out.dtype in (inputs[0].dtype, torch.int64)


def test_round_trip_takes_host_copies_and_brings_each_result_where_it_says():
    from softvk._host import Like, like, round_trip

    meta = torch.device("meta")  # a device other than the host's, on any machine
    x = torch.arange(6, dtype=torch.float64).reshape(2, 3).t()  # not contiguous
    index = torch.tensor([1, 2], dtype=torch.int32)
    seen = []

    def call(a, b, settings, arrays, handle):
        seen.append((a, b, settings, arrays, handle))
        return a * 2, np.arange(3, dtype=np.int64), "handle", [a.T.copy(), None]

    doubled, counted, handle, listed = round_trip(
        call, x, index, ("settings", 1), [x], None,
        back=(Like(meta, torch.float32, (6,)), like(index, dtype=False), None,
              [Like(meta, None, None), like(x)]),
    )
    a, b, settings, arrays, none = seen[0]
    assert isinstance(a, np.ndarray) and a.flags.c_contiguous and a.dtype == np.float64
    np.testing.assert_array_equal(a, x.numpy())
    assert b.dtype == np.int32 and settings == ("settings", 1) and none is None
    assert isinstance(arrays, list) and isinstance(arrays[0], np.ndarray)
    assert (doubled.device, doubled.dtype, tuple(doubled.shape)) == (meta, torch.float32, (6,))
    assert (counted.device, counted.dtype) == (index.device, torch.int64)
    assert handle == "handle"
    assert (listed[0].device, listed[0].dtype, tuple(listed[0].shape)) == (meta, torch.float64,
                                                                           (2, 3))
    assert listed[1] is None


@needs_cuda
@pytest.mark.parametrize("name,dtype", CASES, ids=IDS)
def test_cuda_tensors_give_the_cpu_s_bits(gpu, name, dtype):
    run = INTERFACES[name][0]
    cpu_inputs, cpu_outputs = run("cpu", dtype)
    cuda_inputs, cuda_outputs = run("cuda", dtype)
    for got, want in zip(cuda_outputs, cpu_outputs):
        assert got.device.type == "cuda" and got.dtype == want.dtype
        assert torch.equal(got.detach().cpu(), want.detach())
    for got, want in zip(cuda_inputs, cpu_inputs):
        assert got.grad.device.type == "cuda" and got.grad.dtype == want.grad.dtype
        assert torch.equal(got.grad.cpu(), want.grad)
