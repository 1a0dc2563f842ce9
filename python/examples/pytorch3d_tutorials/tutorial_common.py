"""What the PyTorch3D tutorial scripts here share: the rasterizer switch, the forward timer, the
target mesh (spot, normalised as the mesh-fitting tutorial normalises its cow) and PNG output."""

import os
import pathlib
import sys
import time

import numpy as np
from pytorch3d.io import load_objs_as_meshes

ASSETS = pathlib.Path(
    os.environ.get("SOFTVK_ASSETS") or pathlib.Path(__file__).resolve().parents[3] / "assets"
)


def rasterizer_class(name):
    """The MeshRasterizer class to use: softvk's drop-in replacement or PyTorch3D's."""
    if name == "softvk":
        from softvk.pytorch3d import MeshRasterizer
    else:
        from pytorch3d.renderer import MeshRasterizer
    return MeshRasterizer


class ForwardTimer:
    """Accumulates the seconds spent in the ``forward`` of the modules it wraps."""

    def __init__(self):
        self.seconds = 0.0
        self.calls = 0

    def wrap(self, module):
        inner = module.forward

        def forward(*args, **kwargs):
            start = time.perf_counter()
            try:
                return inner(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - start
                self.calls += 1

        module.forward = forward  # an instance attribute: nn.Module.__call__ finds it first
        return module


def load_spot(device):
    """Spot with its texture, centred on its vertex mean and divided by its largest absolute
    coordinate, as the tutorial normalises the cow; also the centre and scale."""
    mesh = load_objs_as_meshes([str(ASSETS / "spot_triangulated.obj")], device=device)
    verts = mesh.verts_packed()
    center = verts.mean(0)
    scale = (verts - center).abs().max()
    mesh.offset_verts_(-center)
    mesh.scale_verts_(1.0 / float(scale))
    return mesh, center, scale


def save_png(path, rows):
    """Writes a grid of images in [0, 1] (H x W grayscale or H x W x 3) with Pillow, if any."""
    try:
        from PIL import Image
    except ImportError:
        print(f"Pillow is not installed: not writing {path}", file=sys.stderr)
        return

    def rgb(im):
        im = np.clip(im, 0.0, 1.0)
        return np.repeat(im[..., None], 3, axis=-1) if im.ndim == 2 else im

    grid = np.concatenate([np.concatenate([rgb(im) for im in row], axis=1) for row in rows], axis=0)
    Image.fromarray((grid * 255).round().astype(np.uint8)).save(path)
    print(f"wrote {path}", file=sys.stderr)
