"""SoftRas's LaplacianLoss and FlattenLoss against direct loops, known values and gradcheck."""

import itertools
import math
import os
import pathlib

import numpy as np
import pytest
import torch

import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf


def assets_dir():
    env = os.environ.get("SOFTVK_ASSETS")
    if env:
        return pathlib.Path(env)
    return pathlib.Path(__file__).resolve().parent / ".." / ".." / "assets"


# A cube, 8 vertices and 12 triangles wound outward: 12 edges at 90°, 6 flat diagonals.
CUBE_VERTICES = np.array([[x, y, z] for z in (-1, 1) for y in (-1, 1) for x in (-1, 1)], float)
CUBE_FACES = np.array([
    [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5], [0, 1, 5], [0, 5, 4],
    [2, 6, 7], [2, 7, 3], [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6],
])
# An octahedron: 12 edges, dihedral angle arccos(-1/3).
OCTA_VERTICES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                         float)
OCTA_FACES = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                       [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])


def neighbours(faces, nv):
    adjacent = [set() for _ in range(nv)]
    for face in faces:
        for a, b in itertools.permutations(face, 2):
            adjacent[a].add(b)
    return adjacent


def laplacian_by_loop(vertices, faces):
    """Σ_i |x_i - mean of the neighbours of i|² per mesh."""
    adjacent = neighbours(faces, vertices.shape[1])
    out = []
    for mesh in vertices:
        total = 0.0
        for i, near in enumerate(adjacent):
            d = mesh[i] - np.mean([mesh[j] for j in near], axis=0)
            total += float(d @ d)
        out.append(total)
    return np.array(out)


def flatten_by_loop(vertices, faces):
    """Σ over edges shared by two faces of (cos θ + 1)², θ between the two faces' directions
    perpendicular to the edge (exact, no eps)."""
    by_edge = {}
    for face in faces:
        for k in range(3):
            a, b, c = face[k], face[(k + 1) % 3], face[(k + 2) % 3]
            by_edge.setdefault(tuple(sorted((a, b))), []).append(c)
    out = []
    for mesh in vertices:
        total = 0.0
        for (a, b), opposite in by_edge.items():
            assert len(opposite) == 2
            edge = mesh[b] - mesh[a]
            edge = edge / np.linalg.norm(edge)
            heights = []
            for c in opposite:
                d = mesh[c] - mesh[a]
                heights.append(d - (d @ edge) * edge)
            h0, h1 = heights
            cos = h0 @ h1 / (np.linalg.norm(h0) * np.linalg.norm(h1))
            total += (cos + 1) ** 2
        out.append(total)
    return np.array(out)


def perturbed(vertices, batch, scale, seed):
    rng = np.random.RandomState(seed)
    return np.stack([vertices + scale * rng.randn(*vertices.shape) for _ in range(batch)])


@pytest.mark.parametrize("name", ["cube", "octahedron"])
def test_laplacian_loss_matches_a_direct_loop(name):
    v, f = (CUBE_VERTICES, CUBE_FACES) if name == "cube" else (OCTA_VERTICES, OCTA_FACES)
    x = perturbed(v, 3, 0.2, seed=1)
    loss = sr.LaplacianLoss(torch.tensor(v), torch.tensor(f))
    out = loss(torch.tensor(x))
    assert out.shape == (3,)
    assert np.allclose(out.numpy(), laplacian_by_loop(x, f), rtol=1e-5)
    average = sr.LaplacianLoss(torch.tensor(v), torch.tensor(f), average=True)
    assert np.isclose(average(torch.tensor(x)).item(), laplacian_by_loop(x, f).mean(), rtol=1e-5)


def test_laplacian_buffer_is_softras_dense_operator():
    loss = sr.LaplacianLoss(torch.tensor(OCTA_VERTICES), torch.tensor(OCTA_FACES))
    lap = loss.laplacian.numpy()
    assert lap.shape == (6, 6) and lap.dtype == np.float32
    assert np.allclose(np.diag(lap), 1)
    assert np.isclose(lap[0, 2], -0.25) and lap[0, 1] == 0  # 4 neighbours, 0 and 1 opposite
    assert "laplacian" in loss.state_dict()


