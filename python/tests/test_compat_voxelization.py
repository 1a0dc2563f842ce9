"""functional.voxelization: a filled cube, and SoftRas's CUDA kernels ported loop for loop."""

import math
import os
import pathlib

import numpy as np
import pytest
import torch

import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf

CUBE_VERTICES = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
CUBE_FACES = np.array([
    [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5], [0, 1, 5], [0, 5, 4],
    [2, 6, 7], [2, 7, 3], [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6],
])


def assets_dir():
    env = os.environ.get("SOFTVK_ASSETS")
    if env:
        return pathlib.Path(env)
    return pathlib.Path(__file__).resolve().parent / ".." / ".." / "assets"


def cube_face_vertices(low, high, dtype=torch.float64):
    vertices = torch.tensor(low + CUBE_VERTICES * (high - low), dtype=dtype)
    return srf.face_vertices(vertices[None], torch.tensor(CUBE_FACES)[None])


# -- SoftRas's voxelization_cuda_kernel.cu, one thread at a time -----------------------------------

def kernel_sub1(faces, vs):
    """voxelize_sub1_kernel: faces [nf, 9] as the kernel indexes them, one mesh."""
    voxels = np.zeros((vs, vs, vs), np.int32)
    for y in range(vs):
        for x in range(vs):
            for face in faces:
                y1d, x1d, z1d = face[3] - face[0], face[4] - face[1], face[5] - face[2]
                y2d, x2d, z2d = face[6] - face[0], face[7] - face[1], face[8] - face[2]
                ypd, xpd = y - face[0], x - face[1]
                det = x1d * y2d - x2d * y1d
                if det == 0:
                    continue
                t1 = (y2d * xpd - x2d * ypd) / det
                t2 = (-y1d * xpd + x1d * ypd) / det
                if t1 < 0 or t2 < 0 or 1 < t1 + t2:
                    continue
                zi = math.floor(t1 * z1d + t2 * z2d + face[2])
                for yi, xi in ((y, x), (y - 1, x), (y, x - 1), (y - 1, x - 1)):
                    if 0 <= yi < vs and 0 <= xi < vs and 0 <= zi < vs:
                        voxels[yi, xi, zi] = 1
    return voxels


def kernel_sub2(faces, vs):
    voxels = np.zeros((vs, vs, vs), np.int32)
    for face in faces:
        for k in range(3):
            yi, xi, zi = (math.floor(face[3 * k + c]) for c in range(3))
            if 0 <= yi < vs and 0 <= xi < vs and 0 <= zi < vs:
                voxels[yi, xi, zi] = 1
    return voxels


def kernel_fill(voxels):
    """voxelize_sub3 then voxelize_sub4 until nothing changes (sequential sweeps)."""
    vs = voxels.shape[0]
    visible = np.zeros_like(voxels)
    for y, x, z in np.ndindex(vs, vs, vs):
        if min(y, x, z) == 0 or max(y, x, z) == vs - 1:
            if voxels[y, x, z] == 0:
                visible[y, x, z] = 1
    while True:
        before = visible.sum()
        for y, x, z in np.ndindex(vs, vs, vs):
            if min(y, x, z) == 0 or max(y, x, z) == vs - 1:
                continue
            if voxels[y, x, z] == 0 and visible[y, x, z] == 0:
                for dy, dx, dz in ((-1, 0, 0), (1, 0, 0), (0, -1, 0), (0, 1, 0), (0, 0, -1),
                                   (0, 0, 1)):
                    if visible[y + dy, x + dx, z + dz] != 0:
                        visible[y, x, z] = 1
        if visible.sum() == before:
            return 1 - visible


def softras_voxelization(faces, size, normalize=False):
    """SoftRas's functional.voxelization around the kernels above, for a [1, F, 3, 3] input."""
    f = faces[0].numpy().astype(np.float64)
    if not normalize:
        f = f * size
    total = np.zeros((size, size, size), np.int32)
    for dim in range(3):
        order = {0: [2, 1, 0], 1: [0, 2, 1], 2: [0, 1, 2]}[dim]
        v = kernel_sub1(f[:, :, order].reshape(-1, 9), size)
        total += np.swapaxes(v, dim, 2)
    total += kernel_sub2(f.reshape(-1, 9), size)
    return kernel_fill((total > 0).astype(np.int32))


# -- tests -----------------------------------------------------------------------------------------

def test_cube_at_half_integers_fills_exactly_its_cells():
    # Vertices at 2.5 and 9.5 voxel units: cells 2..9 on every axis, surface and inside.
    out = srf.voxelization(cube_face_vertices(2.5, 9.5), 12, normalize=True)
    assert out.shape == (1, 12, 12, 12) and out.dtype == torch.int32
    expected = torch.zeros(12, 12, 12, dtype=torch.int32)
    expected[2:10, 2:10, 2:10] = 1
    assert torch.equal(out[0], expected)


def test_cube_in_unit_coordinates_is_scaled_by_size_unless_normalized():
    faces = cube_face_vertices(2.5 / 12, 9.5 / 12)
    assert torch.equal(srf.voxelization(faces, 12),
                       srf.voxelization(faces * 12, 12, normalize=True))
    assert int(srf.voxelization(faces, 12).sum()) == 8 ** 3


def test_open_box_is_not_filled():
    # Without its top (+z) two faces the inside is reachable from outside: only the walls stay.
    faces = cube_face_vertices(2.5, 9.5)[:, :10]
    out = srf.voxelization(faces, 12, normalize=True)[0]
    assert int(out[5, 5, 5]) == 0 and int(out[5, 5, 2]) == 1 and int(out[2, 5, 5]) == 1


def test_matches_softras_kernels_on_a_cube_at_integer_coordinates():
    faces = cube_face_vertices(2.0, 7.0, dtype=torch.float32)
    out = srf.voxelization(faces, 10, normalize=True)[0].numpy()
    assert np.array_equal(out, softras_voxelization(faces, 10, normalize=True))


@pytest.mark.parametrize("seed", [0, 1])
def test_matches_softras_kernels_on_a_perturbed_sphere(seed):
    vertices, faces = srf.load_obj(str(assets_dir() / "sphere_642.obj"))
    rng = np.random.RandomState(seed)
    vertices = vertices * 0.4 * torch.from_numpy(1 + 0.1 * rng.rand(len(vertices), 1)).float()
    face_vertices = srf.face_vertices(vertices[None], faces[None]) * (11.0 / 12) + 0.5
    out = srf.voxelization(face_vertices, 12)[0].numpy()
    expected = softras_voxelization(face_vertices, 12)
    assert expected.sum() > 200  # a filled ball, not just its surface
    assert np.array_equal(out, expected)


def test_batch_and_mesh_voxelize():
    vertices, faces = srf.load_obj(str(assets_dir() / "sphere_642.obj"))
    mesh = sr.Mesh(torch.stack([vertices * 0.45, vertices * 0.25]), faces[None].repeat(2, 1, 1))
    out = mesh.voxelize(16)
    assert out.shape == (2, 16, 16, 16)
    # The inner cell of each ball is filled; the smaller ball fills less.
    assert int(out[0, 8, 8, 8]) == 1 and int(out[1, 8, 8, 8]) == 1
    assert int(out[0].sum()) > int(out[1].sum()) > 0
    single = srf.voxelization(mesh.face_vertices[1:] * 16 / 15 + 0.5, 16)
    assert torch.equal(out[1:], single)
