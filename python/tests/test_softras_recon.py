"""The pieces of python/examples/softras_recon.py that are softvk's: the launcher that runs
SoftRas's unmodified reconstruction scripts (module redirection, CUDA no-ops on a CPU machine,
paths), and the export of SoftRas's evaluation voxels in the dataset's order. SoftRas's own code
is not here; stand-ins written by the tests take its place."""

import importlib.util
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import torch

import softvk
import softvk.soft_renderer.functional as srf
from conftest import REPO

LAUNCHER = REPO / "python" / "examples" / "softras_recon.py"


def load_launcher():
    spec = importlib.util.spec_from_file_location("softras_recon", LAUNCHER)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# A stand-in for SoftRas's train.py: the imports, CUDA calls and relative paths its scripts use.
STAND_IN_TRAIN = """
import argparse, json, os
import torch
import soft_renderer as sr
import soft_renderer.functional as srf
from soft_renderer.functional.voxelization import voxelization
import models  # from examples/recon, as SoftRas's scripts import theirs

parser = argparse.ArgumentParser()
parser.add_argument('-dd', '--dataset-directory', type=str)
parser.add_argument('-md', '--model-directory', type=str)
parser.add_argument('-b', '--batch-size', type=int)
args = parser.parse_args()

torch.backends.cudnn.deterministic = True
torch.cuda.manual_seed_all(0)
model = torch.nn.Linear(3, 2).cuda()
x = torch.ones(1, 3).cuda()
y = torch.autograd.Variable(x).cuda()
template = sr.Mesh.from_obj('data/obj/tetra.obj')  # relative to the checkout, as SoftRas's
os.makedirs(args.model_directory, exist_ok=True)
with open(os.path.join(args.model_directory, 'report.json'), 'w') as f:
    json.dump({
        'sr': sr.__name__, 'srf': srf.__name__, 'voxelization': voxelization.__module__,
        'models': models.NAME, 'device': str(model(y).device), 'batch': args.batch_size,
        'faces': int(template.faces.shape[1]), 'dataset': args.dataset_directory,
    }, f)
"""


def test_the_launcher_runs_a_softras_script_on_softvk_without_cuda(tmp_path):
    checkout = tmp_path / "SoftRas"
    recon = checkout / "examples" / "recon"
    recon.mkdir(parents=True)
    (recon / "train.py").write_text(STAND_IN_TRAIN)
    (recon / "models.py").write_text("NAME = 'stand-in models'\n")
    (checkout / "data" / "obj").mkdir(parents=True)
    (checkout / "data" / "obj" / "tetra.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    )
    work = tmp_path / "work"
    work.mkdir()
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(pathlib.Path(softvk.__file__).parents[1])]
                                        + [p for p in [env.get("PYTHONPATH")] if p])
    env["CUDA_VISIBLE_DEVICES"] = ""  # a CPU machine, even where a CUDA device exists
    run = subprocess.run(
        [sys.executable, str(LAUNCHER), "train", "--softras", str(checkout), "--",
         "-dd", "data/ds", "--model-directory=models/run", "-b", "16"],
        cwd=work, env=env, capture_output=True, text=True, timeout=300,
    )
    assert run.returncode == 0, run.stderr
    # The relative paths were taken against the launcher's directory, not the checkout's.
    report = json.loads((work / "models" / "run" / "report.json").read_text())
    assert report == {
        "sr": "softvk.soft_renderer",
        "srf": "softvk.soft_renderer.functional",
        "voxelization": "softvk.soft_renderer.functional.voxelization",
        "models": "stand-in models",
        "device": "cpu",
        "batch": 16,
        "faces": 4,
        "dataset": str(work / "data" / "ds"),
    }


def box(low, high):
    """An axis-aligned box as (vertices [1, 8, 3], faces [1, 12, 3]), outward faces."""
    corners = torch.tensor(
        [[(high if (i >> k) & 1 else low)[k] for k in range(3)] for i in range(8)],
        dtype=torch.float32,
    )
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return corners[None], torch.tensor(faces, dtype=torch.int32)[None]


