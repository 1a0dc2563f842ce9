"""softvk across processes and threads: torchrun ranks, forked children (DataLoader workers),
concurrent threads, and a machine with no Vulkan driver."""

import os
import subprocess
import sys
import threading

import numpy as np
import pytest
import torch

import softvk
import softvk.torch as st
from conftest import REPO


def scene(seed, batch=2, faces=30):
    rng = np.random.default_rng(seed)
    fv = np.concatenate(
        [rng.uniform(-0.9, 0.9, (batch, faces, 3, 2)), rng.uniform(2, 4, (batch, faces, 3, 1))], -1
    )
    return torch.tensor(fv, dtype=torch.float32), torch.rand(batch, faces, 4, 3, generator=torch.Generator().manual_seed(seed))


def render_with_grad(fv, tex):
    fv = fv.clone().requires_grad_(True)
    image = st.soft_rasterize(fv, tex, image_size=32, sigma_val=1e-3, gamma_val=1e-2)
    (image * image.detach()).sum().backward()
    return image.detach(), fv.grad


def test_two_torchrun_ranks_end_with_identical_parameters(gpu, tmp_path):
    # Debian's torch 1.13 under Python 3.11 cannot parse torchrun's default "--redirects 0"
    # (an enum change of 3.11); any other setting works, and newer torch has no such problem.
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--redirects", "1", "--tee", "1",
        "--log_dir", str(tmp_path / "logs"), "--nproc_per_node", "2", "--master_port", "29517",
        str(REPO / "python" / "examples" / "ddp_fit.py"), "--iters", "12", "--out", str(tmp_path),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    ranks = [torch.load(tmp_path / f"rank{r}.pt") for r in range(2)]
    assert ranks[0].keys() == ranks[1].keys()
    for name in ranks[0]:
        assert torch.equal(ranks[0][name], ranks[1][name]), name
    # They trained: the displacements moved, and the two ranks saw different views.
    assert ranks[0]["displace"].abs().max() > 1e-3
    losses = [torch.load(tmp_path / f"loss{r}.pt").item() for r in range(2)]
    assert losses[0] != losses[1]


def test_a_forked_child_cannot_touch_its_parents_device(gpu):
    fv, tex = scene(1)
    st.soft_rasterize(fv, tex, image_size=16)  # the parent has opened the device
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: report what happened, then leave without any clean-up
        try:
            st.soft_rasterize(fv, tex, image_size=16)
            message = "rendered"
        except RuntimeError as e:
            message = str(e) if softvk.is_forked_child() else "is_forked_child() is False"
        os.write(write, message.encode())
        os._exit(0)
    os.close(write)
    message = os.read(read, 4096).decode()
    os.waitpid(pid, 0)
    assert "was forked from process" in message and "fork()" in message, message
    # The parent carries on.
    assert not softvk.is_forked_child()
    st.soft_rasterize(fv, tex, image_size=16)


class Renders(torch.utils.data.Dataset):
    def __len__(self):
        return 2

    def __getitem__(self, i):
        fv, tex = scene(i)
        return st.soft_rasterize(fv, tex, image_size=16)


def test_a_forked_dataloader_worker_gets_the_clear_error(gpu):
    st.soft_rasterize(*scene(0), image_size=16)
    loader = torch.utils.data.DataLoader(Renders(), num_workers=1, multiprocessing_context="fork")
    with pytest.raises(RuntimeError, match="was forked from process"):
        next(iter(loader))


FORK_BEFORE_ANY_RENDER = """
import os, sys, numpy as np, torch
sys.path.insert(0, {tests!r})
from test_processes import scene, render_with_grad
pid = os.fork()
image, grad = render_with_grad(*scene(3))
if pid == 0:
    np.save({child!r}, np.concatenate([image.numpy().ravel(), grad.numpy().ravel()]))
    os._exit(0)
os.waitpid(pid, 0)
np.save({parent!r}, np.concatenate([image.numpy().ravel(), grad.numpy().ravel()]))
"""


def test_a_child_forked_before_any_render_opens_its_own_device(gpu, tmp_path):
    code = FORK_BEFORE_ANY_RENDER.format(
        tests=str(REPO / "python" / "tests"),
        child=str(tmp_path / "child.npy"),
        parent=str(tmp_path / "parent.npy"),
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    np.testing.assert_array_equal(np.load(tmp_path / "child.npy"), np.load(tmp_path / "parent.npy"))


def test_concurrent_renders_from_two_threads_equal_sequential_ones(gpu):
    scenes = [scene(s, batch=3, faces=60) for s in (5, 6)]
    sequential = [render_with_grad(*s) for s in scenes]
    results = [None, None]

    def work(i):
        for _ in range(3):
            results[i] = render_with_grad(*scenes[i])

    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for (image, grad), (seq_image, seq_grad) in zip(results, sequential):
        assert torch.equal(image, seq_image) and torch.equal(grad, seq_grad)


def test_no_vulkan_driver_is_one_clear_exception(tmp_path):
    # A loader that finds no driver (the ICD list points at nothing): the first render says
    # what to install, as one RuntimeError.
    code = "import torch, softvk.torch as st; st.soft_rasterize(torch.zeros(1, 1, 3, 3), torch.ones(1, 1, 1, 3))"
    env = dict(os.environ, VK_ICD_FILENAMES=str(tmp_path / "none.json"), VK_DRIVER_FILES=str(tmp_path / "none.json"))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode != 0
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("RuntimeError: softvk: "), done.stderr
    assert "mesa-vulkan-drivers" in last or "driver" in last, last
