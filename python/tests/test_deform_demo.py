"""The deformation demo (python/examples/deform.py), SoftRas's script through the compatible
module, fits a sphere to 24 generated silhouettes of spot."""

import importlib.util

from conftest import REPO


def load_example(name):
    spec = importlib.util.spec_from_file_location(name, REPO / "python" / "examples" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_deformation_demo_fits_a_sphere_to_24_silhouettes(gpu, assets, tmp_path):
    deform = load_example("deform")
    lines = []
    iou = deform.fit(
        assets / "spot_triangulated.obj", assets / "sphere_1352.obj", size=32, views=24,
        iters=200, log_every=100, out=tmp_path / "fit.obj", log=lines.append,
    )
    ious = [float(line.split("mean IoU ")[1].split()[0].rstrip(",")) for line in lines]
    # It learned: from the template sphere's IoU, through the log after 100 iterations, to the
    # end (measured: 0.466, 0.864, 0.946).
    assert ious[0] < 0.6 and ious[0] < ious[1] < iou, lines
    assert iou >= 0.9, lines
    assert (tmp_path / "fit.obj").read_text().count("\nf ") == 2700