def test_laplacian_loss_is_zero_for_a_vertex_at_its_neighbours_mean():
    # A flat fan: the centre vertex at the mean of a regular hexagon ring.
    ring = [[math.cos(a), math.sin(a), 0.0] for a in np.arange(6) * math.pi / 3]
    v = np.array([[0.0, 0.0, 0.0]] + ring)
    f = np.array([[0, 1 + k, 1 + (k + 1) % 6] for k in range(6)])
    loss = sr.LaplacianLoss(torch.tensor(v), torch.tensor(f))
    terms = torch.matmul(loss.laplacian.double(), torch.tensor(v))
    assert torch.allclose(terms[0], torch.zeros(3, dtype=torch.float64), atol=1e-7)


def test_flatten_loss_known_values_cube_12_octahedron_16_over_3():
    cube = sr.FlattenLoss(torch.tensor(CUBE_FACES))
    assert cube.v0s.shape == (18,)  # 12 cube edges + 6 face diagonals
    assert np.isclose(cube(torch.tensor(CUBE_VERTICES[None])).item(), 12.0, rtol=1e-4)
    octa = sr.FlattenLoss(torch.tensor(OCTA_FACES))
    assert np.isclose(octa(torch.tensor(OCTA_VERTICES[None])).item(), 12 * (2 / 3) ** 2,
                      rtol=1e-4)


@pytest.mark.parametrize("name", ["cube", "octahedron"])
def test_flatten_loss_matches_a_direct_loop(name):
    v, f = (CUBE_VERTICES, CUBE_FACES) if name == "cube" else (OCTA_VERTICES, OCTA_FACES)
    x = perturbed(v, 2, 0.15, seed=4)
    out = sr.FlattenLoss(torch.tensor(f))(torch.tensor(x))
    assert out.shape == (2,)
    # SoftRas's eps = 1e-6 terms shift the value slightly.
    assert np.allclose(out.numpy(), flatten_by_loop(x, f), rtol=1e-4, atol=1e-4)
    average = sr.FlattenLoss(torch.tensor(f), average=True)(torch.tensor(x))
    assert np.isclose(average.item(), out.mean().item())


def test_flatten_loss_of_the_sphere_template_matches_a_direct_loop():
    vertices, faces = srf.load_obj(str(assets_dir() / "sphere_642.obj"))
    loss = sr.FlattenLoss(faces)
    assert loss.v0s.shape == (1920,)  # every edge of the closed sphere: 3F / 2
    # The sphere's edges are nearly flat, so every term is small and SoftRas's eps weighs:
    # scaled up (the loss is scale-invariant) the eps beside squared lengths fades, and the
    # one in the sines (1e-6 beside sin²) leaves under 0.2 %.
    x = vertices[None].double() * 10
    assert np.isclose(loss(x).item(), flatten_by_loop(x.numpy(), faces.numpy())[0], rtol=2e-3)


def test_flatten_loss_skips_boundary_edges():
    # Two triangles sharing one edge, folded 90°: one interior edge, four boundary edges.
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, 0, 1]])
    f = np.array([[0, 1, 2], [1, 0, 3]])
    loss = sr.FlattenLoss(torch.tensor(f))
    assert loss.v0s.tolist() == [0] and loss.v1s.tolist() == [1]
    assert sorted([loss.v2s.item(), loss.v3s.item()]) == [2, 3]
    assert np.isclose(loss(torch.tensor(v[None])).item(), 1.0, rtol=1e-4)


def test_laplacian_loss_gradcheck_float64():
    loss = sr.LaplacianLoss(torch.tensor(CUBE_VERTICES), torch.tensor(CUBE_FACES))
    x = torch.tensor(perturbed(CUBE_VERTICES, 2, 0.2, seed=7), requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: loss(t), (x,))


def test_flatten_loss_gradcheck_float64():
    loss = sr.FlattenLoss(torch.tensor(OCTA_FACES))
    x = torch.tensor(perturbed(OCTA_VERTICES, 2, 0.2, seed=8), requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: loss(t), (x,))
