"""Writes the .npy/.npz fixtures of tests/recon_data.rs with NumPy itself.

Run from anywhere: python3 make_fixtures.py  (needs numpy; the files are committed, so the
tests never need it). Every value comes from a formula the Rust tests recompute.
"""
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def path(name):
    return os.path.join(HERE, name)


def main():
    # An images-like 5-D uint8 array: (objects, views, channels, rows, columns).
    images = (np.arange(2 * 3 * 4 * 5 * 6) % 251).astype(np.uint8).reshape(2, 3, 4, 5, 6)
    np.savez(path("images_u8.npz"), images)
    np.savez_compressed(path("images_u8_compressed.npz"), images)

    # Voxel-like grids in every dtype softvk reads: occupied where (n * 7) % 3 == 0.
    n = np.arange(2 * 8 * 8 * 8)
    occupied = ((n * 7) % 3 == 0).reshape(2, 8, 8, 8)
    np.savez_compressed(path("voxels_bool.npz"), occupied)
    np.savez_compressed(path("voxels_u8.npz"), occupied.astype(np.uint8))
    np.savez_compressed(path("voxels_i32.npz"), occupied.astype(np.int32) * 3)
    # Floats: (n % 4) / 4, so ≥ 0.5 exactly where n % 4 >= 2.
    np.savez_compressed(path("voxels_f32.npz"), ((n % 4) / 4).astype(np.float32).reshape(2, 8, 8, 8))
    np.savez_compressed(path("voxels_f64.npz"), ((n % 4) / 4).astype(np.float64).reshape(2, 8, 8, 8))

    # Several arrays in one archive, named and positional, in this order.
    ints = ((np.arange(10) - 5) * 1000003).astype(np.int32)
    floats = (np.arange(6, dtype=np.float64) * 0.5 - 1.25).reshape(2, 3)
    np.savez(path("multi.npz"), ints, floats, scalar=np.float32(2.5))

    # Plain .npy files: 0-d, 1-d, big-endian, Fortran order, an unsupported dtype.
    np.save(path("scalar_f64.npy"), np.float64(3.25))
    np.save(path("vector_f32.npy"), np.arange(7, dtype=np.float32) / 8)
    np.save(path("big_endian_f32.npy"), (np.arange(12, dtype=np.float32) / 4).reshape(3, 4).astype(">f4"))
    np.save(path("fortran_i32.npy"), np.asfortranarray(np.arange(12, dtype=np.int32).reshape(3, 4)))
    np.save(path("int16.npy"), np.arange(5, dtype=np.int16))

    # An archive with no array in it.
    np.savez(path("empty.npz"))


if __name__ == "__main__":
    main()
