"""Reading texture images and writing PNGs, without an imaging library as a dependency.

SoftRas used scikit-image; numpy is softvk's one required dependency. PNGs are read and written
by the native module (the ``image`` crate, as ``softvk render`` reads textures); other formats
are read with Pillow when it is installed.
"""

import numpy as np

from ... import _native


def read_rgb(path):
    """The image at ``path`` as float32 [H, W, 3] in [0, 1], row 0 at the top.

    Grey is replicated to RGB and alpha dropped, as SoftRas's texture loader does.
    """
    with open(path, "rb") as f:
        is_png = f.read(8) == b"\x89PNG\r\n\x1a\n"
    if is_png:
        return _native.read_rgb(str(path))
    try:
        from PIL import Image
    except ImportError:
        raise ValueError("%s: not a PNG; install Pillow to read other image formats" % path)
    with Image.open(path) as image:
        return np.asarray(image.convert("RGB"), dtype=np.float32) / 255.0


def write_png(path, image):
    """Writes uint8 [H, W, 3] (or [H, W], [H, W, 4]) as an 8-bit PNG."""
    _native.write_png(str(path), np.ascontiguousarray(image, dtype=np.uint8))
