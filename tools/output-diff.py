#!/usr/bin/env python3
"""Compares two folders of `softvk` outputs, as `tools/output-hashes --keep` leaves them, file by
file, and prints a table: per file whether its bytes changed and, where they did, the largest
difference in the file's own units.

    tools/output-diff.py [--names OLD,NEW] [--differing] OLD_DIR NEW_DIR

- 8-bit images (PNG, GIF, every frame): the largest channel difference in 1/255 (16-bit PNG:
  1/65535), where it is, and how many channel values differ;
- float images (OpenEXR, read here by a small reader of scan-line files without compression,
  RLE, ZIPS or ZIP, which is what softvk writes): units in the last place of the channel's type
  and the absolute difference;
- NPZ arrays: float arrays in units in the last place of their dtype and relative to each
  element (|a - b| / max(|a|, |b|)), integer arrays by their largest absolute difference;
- text (CSV, JSON, OBJ, standard output): every number relative to its own value, with the
  CSV column (loss columns, gradient components) or the line it is on; other text that differs
  is named by its first differing line.

Where an f64 twin's tolerance bounds a file (the render's EXR: the forward, 1e-4 per channel;
`grad.csv`: the backward, 1e-3 of the largest component's magnitude), the difference is also
given as a multiple of that tolerance. A file this script cannot read (an EXR it has no decoder
for, an unknown binary) is reported as "bytes differ" with the number of differing bytes.

Exit status: 0 when every file is the same, 1 when any differs or is missing on one side.
"""

import argparse
import io
import math
import os
import re
import struct
import sys
import zlib

import numpy as np

# Outputs that an f64 twin's tolerance bounds (tests/raster_forward.rs and
# tests/raster_backward.rs): file name -> (what, tolerance, "abs" for an absolute bound per
# value or the CSV columns whose largest magnitude scales it).
TWIN_TOLERANCES = {
    "render-exr.exr": ("forward's f64 twin", 1e-4, "abs"),
    "grad.csv": ("backward's f64 twin", 1e-3, ("dx", "dy", "dz")),
}


class Unreadable(Exception):
    """The file's format is one this script has no reader for."""


def fmt(x):
    """A difference, short: integers as they are, others in 3 significant digits."""
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if x == 0:
        return "0"
    if math.isinf(x) or math.isnan(x):
        return str(x)
    if float(x).is_integer() and abs(x) < 2**53:
        return str(int(x))
    return f"{x:.3g}"


# ---- floats: units in the last place ----


def ordered(a):
    """Float bits as integers that order as the floats do (-0 and +0 both 0)."""
    ints = {np.float16: np.int16, np.float32: np.int32, np.float64: np.int64}[a.dtype.type]
    bits = {np.float16: 15, np.float32: 31, np.float64: 63}[a.dtype.type]
    i = a.view(ints).astype(np.int64)
    mag = i & np.int64((1 << bits) - 1)
    return np.where(i < 0, -mag, mag)


def ulps(a, b):
    """|a - b| in units in the last place of their dtype, as float64 (exact below 2^53)."""
    oa, ob = ordered(a), ordered(b)
    same_sign = (oa >= 0) == (ob >= 0)
    with np.errstate(over="ignore"):
        exact = np.abs(oa - ob).astype(np.float64)
    approx = np.abs(oa.astype(np.float64) - ob.astype(np.float64))
    return np.where(same_sign, exact, approx)


def rel(a, b):
    """|a - b| / max(|a|, |b|), 0 where both are 0."""
    a = a.astype(np.float64)
    b = b.astype(np.float64)
    scale = np.maximum(np.abs(a), np.abs(b))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.abs(a - b) / scale
    return np.where(scale == 0, 0.0, r)