def dataset_voxels(low, high):
    """The dataset's voxels of the box (src/recon/dataset.rs): ``[a][b][c]`` is occupied when its
    centre ((b - 15.5)/31, (a - 15.5)/31, (15.5 - c)/31) is inside."""
    n = (np.arange(32) - 15.5) / 31
    a, b, c = np.meshgrid(n, n, -n, indexing="ij")
    centre = np.stack([b, a, c], axis=-1)
    return np.all((centre > low) & (centre < high), axis=-1)


def dilate(v):
    """``v`` grown by one voxel in every direction (the 3×3×3 cube around each voxel)."""
    for axis in range(3):
        v = v | np.roll(v, 1, axis=axis) | np.roll(v, -1, axis=axis)
    return v


# Unequal extents, off centre on every axis: any wrong transpose or flip puts it elsewhere.
LOW, HIGH = np.array([0.05, -0.3, -0.4]), np.array([0.35, 0.1, -0.15])


class StandInModel:
    """A model whose evaluation voxelizes a fixed mesh the way SoftRas's ``evaluate_iou`` does
    (the faces scaled by 31/32 and shifted by 0.5, ``srf.voxelization``, then compared in the
    dataset's order)."""

    def __init__(self, vertices, faces):
        self.vertices, self.faces = vertices, faces

    def __call__(self, images, voxels=None, task="test"):
        n = images.shape[0]
        vertices = self.vertices.expand(n, -1, -1)
        faces = self.faces.expand(n, -1, -1)
        faces_norm = srf.face_vertices(vertices, faces) * (32.0 - 1) / 32.0 + 0.5
        raw = srf.voxelization(faces_norm, 32, False).cpu().numpy()
        ordered = raw.transpose(0, 2, 1, 3)[:, :, :, ::-1]
        iou = (voxels * ordered).sum((1, 2, 3)) / (0 < (voxels + ordered)).sum((1, 2, 3))
        return iou, vertices, faces


def test_the_export_writes_softras_evaluation_voxels_in_the_dataset_order():
    launcher = load_launcher()
    truth = dataset_voxels(LOW, HIGH)
    assert 100 < truth.sum() < 32 ** 3 // 8
    model = StandInModel(*box(LOW, HIGH))
    images = torch.zeros(2, 4, 64, 64)
    iou, predicted = launcher.evaluate_with_voxels(
        model, images, np.stack([truth, truth]).astype(np.float32), srf
    )
    assert predicted.dtype == np.uint8 and predicted.shape == (2, 32, 32, 32)
    assert set(np.unique(predicted)) == {0, 1}
    # SoftRas's voxelization is conservative (every cell the surface touches, then filled), the
    # dataset's counts centres inside: the export holds the dataset's voxels and at most one
    # layer more around them.
    p = predicted[0].astype(bool)
    assert np.all(p[truth]), "a voxel of the box is missing from the export"
    assert not np.any(p & ~dilate(truth)), "the export has voxels away from the box"
    assert np.array_equal(predicted[0], predicted[1])
    # The IoU SoftRas's evaluation reported is that of the exported voxels.
    again = (truth & p).sum() / (truth | p).sum()
    assert np.allclose(iou, again) and again > 0.5


def test_dataset_order_is_the_transpose_and_flip_of_evaluate_iou():
    launcher = load_launcher()
    raw = np.zeros((1, 32, 32, 32), np.int32)
    raw[0, 3, 20, 5] = 1  # x = 3, y = 20, z = 5
    ordered = launcher.dataset_order(raw)
    assert ordered.flags["C_CONTIGUOUS"]
    assert list(zip(*np.nonzero(ordered[0]))) == [(20, 3, 26)]  # [a = y][b = x][c = 31 - z]
