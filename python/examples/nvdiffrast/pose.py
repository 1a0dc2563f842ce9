"""Recovers a coloured cube's rotation from one image of it, in the style of nvdiffrast's pose
sample, on softvk's nvdiffrast API (``softvk.nvdiffrast.torch``).

    SOFTVK_VALIDATION=0 python python/examples/nvdiffrast/pose.py --targets 10 --resolution 64 \
        --out /tmp/nvsamples/pose

The cube is cube.py's (8 corners at +-0.5, 12 outward-wound triangles). Each face has its own
colour (six distinct colours), shaded across the face: the colour times a different brightness
at each of the face's four corners (1.0, 0.8, 0.6, 0.4 around it), interpolated. The shading
matters: with flat face colours a view straight at one face looks the same after a quarter or
half turn about the view axis, and a search can settle there; shaded, no rotation of the cube
other than the identity leaves its image unchanged from any view, so the angular error needs no
reduction by the cube's symmetry group. (``--colouring face`` gives the flat colours.) The
colours come through a second index buffer (each triangle's colour indices pick its face's
entries), as nvdiffrast's samples do; antialias uses the position triangles.

For each target (a uniformly random rotation from ``--seed`` + the target's number), the target
image is rendered once at ``--resolution``, camera fixed 3.5 away with a 45-degree perspective
projection. Then, all renders antialiased (rasterize -> interpolate -> antialias) and the loss
the mean squared pixel difference to the target:

1. **Greedy random search**: ``--candidates`` uniformly random rotations, rendered as
   minibatches of ``--batch``; the best by image loss is kept. Then ``--refine-rounds`` rounds,
   each trying ``--batch`` perturbations of the best so far by random rotations of up to a
   shrinking angle (``--refine-start`` degrees down to ``--refine-end``), half of them also
   composed with a random one of the cube's 24 rotations, plus the best itself under each of the
   23 other rotations of the cube; any trial that lowers the loss becomes the best.
2. **Gradient descent**: Adam on the quaternion (rendered through the rotation of the normalised
   quaternion), renormalised after each step, ``--iters`` steps, the learning rate decaying
   exponentially from ``--lr`` to ``--lr * --lr-end``.

nvdiffrast's sample differs in these: its search is a noise phase over the first half of its
iterations (one perturbed render per iteration: a random rotation slerped toward the identity by
a decaying amount, composed with a random one of the cube's 24 rotations; the best kept), its
faces are flat-coloured, its loss is ``tanh(5 * max over channels of the squared difference)``,
and its image is 256 x 256. Here the search is batched (one rasterize call per minibatch of
candidates), the loss is plain L2, and the image smaller (the cost on a CPU Vulkan device grows
with the pixels).

The angular error between two unit quaternions p and q is ``2 acos(|p . q|)`` in degrees (the
absolute value accounts for q and -q being one rotation). Prints one line per target and a
summary, and writes ``pose.csv`` (one row per target) and ``pose_target<k>.csv`` (the error
every ``--log-every`` gradient steps) to ``--out``.
"""

import argparse
import csv
import itertools
import os
import pathlib
import sys
import time

import numpy as np
import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import cube  # noqa: E402  (this folder's cube.py: the geometry and the camera)

import softvk.nvdiffrast.torch as dr  # noqa: E402

# ---------------------------------------------------------------------------------------------
# The face-coloured cube.

FACE_COLOURS = np.array(
    [
        [0.90, 0.15, 0.15],  # -x: red
        [0.15, 0.75, 0.20],  # +x: green
        [0.15, 0.30, 0.90],  # -y: blue
        [0.95, 0.85, 0.15],  # +y: yellow
        [0.85, 0.20, 0.85],  # -z: magenta
        [0.20, 0.85, 0.85],  # +z: cyan
    ],
    dtype=np.float32,
)


# Brightness at the four corners of a face, in cube.cube_faces()'s cycle around it: four different
# values, so that no quarter turn of a face looks the same.
CORNER_SHADES = np.array([1.0, 0.8, 0.6, 0.4], dtype=np.float32)


