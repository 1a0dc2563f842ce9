"""Reading texture images and writing PNGs without a required imaging library.

SoftRas used scikit-image. numpy is softvk's one required dependency, so textures are read with
Pillow when it is installed (any format it knows) and otherwise with the small PNG decoder
below (8 and 16 bits, every colour type, not interlaced); PNGs are written by the encoder here.
"""

import struct
import zlib

import numpy as np

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def read_rgb(path):
    """The image at ``path`` as float32 [H, W, 3] in [0, 1], row 0 at the top.

    Grey is replicated to RGB and alpha dropped, as SoftRas's texture loader does.
    """
    try:
        from PIL import Image
    except ImportError:
        Image = None
    if Image is None:
        with open(path, "rb") as f:
            data = f.read()
        if not data.startswith(_PNG_SIGNATURE):
            raise ValueError(
                "%s: not a PNG; install Pillow to read other image formats" % path
            )
        return _decode_png(data, path)
    with Image.open(path) as image:
        if image.mode.startswith("I;16") or image.mode == "I":
            grey = np.asarray(image, dtype=np.float32) / 65535.0
            return np.repeat(grey[:, :, None], 3, axis=2)
        if image.mode == "F":
            grey = np.asarray(image, dtype=np.float32)
            return np.repeat(grey[:, :, None], 3, axis=2)
        return np.asarray(image.convert("RGB"), dtype=np.float32) / 255.0


def write_png(path, rgb):
    """Writes uint8 [H, W, 3] (or [H, W]) as an 8-bit PNG."""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    if rgb.ndim == 2:
        rgb = rgb[:, :, None]
    height, width, channels = rgb.shape
    color_type = {1: 0, 3: 2, 4: 6}[channels]
    # Filter type 0 (none) on every row.
    raw = np.concatenate([np.zeros((height, 1), np.uint8), rgb.reshape(height, -1)], axis=1)

    def chunk(kind, payload):
        body = kind + payload
        crc = struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
        return struct.pack(">I", len(payload)) + body + crc

    header = struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(_PNG_SIGNATURE)
        f.write(chunk(b"IHDR", header))
        f.write(chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)))
        f.write(chunk(b"IEND", b""))


def _decode_png(data, path):
    pos = len(_PNG_SIGNATURE)
    idat = []
    palette = None
    header = None
    while pos + 8 <= len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind = data[pos + 4:pos + 8]
        payload = data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", payload)
        elif kind == b"PLTE":
            palette = np.frombuffer(payload, np.uint8).reshape(-1, 3)
        elif kind == b"IDAT":
            idat.append(payload)
        elif kind == b"IEND":
            break
    if header is None:
        raise ValueError("%s: a PNG without a header" % path)
    width, height, depth, color_type, _, _, interlace = header
    channels = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}.get(color_type)
    if channels is None or depth not in (8, 16) or interlace != 0:
        raise ValueError(
            "%s: PNG of bit depth %d, colour type %d%s is not supported without Pillow"
            % (path, depth, color_type, ", interlaced" if interlace else "")
        )
    bpp = channels * depth // 8
    stride = width * bpp
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), np.uint8)
    raw = raw[: height * (stride + 1)].reshape(height, stride + 1)
    rows = _unfilter(raw[:, 0], raw[:, 1:].astype(np.int64), bpp)
    if depth == 16:
        pixels = (rows[:, 0::2] * 256 + rows[:, 1::2]).astype(np.float32) / 65535.0
    else:
        pixels = rows.astype(np.float32)
    pixels = pixels.reshape(height, width, channels)
    if color_type == 3:
        if palette is None:
            raise ValueError("%s: a palette PNG without a palette" % path)
        return palette[pixels[:, :, 0].astype(np.int64)].astype(np.float32) / 255.0
    if depth == 8:
        pixels = pixels / 255.0
    if channels <= 2:
        return np.repeat(pixels[:, :, :1], 3, axis=2)
    return np.ascontiguousarray(pixels[:, :, :3])


def _unfilter(filters, rows, bpp):
    """Undoes the PNG row filters (int64 [H, stride] in, values in [0, 255] out)."""
    out = np.zeros_like(rows)
    prior = np.zeros(rows.shape[1], np.int64)
    for y in range(rows.shape[0]):
        line = rows[y]
        kind = filters[y]
        if kind == 0:
            cur = line.copy()
        elif kind == 2:
            cur = (line + prior) & 0xFF
        elif kind == 1:
            # Each byte adds the one bpp earlier: a running sum per byte lane.
            cur = line.copy()
            for lane in range(bpp):
                cur[lane::bpp] = np.cumsum(line[lane::bpp]) & 0xFF
        elif kind in (3, 4):
            # Sequential along the row; plain lists are much faster than numpy scalars here.
            line_l, up_l = line.tolist(), prior.tolist()
            cur_l = [0] * len(line_l)
            for x, value in enumerate(line_l):
                left = cur_l[x - bpp] if x >= bpp else 0
                up = up_l[x]
                if kind == 3:
                    cur_l[x] = (value + ((left + up) >> 1)) & 0xFF
                    continue
                up_left = up_l[x - bpp] if x >= bpp else 0
                p = left + up - up_left
                pa, pb, pc = abs(p - left), abs(p - up), abs(p - up_left)
                if pa <= pb and pa <= pc:
                    pred = left
                elif pb <= pc:
                    pred = up
                else:
                    pred = up_left
                cur_l[x] = (value + pred) & 0xFF
            cur = np.array(cur_l, dtype=np.int64)
        else:
            raise ValueError("bad PNG filter type %d" % kind)
        out[y] = cur
        prior = cur
    return out
