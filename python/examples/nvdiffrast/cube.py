"""Fits a coloured cube's corners and colours to renders of a target cube from random views, in the
style of nvdiffrast's cube sample, on softvk's nvdiffrast API (``softvk.nvdiffrast.torch``).

    SOFTVK_VALIDATION=0 python python/examples/nvdiffrast/cube.py --resolution 16 --iters 2000 \
        --out /tmp/nvsamples/cube

The cube is built here: 8 corners at (+-0.5, +-0.5, +-0.5), 12 triangles wound outwards, and one
colour per corner (8 RGB colours, shared by the faces that meet there, so the colour varies
smoothly over each face and is continuous across its edges). The model starts from the target
perturbed as nvdiffrast's sample perturbs it: uniform noise in [-0.5, 0.5] on every coordinate
of every corner, and uniform random colours in [0, 1].

Each iteration draws a random view (a uniformly random rotation of the cube and a small random
translation, then a camera 3.5 away with a 45-degree perspective projection into clip space),
renders the target and the model at ``--resolution`` x ``--resolution`` (rasterize ->
interpolate the corner colours -> antialias), and takes one Adam step on the mean squared pixel
difference. The learning rate decays exponentially, from ``--lr`` by a factor ``--lr-decay``
every 1000 iterations, down to 1 % of ``--lr``.

The geometric error is the mean, over the 8 corners, of the Euclidean distance from each fitted
corner to its own true corner (a correspondence-based error). nvdiffrast's sample measures the
mean of ``|| |p| - 0.5 ||``, the distance to the nearest true corner after folding every sign
(smaller or equal); it is written to the CSV as ``geom_err_nv``, for comparison.

Writes ``cube_<resolution>_seed<seed>.csv`` to ``--out`` with one row every ``--log-every``
iterations (the error measured before that iteration's step, so row ``k`` is the cube after
``k`` steps) and prints a summary line.
"""

import argparse
import csv
import os
import time

import numpy as np
import torch

import softvk.nvdiffrast.torch as dr

# ---------------------------------------------------------------------------------------------
# The cube.


def cube_corners(half=0.5):
    """The 8 corners, float32 [8, 3]: corner i has x, y, z = +half where bits 0, 1, 2 of i are
    set, -half where not."""
    bits = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], dtype=np.float64)
    return ((2.0 * bits - 1.0) * half).astype(np.float32)


def cube_faces():
    """The six faces as (axis, side, the 4 corner indices in a cycle around the face)."""
    faces = []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        for side in (0, 1):
            # Walk the face's square: (a, b) bits 00 -> 10 -> 11 -> 01.
            cycle = []
            for ba, bb in ((0, 0), (1, 0), (1, 1), (0, 1)):
                cycle.append((side << axis) | (ba << a) | (bb << b))
            faces.append((axis, side, cycle))
    return faces


def cube_triangles():
    """12 triangles, int32 [12, 3], two per face, each wound counter-clockwise seen from
    outside (its normal by the right-hand rule points away from the centre). Face f owns
    triangles 2f and 2f + 1 (in cube_faces()'s order)."""
    corners = cube_corners().astype(np.float64)
    tris = []
    for _, _, (c0, c1, c2, c3) in cube_faces():
        for t in ((c0, c1, c2), (c0, c2, c3)):
            p0, p1, p2 = corners[list(t)]
            normal = np.cross(p1 - p0, p2 - p0)
            if np.dot(normal, p0 + p1 + p2) < 0.0:
                t = (t[0], t[2], t[1])
            tris.append(t)
    return np.asarray(tris, dtype=np.int32)


def corner_colours():
    """One colour per corner, float32 [8, 3]: the corner's octant mapped into [0.1, 0.9]^3, with
    the channels rotated so that no two corners share a colour and none is grey."""
    bits = np.array([[(i >> k) & 1 for k in range(3)] for i in range(8)], dtype=np.float64)
    colours = 0.1 + 0.8 * bits[:, [1, 2, 0]]
    # Lift the two corners that would be black and white off the grey axis.
    colours[0] = [0.2, 0.1, 0.5]
    colours[7] = [0.9, 0.8, 0.3]
    return colours.astype(np.float32)


# ---------------------------------------------------------------------------------------------
# Cameras.