def float_diff(a, b, where):
    """The largest difference of two float arrays of one shape: a phrase, and the largest
    absolute difference (for the twins' tolerances). `where(flat_index)` names an element."""
    a = a.ravel()
    b = b.ravel()
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    nan_mismatch = int(np.count_nonzero(nan_a != nan_b))
    ok = ~(nan_a | nan_b)
    differ = int(np.count_nonzero(a.view(f"u{a.itemsize}") != b.view(f"u{b.itemsize}")))
    if not ok.any():
        return f"{differ} of {a.size} values differ (all NaN)", 0.0
    u = np.where(ok, ulps(a, b), 0.0)
    r = np.where(ok, rel(a, b), 0.0)
    with np.errstate(invalid="ignore"):
        d = np.where(ok, np.abs(a.astype(np.float64) - b.astype(np.float64)), 0.0)
    at = lambda k: f"{where(k)}: {a[k]!r} -> {b[k]!r}"  # noqa: E731
    ku, kd = int(np.argmax(u)), int(np.argmax(d))
    phrase = f"{fmt(u[ku])} ulp ({a.dtype.name}) at {at(ku)}"
    if kd != ku and d[kd] > d[ku]:
        phrase += f"; largest |d| {fmt(d[kd])} at {at(kd)}"
    else:
        phrase += f"; |d| {fmt(d[ku])}"
    phrase += f"; largest relative {fmt(r.max())}; {differ} of {a.size} values differ"
    if nan_mismatch:
        phrase += f", {nan_mismatch} NaN on one side only"
    return phrase, float(d.max())


# ---- images ----


def image_frames(path):
    """The frames of a PNG or GIF as arrays (height, width, channels), and the unit's name."""
    from PIL import Image, ImageSequence

    with Image.open(path) as im:
        frames = []
        for frame in ImageSequence.Iterator(im):
            if frame.mode in ("I;16", "I;16B", "I"):
                frames.append((np.asarray(frame, dtype=np.int64)[..., None], 65535))
            else:
                mode = "RGBA" if "A" in frame.getbands() or frame.mode == "P" else "RGB"
                if frame.mode in ("L", "LA"):
                    mode = frame.mode
                frames.append((np.asarray(frame.convert(mode), dtype=np.int64), 255))
                if frames[-1][0].ndim == 2:
                    frames[-1] = (frames[-1][0][..., None], 255)
    return frames


def diff_image(old, new):
    fa, fb = image_frames(old), image_frames(new)
    if len(fa) != len(fb):
        return f"{len(fa)} -> {len(fb)} frames"
    worst = None
    differ = total = 0
    for n, ((a, unit), (b, unit_b)) in enumerate(zip(fa, fb)):
        if a.shape != b.shape or unit != unit_b:
            return f"frame {n}: {a.shape} -> {b.shape}"
        d = np.abs(a - b)
        differ += int(np.count_nonzero(d))
        total += d.size
        k = np.unravel_index(int(np.argmax(d)), d.shape)
        if worst is None or d[k] > worst[0]:
            worst = (int(d[k]), n, k, int(a[k]), int(b[k]), unit)
    step, n, (y, x, c), va, vb, unit = worst
    frame = f"frame {n}, " if len(fa) > 1 else ""
    return (
        f"{step}/{unit} at {frame}pixel (x {x}, y {y}) channel {c}: {va} -> {vb}; "
        f"{differ} of {total} channel values differ"
    )


