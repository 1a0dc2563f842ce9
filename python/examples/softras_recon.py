"""Runs SoftRas's own single-view reconstruction scripts (``examples/recon`` of a SoftRas checkout,
unmodified) through softvk's SoftRas-compatible module, on a dataset that ``softvk dataset``
wrote, and exports its predictions in the layout ``softvk eval-recon --predicted`` reads.

    python python/examples/softras_recon.py train --softras ~/SoftRas -- \\
        -eid small -dd /tmp/srds -md /tmp/softras-models -cls 02691156,03001627 \\
        -b 16 -ni 300 -pf 50 -df 1000000 -sf 300
    python python/examples/softras_recon.py test --softras ~/SoftRas -- \\
        -eid small -d /tmp/softras-models/small/checkpoint_0000300.pth.tar -dd /tmp/srds -cls ...
    python python/examples/softras_recon.py predict --softras ~/SoftRas \\
        --checkpoint /tmp/softras-models/small/checkpoint_0000300.pth.tar \\
        --dataset-directory /tmp/srds --class-ids 02691156,03001627 --out /tmp/softras-pred

``train`` and ``test`` run SoftRas's ``train.py`` / ``test.py`` with the arguments after ``--``
(SoftRas's own: ``-dd`` dataset directory, ``-cls`` class ids, ``-b`` batch size, ``-ni``
iterations, ``-lr`` learning rate, ``-md`` model directory, ``-eid`` experiment id, ...).
``predict`` loads a SoftRas checkpoint into SoftRas's ``models.Model``, runs its evaluation
(``Model.evaluate_iou``) on every view of every object of a split, prints SoftRas's mean IoU per
class as ``test.py`` computes it, and writes ``OUT/<class>_<split>_predicted_voxels.npz``: array
``arr_0``, uint8 0/1, shape (N, 24, 32, 32, 32), the prediction from view v of object n, in the
dataset's voxel order.

Three things make the unmodified scripts run here:
- ``import soft_renderer`` (and ``soft_renderer.functional`` and the other submodules) resolves to
  ``softvk.soft_renderer``;
- without CUDA, ``.cuda()`` on tensors and modules returns them unchanged, the ``torch.cuda``
  seeding and synchronization calls do nothing, and ``torch.load`` maps to the CPU;
- the scripts run from the checkout's root, as SoftRas's README runs them (they open
  ``data/obj/sphere/sphere_642.obj`` relative to it), so their path arguments are made absolute
  against the directory the launcher was started from first.
"""

import argparse
import importlib
import os
import pkgutil
import runpy
import sys
import time

import numpy as np
import torch

# SoftRas's path options, per script: made absolute before the scripts run from the checkout.
PATH_OPTIONS = {
    "train": ("-dd", "--dataset-directory", "-md", "--model-directory", "-r", "--resume-path"),
    "test": ("-dd", "--dataset-directory", "-d", "--model-directory", "-img", "--image-path"),
}

VOXEL_SIZE = 32
VIEWS = 24


def install_soft_renderer():
    """Makes ``soft_renderer`` and every ``soft_renderer.<sub>`` module name resolve to softvk's
    ``softvk.soft_renderer`` counterparts (the same module objects)."""
    import softvk.soft_renderer as package

    names = ["softvk.soft_renderer"]
    for info in pkgutil.walk_packages(package.__path__, "softvk.soft_renderer."):
        names.append(info.name)
    for name in names:
        module = importlib.import_module(name)
        sys.modules["soft_renderer" + name[len("softvk.soft_renderer"):]] = module
    return package


def _returns_self(self, *args, **kwargs):
    return self


def _does_nothing(*args, **kwargs):
    return None


def install_cpu_cuda():
    """Without CUDA, turns the CUDA calls SoftRas's scripts make into no-ops: ``.cuda()`` of
    tensors and modules returns them where they are, ``torch.cuda`` seeding and synchronization do
    nothing, and ``torch.load`` reads CUDA-saved checkpoints onto the CPU. With CUDA, nothing
    changes. Returns whether it patched."""
    if torch.cuda.is_available():
        return False
    torch.Tensor.cuda = _returns_self
    torch.nn.Module.cuda = _returns_self
    for name in ("manual_seed", "manual_seed_all", "synchronize", "empty_cache"):
        setattr(torch.cuda, name, _does_nothing)
    load = torch.load

    def load_on_cpu(f, map_location=None, *args, **kwargs):
        return load(f, map_location="cpu" if map_location is None else map_location, *args, **kwargs)

    torch.load = load_on_cpu
    return True


def absolute_paths(argv, options, start):
    """``argv`` with the values of ``options`` (``-x VALUE`` or ``--xx=VALUE``) made absolute
    against ``start``."""
    out = []
    take = False
    for arg in argv:
        if take:
            out.append(os.path.join(start, arg) if arg else arg)
            take = False
        elif arg in options:
            out.append(arg)
            take = True
        elif "=" in arg and arg.split("=", 1)[0] in options:
            key, value = arg.split("=", 1)
            out.append(key + "=" + (os.path.join(start, value) if value else value))
        else:
            out.append(arg)
    return out


def enter_checkout(softras):
    """Prepares the process to run SoftRas's ``examples/recon`` files: the module shims, the
    recon folder first on ``sys.path`` (its scripts import ``models``, ``datasets``, ...), and the
    checkout's root as the working directory. Returns the recon folder."""
    softras = os.path.abspath(softras)
    recon = os.path.join(softras, "examples", "recon")
    if not os.path.isfile(os.path.join(recon, "models.py")):
        raise SystemExit("%s is not a SoftRas checkout (no examples/recon/models.py)" % softras)
    install_soft_renderer()
    install_cpu_cuda()
    sys.path.insert(0, recon)
    os.chdir(softras)
    return recon