def colouring(mode):
    """The colour table [C, 3] and the colour triangles [12, 3] (int32 indices into it) of
    ``mode``: ``'face'``, one flat colour per face (C = 6; triangle t takes face t // 2's, as
    cube.cube_triangles() puts face f's two triangles at 2f and 2f + 1), or ``'shaded'``, each
    face's colour times CORNER_SHADES at its four corners (C = 24, entry 4f + j for corner j of
    face f's cycle), interpolated over the face."""
    if mode == "face":
        tri = np.repeat(np.arange(6, dtype=np.int32), 2)[:, None].repeat(3, axis=1)
        return FACE_COLOURS.copy(), tri
    if mode != "shaded":
        raise ValueError(f"unknown colouring {mode!r}")
    table = (FACE_COLOURS[:, None, :] * CORNER_SHADES[None, :, None]).reshape(24, 3)
    tri = cube.cube_triangles()
    colour_tri = np.empty_like(tri)
    for f, (_, _, cycle) in enumerate(cube.cube_faces()):
        for t in (2 * f, 2 * f + 1):
            colour_tri[t] = [4 * f + cycle.index(int(v)) for v in tri[t]]
    return table.astype(np.float32), colour_tri.astype(np.int32)


# ---------------------------------------------------------------------------------------------
# Quaternions (w, x, y, z).


def quat_to_matrix(q):
    """The 3 x 3 rotation matrices of quaternions ``q`` [..., 4] (normalised here)."""
    q = q / torch.linalg.norm(q, dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    rows = [
        torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ]
    return torch.stack(rows, -2)


def quat_mul(p, q):
    """The Hamilton product p q of numpy quaternions [..., 4] (rotation q, then p)."""
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        -1,
    )


