"""Smoke versions of the nvdiffrast-style samples in python/examples/nvdiffrast (cube.py, pose.py,
albedo.py, envphong.py): a few seconds each, on tiny images. The full runs and their numbers
are in RESULTS.md."""

import argparse
import importlib.util
import pathlib

import numpy as np
import pytest

SAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples" / "nvdiffrast"


def load(name):
    path = SAMPLES / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"nvdiffrast_sample_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def cube():
    return load("cube")


@pytest.fixture(scope="module")
def pose():
    return load("pose")


@pytest.fixture(scope="module")
def albedo():
    return load("albedo")


@pytest.fixture(scope="module")
def envphong():
    return load("envphong")


def test_cube_is_closed_and_wound_outwards(cube):
    corners = cube.cube_corners().astype(np.float64)
    tri = cube.cube_triangles()
    assert tri.shape == (12, 3)
    # Every edge is shared by exactly two triangles, in opposite directions (closed, consistent).
    directed = [(int(t[i]), int(t[(i + 1) % 3])) for t in tri for i in range(3)]
    assert len(set(directed)) == 36
    assert all((b, a) in set(directed) for a, b in directed)
    for t in tri:
        p0, p1, p2 = corners[t]
        assert np.dot(np.cross(p1 - p0, p2 - p0), p0 + p1 + p2) > 0
    assert len({tuple(c) for c in cube.corner_colours().tolist()}) == 8


def test_cube_fit_error_falls_at_8x8(gpu, cube):
    result = cube.fit_cube(resolution=8, iters=100, log_every=50, seed=0, quiet=True)
    rows = result["rows"]
    start, end = rows[0]["geom_err"], rows[-1]["geom_err"]
    assert rows[-1]["iteration"] == 100
    assert end < 0.85 * start, (start, end)


def test_pose_colouring_tells_every_cube_rotation_apart(gpu, pose):
    import torch

    scene = pose.Scene(32)
    rng = np.random.default_rng(7)
    q = pose.random_quaternions(rng, 1)
    with torch.no_grad():
        target = scene.render(torch.from_numpy(q.astype(np.float32)))
        turned = pose.quat_mul(q, pose.CUBE_ROTATIONS).astype(np.float32)
        losses = scene.losses(torch.from_numpy(turned), target).numpy()
    assert losses[0] == 0.0
    assert losses[1:].min() > 1e-4


def test_pose_gradient_descent_from_15_degrees_reaches_1_degree(gpu, pose):
    import torch

    scene = pose.Scene(32)
    rng = np.random.default_rng(100)
    target_q = pose.random_quaternions(rng, 1)[0]
    axis = np.array([1.0, 2.0, -1.0]) / np.sqrt(6.0)
    half = np.radians(15.0) / 2
    start = pose.quat_mul(np.concatenate([[np.cos(half)], np.sin(half) * axis]), target_q)
    assert abs(pose.angle_deg(start, target_q) - 15.0) < 1e-6
    with torch.no_grad():
        target = scene.render(torch.from_numpy(target_q[None].astype(np.float32)))
    args = argparse.Namespace(iters=100, lr=1e-2, lr_end=0.01, threshold=1.0, log_every=50)
    final, loss, _ = pose.descend(scene, target, target_q, start, args)
    assert pose.angle_deg(final, target_q) < 1.0, (pose.angle_deg(final, target_q), loss)


def test_pose_search_then_descent(gpu, pose):
    scene = pose.Scene(32)
    rng = np.random.default_rng(101)
    target_q = pose.random_quaternions(rng, 1)[0]
    args = argparse.Namespace(
        candidates=64, batch=32, refine_rounds=4, refine_start=45.0, refine_end=5.0,
        jump_share=0.5, symmetric_trials=1, iters=50, lr=1e-2, lr_end=0.01, threshold=1.0,
        log_every=50,
    )
    result = pose.fit_pose(scene, target_q, rng, args)
    assert result["search_err"] < result["uniform_best_err"], result
    assert result["final_err"] < 1.0, result


def test_albedo_error_falls_at_32x32(gpu, albedo):
    result = albedo.fit_albedo(resolution=32, iters=20, tex_size=32, eval_views=2, log_every=10,
                               quiet=True)
    first, last = result["rows"][0], result["rows"][-1]
    assert result["chart_texels"] > 0.3 * 32 * 32
    assert last["albedo_rms"] < 0.8 * first["albedo_rms"], (first, last)
    assert last["image_mse"] < 0.5 * first["image_mse"], (first, last)


def test_the_sample_cube_map_faces_are_the_ones_texture_reads(gpu, envphong):
    """A cube map whose texels hold their own directions, looked up at random directions,
    returns those directions (up to bilinear filtering of a curved field): the sample builds its
    environment with the face table texture() reads."""
    import torch

    import softvk.nvdiffrast.torch as dr

    env = torch.from_numpy(envphong.face_directions(32).astype(np.float32))[None].contiguous()
    d = torch.from_numpy(np.random.default_rng(0).standard_normal((1, 16, 16, 3)))
    d = d.float().contiguous()
    got = dr.texture(env, d, filter_mode="linear", boundary_mode="cube")
    want = d / torch.linalg.norm(d, dim=-1, keepdim=True)
    assert float((got - want).abs().max()) < 0.01


def test_envphong_error_falls_at_32x32(gpu, envphong):
    result = envphong.fit_envphong(resolution=32, iters=20, env_size=8, eval_views=2,
                                   log_every=10, quiet=True)
    first, last = result["rows"][0], result["rows"][-1]
    assert last["image_mse"] < 0.5 * first["image_mse"], (first, last)
    assert last["env_rms"] < first["env_rms"], (first, last)