def run_script(softras, script, argv):
    """Runs SoftRas's ``examples/recon/<script>.py`` as ``__main__`` with ``argv``."""
    start = os.getcwd()
    argv = absolute_paths(argv, PATH_OPTIONS.get(script, ()), start)
    recon = enter_checkout(softras)
    path = os.path.join(recon, script + ".py")
    sys.argv = [path] + argv
    runpy.run_path(path, run_name="__main__")


def dataset_order(voxels):
    """SoftRas's voxelization (``[batch, x, y, z]``, of faces scaled by 31/32 and shifted by 0.5)
    in the dataset's voxel order, as ``evaluate_iou`` compares them: the dataset's ``[a][b][c]`` is
    the voxelization's ``[x = b][y = a][z = 31 - c]``."""
    return np.ascontiguousarray(np.asarray(voxels).transpose(0, 2, 1, 3)[:, :, :, ::-1])


def evaluate_with_voxels(model, images, voxels, srf):
    """SoftRas's ``model(images, voxels=voxels, task='test')``, and the voxels its evaluation
    computed, in the dataset's order: ``srf.voxelization`` is observed during the call, so the
    voxels are the very ones SoftRas scored. Returns (per-image IoU, uint8 voxels)."""
    seen = []
    voxelization = srf.voxelization

    def observed(*args, **kwargs):
        out = voxelization(*args, **kwargs)
        seen.append(out)
        return out

    srf.voxelization = observed
    try:
        with torch.no_grad():
            iou, _, _ = model(images, voxels=voxels, task="test")
    finally:
        srf.voxelization = voxelization
    if len(seen) != 1:
        raise RuntimeError("the evaluation voxelized %d times; expected once" % len(seen))
    predicted = dataset_order(seen[0].cpu().numpy()) != 0
    return np.asarray(iou), predicted.astype(np.uint8)


def predict(args):
    start = os.getcwd()
    out_dir = os.path.join(start, args.out)
    checkpoint = os.path.join(start, args.checkpoint)
    dataset_dir = os.path.join(start, args.dataset_directory)
    enter_checkout(args.softras)
    import soft_renderer.functional as srf
    import datasets
    import models

    model = models.Model("data/obj/sphere/sphere_642.obj", args=args).cuda()
    state = torch.load(checkpoint)
    model.load_state_dict(state["model"], strict=False)
    model.eval()
    dataset = datasets.ShapeNet(dataset_dir, args.class_ids.split(","), args.split)
    os.makedirs(out_dir, exist_ok=True)

    means = []
    for class_id, class_name in dataset.class_ids_pair:
        t0 = time.time()
        ious, predicted = [], []
        for images, voxels in dataset.get_all_batches_for_evaluation(args.batch_size, class_id):
            iou, vox = evaluate_with_voxels(model, images.cuda(), voxels.numpy(), srf)
            # Our voxels scored against the dataset's the way SoftRas does give its IoU back.
            truth = voxels.numpy()
            again = (truth * vox).sum((1, 2, 3)) / (0 < (truth + vox)).sum((1, 2, 3))
            if not np.allclose(again, iou, atol=1e-6, equal_nan=True):
                raise RuntimeError("the exported voxels do not give SoftRas's IoU back")
            ious.append(iou)
            predicted.append(vox)
        n = dataset.num_data[class_id]
        predicted = np.concatenate(predicted).reshape(n, VIEWS, VOXEL_SIZE, VOXEL_SIZE, VOXEL_SIZE)
        path = os.path.join(out_dir, "%s_%s_predicted_voxels.npz" % (class_id, args.split))
        np.savez_compressed(path, arr_0=predicted)
        # test.py's figure: the IoUs summed over every view of every object, in percent.
        mean = float(np.concatenate(ious).sum()) / VIEWS / n * 100
        means.append(mean)
        print("Mean IoU: %.3f for class %s (%s, %d objects x %d views, %.1f s) -> %s"
              % (mean, class_name, class_id, n, VIEWS, time.time() - t0, path))
    print("Mean IoU: %.3f for all classes" % (sum(means) / len(means)))


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in ("train", "test"):
        p = sub.add_parser(name, help="run SoftRas's examples/recon/%s.py; its arguments after --" % name)
        p.add_argument("--softras", required=True, help="a SoftRas checkout")
        p.add_argument("script_args", nargs=argparse.REMAINDER)
    p = sub.add_parser("predict", help="export a checkpoint's test predictions as voxels")
    p.add_argument("--softras", required=True, help="a SoftRas checkout")
    p.add_argument("--checkpoint", required=True, help="a checkpoint train.py saved")
    p.add_argument("-dd", "--dataset-directory", required=True)
    p.add_argument("-cls", "--class-ids", required=True, help="comma-separated class ids")
    p.add_argument("--out", required=True, help="folder for <class>_<split>_predicted_voxels.npz")
    p.add_argument("--split", default="test")
    p.add_argument("-bs", "--batch-size", type=int, default=96)
    p.add_argument("-is", "--image-size", type=int, default=64)
    p.add_argument("-sv", "--sigma-val", type=float, default=1e-4)
    args = parser.parse_args(argv)
    if args.command == "predict":
        predict(args)
    else:
        rest = args.script_args
        if rest[:1] == ["--"]:
            rest = rest[1:]
        run_script(args.softras, args.command, rest)


if __name__ == "__main__":
    main()