def random_quaternions(rng, n):
    """n uniformly random unit quaternions [n, 4]."""
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def small_rotations(rng, n, angle_deg):
    """n rotations [n, 4] about uniformly random axes by angles drawn uniformly from
    [0, angle_deg]."""
    axis = rng.standard_normal((n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    half = np.radians(rng.uniform(0.0, angle_deg, size=n)) / 2.0
    return np.concatenate([np.cos(half)[:, None], np.sin(half)[:, None] * axis], axis=1)


def matrix_to_quat(m):
    """The unit quaternion (w >= 0) of a 3 x 3 rotation matrix (numpy)."""
    m = np.asarray(m, dtype=np.float64)
    # The largest of 4 w^2, 4 x^2, 4 y^2, 4 z^2 gives the best-conditioned formula.
    t = [1 + m[0, 0] + m[1, 1] + m[2, 2], 1 + m[0, 0] - m[1, 1] - m[2, 2],
         1 - m[0, 0] + m[1, 1] - m[2, 2], 1 - m[0, 0] - m[1, 1] + m[2, 2]]
    k = int(np.argmax(t))
    s = 2.0 * np.sqrt(t[k])
    if k == 0:
        q = [s / 4, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif k == 1:
        q = [(m[2, 1] - m[1, 2]) / s, s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif k == 2:
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s]
    else:
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4]
    q = np.asarray(q)
    return q if q[0] >= 0 else -q


def cube_rotations():
    """The 24 rotations that map the cube onto itself, as quaternions [24, 4]: the signed
    permutation matrices of determinant +1."""
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            for row, (col, sign) in enumerate(zip(perm, signs)):
                m[row, col] = sign
            if np.linalg.det(m) > 0:
                out.append(matrix_to_quat(m))
    return np.asarray(out)


def angle_deg(p, q):
    """The angle in degrees of the rotation taking unit quaternion p to q (either sign)."""
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    d = abs(float(np.dot(p / np.linalg.norm(p), q / np.linalg.norm(q))))
    return float(np.degrees(2.0 * np.arccos(min(1.0, d))))


CUBE_ROTATIONS = cube_rotations()

# ---------------------------------------------------------------------------------------------
# Rendering.


class Scene:
    """The cube, the camera and the context, rendering a minibatch of rotations at once."""

    def __init__(self, resolution, mode="shaded"):
        self.glctx = dr.RasterizeCudaContext()
        self.resolution = resolution
        self.pos = torch.from_numpy(cube.cube_corners())
        self.tri = torch.from_numpy(cube.cube_triangles())
        table, colour_tri = colouring(mode)
        self.colour = torch.from_numpy(table)
        self.colour_tri = torch.from_numpy(colour_tri)
        self.topology = dr.antialias_construct_topology_hash(self.tri)
        view = cube.perspective(45.0) @ cube.translation(0.0, 0.0, -3.5)
        self.view = torch.from_numpy(view.astype(np.float32))

    def render(self, q):
        """The antialiased images [B, H, W, 3] of the cube rotated by quaternions q [B, 4]."""
        rot = quat_to_matrix(q)  # [B, 3, 3]
        world = self.pos[None] @ rot.transpose(1, 2)  # [B, 8, 3]
        homogeneous = torch.cat([world, torch.ones_like(world[..., :1])], dim=-1)
        clip = (homogeneous @ self.view.transpose(0, 1)).contiguous()  # [B, 8, 4]
        res = [self.resolution, self.resolution]
        rast, _ = dr.rasterize(self.glctx, clip, self.tri, resolution=res)
        image, _ = dr.interpolate(self.colour, rast, self.colour_tri)
        return dr.antialias(image, rast, clip, self.tri, topology_hash=self.topology)

    def losses(self, q, target):
        """The image loss of each rotation in q [B, 4] against target [1, H, W, 3]."""
        return ((self.render(q) - target) ** 2).mean(dim=(1, 2, 3))


def batched_losses(scene, quats, target, batch):
    """Image losses [N] of numpy quaternions [N, 4], rendered ``batch`` at a time."""
    out = []
    with torch.no_grad():
        for start in range(0, len(quats), batch):
            q = torch.from_numpy(quats[start:start + batch].astype(np.float32))
            out.append(scene.losses(q, target).numpy())
    return np.concatenate(out)


# ---------------------------------------------------------------------------------------------
# One target.


def fit_pose(scene, target_q, rng, args, log_rows=None):
    """Fits one target rotation; returns a dict of the search's and the descent's outcome."""
    with torch.no_grad():
        target = scene.render(torch.from_numpy(target_q[None].astype(np.float32)))

    # 1. Greedy random search: uniform candidates, then shrinking perturbations of the best.
    candidates = random_quaternions(rng, args.candidates)
    losses = batched_losses(scene, candidates, target, args.batch)
    best = candidates[int(np.argmin(losses))]
    best_loss = float(np.min(losses))
    evaluated = len(candidates)
    uniform_best_err = angle_deg(best, target_q)
    for r in range(args.refine_rounds):
        t = r / max(1, args.refine_rounds - 1)
        spread = args.refine_start * (args.refine_end / args.refine_start) ** t
        trial = quat_mul(small_rotations(rng, args.batch, spread), best[None])
        # A share of the trials also jump by one of the cube's 24 rotations (the colouring tells
        # them apart; the silhouette does not), to leave a pose whose outline matches but
        # whose faces are wrong.
        jumps = int(round(args.jump_share * args.batch))
        if jumps:
            symmetry = CUBE_ROTATIONS[rng.integers(0, 24, size=jumps)]
            trial[:jumps] = quat_mul(trial[:jumps], symmetry)
        if args.symmetric_trials:
            # And the best itself under each of the 23 other rotations of the cube, unperturbed.
            trial = np.concatenate([quat_mul(best[None], CUBE_ROTATIONS[1:]), trial])
        trial_losses = batched_losses(scene, trial, target, args.batch)
        evaluated += len(trial)
        i = int(np.argmin(trial_losses))
        if trial_losses[i] < best_loss:
            best, best_loss = trial[i], float(trial_losses[i])
    search_err = angle_deg(best, target_q)

    # 2. Gradient descent on the quaternion.
    final, final_loss, first_below = descend(scene, target, target_q, best, args, log_rows)
    return {
        "uniform_best_err": uniform_best_err,
        "search_err": search_err,
        "search_loss": best_loss,
        "evaluated": evaluated,
        "final_err": angle_deg(final, target_q),
        "final_loss": final_loss,
        "iters": args.iters,
        "first_below": first_below,
        "final_q": final,
    }


def descend(scene, target, target_q, start_q, args, log_rows=None):
    """Adam on the quaternion from ``start_q`` toward the image ``target`` for ``args.iters``
    steps; returns (the final unit quaternion, its image loss, the step from which the error
    stayed below ``args.threshold`` degrees, or None)."""
    q = torch.tensor(np.asarray(start_q)[None].astype(np.float32), requires_grad=True)
    optimizer = torch.optim.Adam([q], lr=args.lr)
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda it: args.lr_end ** (it / max(1, args.iters))
    )
    first_below = None
    loss = None
    for it in range(args.iters + 1):
        err = angle_deg(q.detach().numpy()[0], target_q)
        if err < args.threshold and first_below is None:
            first_below = it
        elif err >= args.threshold:
            first_below = None
        loss = scene.losses(q, target).mean()
        if log_rows is not None and (it % args.log_every == 0 or it == args.iters):
            log_rows.append({"iteration": it, "angle_deg": err, "image_loss": float(loss)})
        if it == args.iters:
            break
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        schedule.step()
        with torch.no_grad():
            q /= torch.linalg.norm(q)
    return q.detach().numpy()[0].copy(), float(loss), first_below


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--targets", type=int, default=10, help="how many random targets")
    parser.add_argument("--seed", type=int, default=100, help="target k uses seed + k")
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--colouring", choices=["shaded", "face"], default="shaded",
                        help="face colours shaded across each face (default), or flat")
    parser.add_argument("--candidates", type=int, default=256, help="uniform search samples")
    parser.add_argument("--batch", type=int, default=32, help="renders per minibatch")
    parser.add_argument("--refine-rounds", type=int, default=16)
    parser.add_argument("--refine-start", type=float, default=45.0, help="degrees")
    parser.add_argument("--refine-end", type=float, default=2.0, help="degrees")
    parser.add_argument("--jump-share", type=float, default=0.5,
                        help="share of each refinement round's trials that also apply a random "
                        "one of the cube's 24 rotations")
    parser.add_argument("--symmetric-trials", type=int, default=1,
                        help="1: each refinement round also tries the best under the cube's 23 "
                        "other rotations")
    parser.add_argument("--iters", type=int, default=1000, help="gradient steps")
    parser.add_argument("--lr", type=float, default=1e-2)
    parser.add_argument("--lr-end", type=float, default=0.01,
                        help="final learning rate as a fraction of --lr")
    parser.add_argument("--threshold", type=float, default=1.0, help="degrees, for the count")
    parser.add_argument("--log-every", type=int, default=50)
    parser.add_argument("--out", default=None, help="folder for the CSV logs")
    args = parser.parse_args()

    scene = Scene(args.resolution, args.colouring)
    results = []
    start_all = time.perf_counter()
    for k in range(args.targets):
        rng = np.random.default_rng(args.seed + k)
        target_q = random_quaternions(rng, 1)[0]
        log_rows = []
        start = time.perf_counter()
        r = fit_pose(scene, target_q, rng, args, log_rows)
        r["target"] = k
        r["seed"] = args.seed + k
        r["seconds"] = time.perf_counter() - start
        results.append(r)
        below = "never" if r["first_below"] is None else str(r["first_below"])
        print(
            f"target={k} seed={r['seed']} uniform_best={r['uniform_best_err']:.2f}deg "
            f"search={r['search_err']:.3f}deg ({r['evaluated']} renders) "
            f"final={r['final_err']:.4f}deg after {r['iters']} steps "
            f"(< {args.threshold:g} deg from step {below}) loss={r['final_loss']:.3g} "
            f"t={r['seconds']:.1f}s",
            flush=True,
        )
        if args.out:
            os.makedirs(args.out, exist_ok=True)
            with open(os.path.join(args.out, f"pose_target{k}.csv"), "w", newline="") as f:
                writer = csv.DictWriter(f, fieldnames=list(log_rows[0].keys()))
                writer.writeheader()
                writer.writerows(log_rows)

    wall = time.perf_counter() - start_all
    within = sum(r["final_err"] < args.threshold for r in results)
    if args.out:
        with open(os.path.join(args.out, "pose.csv"), "w", newline="") as f:
            fields = ["target", "seed", "uniform_best_err", "search_err", "evaluated",
                      "final_err", "iters", "first_below", "final_loss", "seconds"]
            writer = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
            writer.writeheader()
            writer.writerows(results)
    errs = np.array([r["final_err"] for r in results])
    print(
        f"summary: resolution={args.resolution} targets={args.targets} within "
        f"{args.threshold:g} deg: {within}/{args.targets}; final error median "
        f"{np.median(errs):.4f} max {errs.max():.4f} deg; wall={wall:.1f}s"
    )


if __name__ == "__main__":
    main()