def read_exr(path):
    """A single-part scan-line OpenEXR: {channel: array (height, width)}. Compression: none,
    RLE, ZIPS or ZIP (what the `exr` crate's SMALL_LOSSLESS writes); anything else is
    Unreadable."""
    data = open(path, "rb").read()
    if data[:4] != b"\x76\x2f\x31\x01":
        raise Unreadable("not an OpenEXR file")
    flags = struct.unpack_from("<I", data, 4)[0]
    if flags & (0x200 | 0x800 | 0x1000):
        raise Unreadable("tiled, deep or multi-part EXR")
    pos = 8
    attrs = {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        pos = end + 1
        end = data.index(b"\0", pos)
        pos = end + 1
        size = struct.unpack_from("<i", data, pos)[0]
        pos += 4
        attrs[name] = data[pos : pos + size]
        pos += size
    pos += 1
    channels = []
    chlist = attrs["channels"]
    p = 0
    while chlist[p] != 0:
        end = chlist.index(b"\0", p)
        name = chlist[p:end].decode()
        ptype, _, xs, ys = struct.unpack_from("<iB3xii", chlist, end + 1)
        if (xs, ys) != (1, 1):
            raise Unreadable("subsampled channels")
        channels.append((name, {0: np.dtype("<u4"), 1: np.dtype("<f2"), 2: np.dtype("<f4")}[ptype]))
        p = end + 1 + 16
    compression = attrs["compression"][0]
    lines_per_block = {0: 1, 1: 1, 2: 1, 3: 16}.get(compression)
    if lines_per_block is None:
        raise Unreadable(f"EXR compression {compression} (this reader knows none, RLE, ZIPS, ZIP)")
    xmin, ymin, xmax, ymax = struct.unpack("<4i", attrs["dataWindow"])
    width, height = xmax - xmin + 1, ymax - ymin + 1
    chunks = -(-height // lines_per_block)
    offsets = struct.unpack_from(f"<{chunks}Q", data, pos)
    out = {name: np.zeros((height, width), dt) for name, dt in channels}
    line_bytes = sum(width * dt.itemsize for _, dt in channels)
    for off in offsets:
        y, size = struct.unpack_from("<ii", data, off)
        raw = data[off + 8 : off + 8 + size]
        lines = min(lines_per_block, ymax - y + 1)
        expected = lines * line_bytes
        if size < expected:  # stored raw where compression did not shrink it
            if compression == 1:
                raw = rle_decode(raw)
            elif compression in (2, 3):
                raw = zlib.decompress(raw)
            raw = unpredict(raw)
        if len(raw) != expected:
            raise Unreadable(f"chunk at line {y}: {len(raw)} bytes for {expected}")
        p = 0
        for line in range(lines):
            for name, dt in channels:
                n = width * dt.itemsize
                out[name][y - ymin + line] = np.frombuffer(raw, dt, width, p)
                p += n
    return out


def rle_decode(raw):
    out = bytearray()
    p = 0
    while p < len(raw):
        count = struct.unpack_from("b", raw, p)[0]
        p += 1
        if count < 0:
            out += raw[p : p - count]
            p -= count
        else:
            out += raw[p : p + 1] * (count + 1)
            p += 1
    return bytes(out)


def unpredict(raw):
    """Undoes OpenEXR's ZIP/RLE predictor and its split of even and odd bytes."""
    d = np.frombuffer(raw, np.uint8).astype(np.int64)
    d[1:] -= 128
    t = (np.cumsum(d) & 0xFF).astype(np.uint8)
    out = np.empty_like(t)
    half = (len(t) + 1) // 2
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return out.tobytes()


def diff_exr(old, new):
    a, b = read_exr(old), read_exr(new)
    if [(k, v.shape, v.dtype) for k, v in a.items()] != [(k, v.shape, v.dtype) for k, v in b.items()]:
        return f"channels {list(a)} -> {list(b)} (or their sizes or types)", None
    names = list(a)
    # One array (height, width, channel) per pixel type, so that counts cover every channel.
    phrases, dmax = [], 0.0
    for dt in sorted({v.dtype.str for v in a.values()}):
        chans = [n for n in names if a[n].dtype.str == dt]
        x = np.stack([a[n] for n in chans], -1)
        y = np.stack([b[n] for n in chans], -1)
        if x.tobytes() == y.tobytes():
            continue
        if x.dtype.kind == "u":
            d = np.abs(x.astype(np.int64) - y.astype(np.int64))
            phrases.append(f"channels {','.join(chans)}: largest |d| {d.max()}")
            continue
        w, c = x.shape[1], x.shape[2]
        phrase, m = float_diff(
            x, y, lambda k: f"pixel (x {k // c % w}, y {k // c // w}) channel {chans[k % c]}"
        )
        phrases.append(phrase)
        dmax = max(dmax, m)
    return "; ".join(phrases), (dmax, None)


# ---- numbers in text ----

NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?|[-+]?(?:inf|NaN|nan)\b")


def split_numbers(line):
    """(the line with its numbers replaced by #, the numbers as floats)."""
    numbers = [float(m) for m in NUMBER.findall(line)]
    return NUMBER.sub("#", line), numbers


def diff_text(old, new, name, tol):
    la = open(old, encoding="utf-8", errors="replace").read().splitlines()
    lb = open(new, encoding="utf-8", errors="replace").read().splitlines()
    if len(la) != len(lb):
        return f"{len(la)} -> {len(lb)} lines", None
    csv = name.endswith(".csv")
    header = la[0].split(",") if csv and la else []
    # Per column (CSV) or per file: (largest relative difference, where, a, b).
    columns = {}
    text_differs = []
    values = []  # (old, new) pairs of every number, for the twins' tolerances
    magnitudes = []
    count = differ = 0
    for n, (x, y) in enumerate(zip(la, lb)):
        if csv and n > 0:
            cells = list(zip(x.split(","), y.split(",")))
            if len(x.split(",")) != len(y.split(",")):
                text_differs.append(n + 1)
                continue
            pairs = []
            for c, (p, q) in enumerate(cells):
                try:
                    pairs.append((header[c] if c < len(header) else f"column {c + 1}", float(p), float(q)))
                except ValueError:
                    if p != q:
                        text_differs.append(n + 1)
        else:
            sx, nx = split_numbers(x)
            sy, ny = split_numbers(y)
            if sx != sy or len(nx) != len(ny):
                text_differs.append(n + 1)
                continue
            pairs = [(None, p, q) for p, q in zip(nx, ny)]
        for k, (col, p, q) in enumerate(pairs):
            count += 1
            key = col or "numbers"
            magnitudes.append((key, max(abs(p), abs(q))))
            if p == q or (math.isnan(p) and math.isnan(q)):
                continue
            differ += 1
            r = float(rel(np.array([p]), np.array([q]))[0]) if not (math.isnan(p) or math.isnan(q)) else math.inf
            at = f"line {n + 1}" if col is None else f"row {n}"
            if col is None and len(pairs) > 1:
                at += f", number {k + 1}"
            values.append((key, abs(p - q)))
            if key not in columns or r > columns[key][0]:
                columns[key] = (r, at, p, q)
    if not columns and not text_differs:
        return "bytes differ, the text and its numbers do not (white space, number format)", None
    parts = []
    if columns:
        ranked = sorted(columns.items(), key=lambda kv: -kv[1][0])
        for key, (r, at, p, q) in ranked[:4]:
            where = at if key == "numbers" else f"{key} {at}"
            parts.append(f"relative {fmt(r)} ({where}: {p!r} -> {q!r})")
        if len(ranked) > 4:
            parts.append(f"{len(ranked) - 4} more columns")
        parts.append(f"{differ} of {count} numbers differ")
    if text_differs:
        parts.append(f"text differs on {len(text_differs)} lines (first: line {text_differs[0]})")
    twin = None
    if tol is not None and values:
        # The largest |d| over every gradient component, against the largest magnitude.
        comps = tol[2]
        dmax = max(d for k, d in values if k in comps) if comps else 0.0
        scale = max((m for k, m in magnitudes if k in comps), default=0.0)
        twin = (dmax, scale)
    return "; ".join(parts), twin


# ---- NPZ ----


def array_row(name, x, y, stride=1):
    """(how large, a phrase) for two differing arrays of one shape and dtype; `stride`: x and y
    are every stride-th value of the arrays named."""
    if x.dtype.kind == "f":
        shape = x.shape
        if stride == 1:
            where = lambda k: f"{list(np.unravel_index(k, shape))}"  # noqa: E731
        else:
            where = lambda k: f"flat index {k * stride}"  # noqa: E731
        phrase, _ = float_diff(x, y, where)
        return float(ulps(x.ravel(), y.ravel()).max()), f"{name}: {phrase}"
    if x.dtype.kind in "iub":
        d = np.abs(x.astype(np.int64) - y.astype(np.int64))
        return float(d.max()), f"{name}: largest |d| {d.max()}, {np.count_nonzero(d)} of {d.size} differ"
    return math.inf, f"{name}: {x.dtype} differs"


def diff_npz(old, new):
    a, b = np.load(old, allow_pickle=False), np.load(new, allow_pickle=False)
    if sorted(a.files) != sorted(b.files):
        return f"arrays {sorted(a.files)} -> {sorted(b.files)}"
    rows = []
    for name in sorted(a.files):
        x, y = a[name], b[name]
        if x.shape != y.shape or x.dtype != y.dtype:
            rows.append((math.inf, f"{name}: {x.dtype}{list(x.shape)} -> {y.dtype}{list(y.shape)}"))
        elif x.tobytes() != y.tobytes():
            rows.append(array_row(name, x, y))
    if not rows:
        return "bytes differ, the arrays do not (the archive's metadata)"
    rows.sort(key=lambda r: -r[0])
    more = f"; {len(rows) - 2} more arrays differ" if len(rows) > 2 else ""
    return "; ".join(r[1] for r in rows[:2]) + more


# ---- sketches of large NPZ files ----

SKETCH = ".sketch.npz"
SKETCH_FULL = 65536  # arrays of up to this many values are kept whole
SKETCH_STRIDE = 16  # of larger ones, every 16th value
SKETCH_BLOCK = 4096  # and a digest of each block of this many values


def block_digests(flat):
    import hashlib

    raw = flat.tobytes()
    n = SKETCH_BLOCK * flat.itemsize
    return np.array(
        [list(hashlib.blake2b(raw[i : i + n], digest_size=8).digest()) for i in range(0, len(raw), n)],
        np.uint8,
    )


def sketch(path):
    """Replaces the NPZ at `path` by `path.sketch.npz`: its SHA-256, its small arrays whole, and
    of each large one every SKETCH_STRIDE-th value and a digest of each block of values."""
    import hashlib

    z = np.load(path, allow_pickle=False)
    out = {"sha256": np.frombuffer(hashlib.sha256(open(path, "rb").read()).digest(), np.uint8)}
    for name in z.files:
        x = z[name]
        if x.size <= SKETCH_FULL:
            out["full:" + name] = x
        else:
            flat = np.ascontiguousarray(x).ravel()
            out["shape:" + name] = np.array(x.shape, np.int64)
            out["sample:" + name] = flat[::SKETCH_STRIDE]
            out["blocks:" + name] = block_digests(flat)
    np.savez_compressed(path + SKETCH, **out)
    os.remove(path)


class Sketched:
    """The arrays of a sketch, as the NPZ's would be read for the comparison: small ones whole,
    large ones as (shape, sample, block digests)."""

    def __init__(self, path):
        self.sk = np.load(path, allow_pickle=False)
        self.files = sorted({k.split(":", 1)[1] for k in self.sk.files if ":" in k})

    def __getitem__(self, name):
        if "full:" + name in self.sk.files:
            return self.sk["full:" + name]
        return (tuple(self.sk["shape:" + name]), self.sk["sample:" + name], self.sk["blocks:" + name])


def diff_sketch(sketch_path, new):
    """An NPZ, or another sketch, against the sketch of the other side's: the sampled values'
    largest difference and how many blocks of values differ by their digests."""
    sk = np.load(sketch_path, allow_pickle=False)
    z = Sketched(new) if new.endswith(SKETCH) else np.load(new, allow_pickle=False)
    names = sorted({k.split(":", 1)[1] for k in sk.files if ":" in k})
    if names != sorted(z.files):
        return f"arrays {names} -> {sorted(z.files)}"
    rows = []
    for name in names:
        y = z[name]
        if "full:" + name in sk.files:
            x = sk["full:" + name]
            if x.shape != y.shape or x.dtype != y.dtype:
                rows.append((math.inf, f"{name}: {x.dtype}{list(x.shape)} -> {y.dtype}{list(y.shape)}"))
            elif x.tobytes() != y.tobytes():
                rows.append(array_row(name, x, y))
            continue
        shape = tuple(sk["shape:" + name])
        x = sk["sample:" + name]
        if isinstance(y, tuple):  # the other side's sketch
            y_shape, sample, digests = y
            y_dtype = sample.dtype
        else:
            y_shape, y_dtype = y.shape, y.dtype
        if shape != y_shape or x.dtype != y_dtype:
            rows.append((math.inf, f"{name}: {x.dtype}{list(shape)} -> {y_dtype}{list(y_shape)}"))
            continue
        if not isinstance(y, tuple):
            flat = np.ascontiguousarray(y).ravel()
            digests, sample = block_digests(flat), flat[::SKETCH_STRIDE]
        blocks = int(np.count_nonzero((sk["blocks:" + name] != digests).any(axis=1)))
        nblocks = len(sk["blocks:" + name])
        if blocks == 0:
            continue
        note = f"{blocks} of {nblocks} blocks of {SKETCH_BLOCK} values differ"
        if x.tobytes() == sample.tobytes():
            rows.append((0.0, f"{name}: {note}; none of the reference's sampled values (1 in {SKETCH_STRIDE}) does"))
        else:
            key, phrase = array_row(name, x, sample, stride=SKETCH_STRIDE)
            rows.append((key, f"{phrase} (among the reference's 1 in {SKETCH_STRIDE} values kept); {note}"))
    if not rows:
        return "bytes differ, the arrays do not (the archive's metadata)"
    rows.sort(key=lambda r: -r[0])
    more = f"; {len(rows) - 2} more arrays differ" if len(rows) > 2 else ""
    return "; ".join(r[1] for r in rows[:2]) + more


# ---- the table ----


def byte_difference(pa, pb):
    a, b = open(pa, "rb").read(), open(pb, "rb").read()
    n = min(len(a), len(b))
    differ = int(np.count_nonzero(np.frombuffer(a[:n], np.uint8) != np.frombuffer(b[:n], np.uint8)))
    return f"bytes differ: {differ} of {n} bytes" + (f", sizes {len(a)} -> {len(b)}" if len(a) != len(b) else "")


def kind_of(name):
    ext = os.path.splitext(name)[1].lower()
    return {
        ".png": "image",
        ".gif": "image",
        ".exr": "exr",
        ".npz": "npz",
        ".csv": "text",
        ".json": "text",
        ".obj": "text",
        ".stdout": "text",
        ".txt": "text",
    }.get(ext, "bytes")


def compare(pa, pb, rel_path):
    """(the phrase for a differing file, its twin tolerance's ratio or None)."""
    name = os.path.basename(rel_path)
    tol = TWIN_TOLERANCES.get(name)
    kind = kind_of(name)
    twin = None
    try:
        if kind == "image":
            phrase = diff_image(pa, pb)
        elif kind == "exr":
            phrase, twin = diff_exr(pa, pb)
        elif kind == "npz":
            phrase = diff_npz(pa, pb)
        elif kind == "text":
            phrase, twin = diff_text(pa, pb, name, tol)
        else:
            phrase = byte_difference(pa, pb)
    except Unreadable as e:
        phrase = f"{byte_difference(pa, pb)} (not read: {e})"
    except Exception as e:  # a reader's failure must not hide the file
        phrase = f"{byte_difference(pa, pb)} (not read: {type(e).__name__}: {e})"
    ratio = None
    if tol is not None and twin is not None:
        what, t, how = tol
        dmax, scale = twin
        if how == "abs":
            ratio = f"{fmt(dmax / t)} x the {what}'s {t:g} per channel"
        elif scale:
            ratio = f"{fmt(dmax / (t * scale))} x the {what}'s {t:g} of the largest component ({fmt(scale)})"
    return phrase, ratio


def files_under(root):
    """{output path: the file that stands for it} (a sketch stands for its NPZ)."""
    out = {}
    for d, _, names in os.walk(root):
        for n in names:
            if n.endswith(".ckpt") or n == "checkpoint.npz":
                continue
            rel_path = os.path.relpath(os.path.join(d, n), root)
            out[rel_path[: -len(SKETCH)] if rel_path.endswith(SKETCH) else rel_path] = os.path.join(root, rel_path)
    return out


def same_bytes(pa, pb):
    import hashlib

    if pa.endswith(SKETCH):
        sha = np.load(pa, allow_pickle=False)["sha256"].tobytes()
        if pb.endswith(SKETCH):
            return np.load(pb, allow_pickle=False)["sha256"].tobytes() == sha
        return hashlib.sha256(open(pb, "rb").read()).digest() == sha
    if pb.endswith(SKETCH):
        return same_bytes(pb, pa)
    return open(pa, "rb").read() == open(pb, "rb").read()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("old", help="a folder of outputs (its large NPZ files may be sketches)")
    ap.add_argument("new", nargs="?", help="a folder of outputs")
    ap.add_argument("--names", default="old,new", help="what to call the two folders: OLD,NEW")
    ap.add_argument("--differing", action="store_true", help="list only the files that differ")
    ap.add_argument(
        "--sketch",
        type=int,
        metavar="BYTES",
        help="instead of comparing: replace every NPZ in OLD larger than BYTES by a sketch of it "
        f"(NAME{SKETCH}: its hash, its small arrays, 1 in {SKETCH_STRIDE} values of the others and "
        "digests of their blocks), to keep a folder small",
    )
    args = ap.parse_args()
    if args.sketch is not None:
        for d, _, names in os.walk(args.old):
            for n in names:
                path = os.path.join(d, n)
                if n.endswith(".npz") and not n.endswith(SKETCH) and os.path.getsize(path) > args.sketch:
                    sketch(path)
        return 0
    if args.new is None:
        ap.error("two folders to compare")
    old_name, new_name = args.names.split(",", 1)
    fa, fb = files_under(args.old), files_under(args.new)
    paths = sorted(set(fa) | set(fb))
    width = max((len(p) for p in paths), default=4) + 4  # "./", the path and two spaces
    print(f"{'file':<{width}}{'bytes':<14}largest difference ({old_name} -> {new_name})")
    differing = 0
    for p in paths:
        if p not in fb:
            row, detail = f"only in {old_name}", ""
        elif p not in fa:
            row, detail = f"only in {new_name}", ""
        elif same_bytes(fa[p], fb[p]):
            if args.differing:
                continue
            print(f"./{p:<{width - 2}}same")
            continue
        elif fa[p].endswith(SKETCH) or fb[p].endswith(SKETCH):
            try:
                if fa[p].endswith(SKETCH):
                    phrase = diff_sketch(fa[p], fb[p])
                else:
                    phrase = diff_sketch(fb[p], fa[p]) + f" ({new_name} holds the sketch)"
            except Exception as e:
                phrase = f"the file's hash differs from its sketch's (not read: {type(e).__name__}: {e})"
            row, detail = "DIFFER", phrase
        else:
            phrase, ratio = compare(fa[p], fb[p], p)
            row, detail = "DIFFER", phrase + (f" [{ratio}]" if ratio else "")
        differing += 1
        print(f"./{p:<{width - 2}}{row:<14}{detail}")
    print(f"{differing} of {len(paths)} files differ")
    return 1 if differing else 0


if __name__ == "__main__":
    sys.exit(main())