def perspective(fov_y_deg=45.0, near=1.0, far=50.0):
    """An OpenGL-style perspective projection (camera looking down -z) into clip space,
    float64 [4, 4]."""
    f = 1.0 / np.tan(np.radians(fov_y_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def translation(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def quat_to_matrix_np(q):
    """The rotation matrix [3, 3] of a quaternion (w, x, y, z), normalised first."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def random_quaternion(rng):
    """A uniformly distributed unit quaternion (w, x, y, z): a normalised 4-D Gaussian."""
    q = rng.standard_normal(4)
    return q / np.linalg.norm(q)


def random_view(rng, distance=3.5, jitter=0.25, fov_y_deg=45.0):
    """A random model-view-projection matrix, float64 [4, 4]: the cube rotated uniformly at
    random and moved by up to ``jitter`` along each axis, seen from ``distance`` away."""
    model = np.eye(4)
    model[:3, :3] = quat_to_matrix_np(random_quaternion(rng))
    model[:3, 3] = rng.uniform(-jitter, jitter, size=3)
    return perspective(fov_y_deg) @ translation(0.0, 0.0, -distance) @ model


# ---------------------------------------------------------------------------------------------
# Rendering.


def to_clip(mvp, pos):
    """Positions [V, 3] into clip space [1, V, 4] by ``mvp`` [4, 4] (a tensor)."""
    homogeneous = torch.cat([pos, torch.ones_like(pos[:, :1])], dim=1)
    return (homogeneous @ mvp.transpose(0, 1))[None]


def render(glctx, mvp, pos, tri, colour, colour_tri, resolution, topology=None):
    """The antialiased image [1, H, W, 3] of triangles ``tri`` over positions ``pos`` [V, 3],
    coloured by interpolating ``colour`` [C, 3] over ``colour_tri`` (same triangle count)."""
    clip = to_clip(mvp, pos)
    rast, _ = dr.rasterize(glctx, clip, tri, resolution=[resolution, resolution])
    image, _ = dr.interpolate(colour[None], rast, colour_tri)
    return dr.antialias(image, rast, clip, tri, topology_hash=topology)


# ---------------------------------------------------------------------------------------------
# The fit.


def fit_cube(resolution=16, iters=2000, lr=1e-2, lr_decay=0.1, log_every=10, seed=0,
             out_dir=None, quiet=False):
    """Runs one fit; returns a dict of its log (rows of iteration, errors, losses) and timing."""
    rng = np.random.default_rng(seed)
    glctx = dr.RasterizeCudaContext()

    true_pos = torch.from_numpy(cube_corners())
    true_col = torch.from_numpy(corner_colours())
    tri = torch.from_numpy(cube_triangles())
    topology = dr.antialias_construct_topology_hash(tri)

    init_pos = cube_corners() + rng.uniform(-0.5, 0.5, size=(8, 3)).astype(np.float32)
    init_col = rng.uniform(0.0, 1.0, size=(8, 3)).astype(np.float32)
    pos = torch.tensor(init_pos, requires_grad=True)
    col = torch.tensor(init_col, requires_grad=True)

    optimizer = torch.optim.Adam([pos, col], lr=lr)
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda it: max(0.01, lr_decay ** (it / 1000.0))
    )

    rows = []
    losses = []
    start = time.perf_counter()
    for it in range(iters + 1):
        with torch.no_grad():
            geom = float(torch.linalg.norm(pos - true_pos, dim=1).mean())
            geom_nv = float(torch.linalg.norm(pos.abs() - 0.5, dim=1).mean())
        mvp = torch.from_numpy(random_view(rng).astype(np.float32))
        with torch.no_grad():
            target = render(glctx, mvp, true_pos, tri, true_col, tri, resolution, topology)
        image = render(glctx, mvp, pos, tri, col, tri, resolution, topology)
        loss = torch.mean((image - target) ** 2)
        losses.append(float(loss))

        if it % log_every == 0 or it == iters:
            row = {
                "iteration": it,
                "geom_err": geom,
                "geom_err_nv": geom_nv,
                "image_loss": losses[-1],
                "image_loss_avg": float(np.mean(losses)),
                "seconds": time.perf_counter() - start,
            }
            losses = []
            rows.append(row)
            if not quiet:
                print(
                    f"res={resolution} it={it} geom_err={geom:.6f} geom_err_nv={geom_nv:.6f} "
                    f"loss={row['image_loss']:.6f} loss_avg={row['image_loss_avg']:.6f} "
                    f"t={row['seconds']:.1f}s",
                    flush=True,
                )
        if it == iters:
            break
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        schedule.step()

    wall = time.perf_counter() - start
    result = {
        "resolution": resolution, "seed": seed, "rows": rows, "wall_s": wall,
        "final_pos": pos.detach().numpy().copy(), "final_col": col.detach().numpy().copy(),
    }
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
        path = os.path.join(out_dir, f"cube_{resolution}_seed{seed}.csv")
        with open(path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
            writer.writeheader()
            writer.writerows(rows)
        result["csv"] = path
    return result


def error_at(rows, iteration):
    """The geometric error logged at ``iteration`` (None where it was not logged)."""
    for row in rows:
        if row["iteration"] == iteration:
            return row["geom_err"]
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resolution", type=int, default=16, help="image side in pixels")
    parser.add_argument("--iters", type=int, default=2000)
    parser.add_argument("--lr", type=float, default=1e-2, help="Adam's starting learning rate")
    parser.add_argument("--lr-decay", type=float, default=0.1,
                        help="learning-rate factor per 1000 iterations (floored at 0.01)")
    parser.add_argument("--log-every", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="folder for the CSV log")
    parser.add_argument("--quiet", action="store_true", help="print the summary line only")
    args = parser.parse_args()

    result = fit_cube(args.resolution, args.iters, args.lr, args.lr_decay, args.log_every,
                      args.seed, args.out, args.quiet)
    rows = result["rows"]
    start, end = rows[0]["geom_err"], rows[-1]["geom_err"]
    marks = " ".join(
        f"@{k}={error_at(rows, k):.5f}" for k in (100, 500, 1000, 2000)
        if error_at(rows, k) is not None
    )
    print(
        f"summary: resolution={args.resolution} seed={args.seed} iters={args.iters} "
        f"geom_err start={start:.5f} end={end:.5f} ({100.0 * end / start:.2f} % of start) "
        f"{marks} wall={result['wall_s']:.1f}s"
        + (f" csv={result['csv']}" if "csv" in result else "")
    )


if __name__ == "__main__":
    main()
