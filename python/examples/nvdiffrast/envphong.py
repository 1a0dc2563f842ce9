"""Learns an environment map (a cube map) and Phong parameters from renders of a shiny Spot from
random views, in the style of nvdiffrast's samples, on softvk's nvdiffrast API
(``softvk.nvdiffrast.torch``): rasterize -> interpolate the reflection vector with its pixel
derivatives -> texture (a cube map, 'linear-mipmap-linear', the level from those derivatives) ->
diffuse and Blinn-Phong terms -> antialias -> L2 -> backward.

    SOFTVK_VALIDATION=0 /usr/bin/python3 python/examples/nvdiffrast/envphong.py \
        --resolution 256 --iters 300 --out /tmp/nvsamples/envphong

The mesh is known and fixed (Spot, with area-weighted vertex normals). A pixel's colour is what
its reflection direction sees in the environment plus a diffuse and a Blinn-Phong term from one
light of known direction ``l``: ``env(r) + kd · max(n · l, 0) + ks · max(n · h, 0)^e``, where
``r`` is the view direction reflected about the normal at each vertex (interpolated, with its
pixel derivatives), ``n`` the interpolated normal and ``h`` the half vector of ``l`` and the
direction to the eye. (A highlight of ``r · l`` alone would be a function of ``r``, which the
environment absorbs: its parameters could not be told from the map. These terms depend on the
normal and the view, so they can.) The true environment is made here: a sky-to-ground gradient
with three coloured lights; the true ``kd`` is (0.3, 0.2, 0.1), ``ks`` (0.9, 0.8, 0.6) and ``e``
40. The learned environment starts a uniform grey (0.5), ``kd`` and ``ks`` at 0.2 and ``e`` at 8
(learned through its logarithm).

Each iteration draws a random camera orbiting the cow and takes one Adam step on the mean
squared pixel difference. The image error is the mean squared difference over
``--eval-views`` fixed cameras; the environment's error is the RMS over its texels (every
direction is seen from some view, but not all equally often). Writes ``envphong_<resolution>.csv``
to ``--out`` (one row every ``--log-every`` iterations, measured before that iteration's step)
and prints a summary line.
"""

import argparse
import csv
import os
import pathlib
import sys
import time

import numpy as np
import torch

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import mesh  # noqa: E402  (this folder's mesh.py: Spot and the cameras)

import softvk.nvdiffrast.torch as dr  # noqa: E402

LIGHT = np.array([-0.3, 0.9, 0.3]) / np.linalg.norm([-0.3, 0.9, 0.3])
TRUE_KD = (0.3, 0.2, 0.1)
TRUE_KS = (0.9, 0.8, 0.6)
TRUE_EXPONENT = 40.0


def face_directions(size):
    """The unit direction through each texel centre of a cube map, [6, size, size, 3], faces
    +x, -x, +y, -y, +z, -z by OpenGL's table (s across, t down the rows)."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    a, b = np.meshgrid(c, c)  # a: along s (columns), b: along t (rows)
    one = np.ones_like(a)
    faces = [
        (one, -b, -a), (-one, -b, a), (a, one, b), (a, -one, -b), (a, -b, one), (-a, -b, -one),
    ]
    d = np.stack([np.stack(f, -1) for f in faces])
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def true_environment(size):
    """The environment made here, float32 [1, 6, size, size, 3]: a warm ground, a blue sky
    brightening to the horizon, and three soft coloured lights."""
    d = face_directions(size)
    y = d[..., 1:2]
    sky = np.array([0.25, 0.45, 0.9]) * (0.6 + 0.4 * (1.0 - y)) * (y > 0)
    ground = np.array([0.45, 0.35, 0.2]) * (0.5 + 0.5 * -y) * (y <= 0)
    env = sky + ground
    for centre, colour, width in (
        ((0.6, 0.5, 0.6), (1.0, 0.9, 0.5), 0.12),
        ((-0.7, 0.2, -0.3), (0.3, 1.0, 0.4), 0.2),
        ((0.1, -0.3, -0.9), (1.0, 0.3, 0.6), 0.25),
    ):
        c = np.asarray(centre) / np.linalg.norm(centre)
        closeness = (d @ c)[..., None]
        env = env + np.asarray(colour) * np.exp((closeness - 1.0) / width)
    return torch.from_numpy(env.astype(np.float32))[None].contiguous()


class Scene:
    """Spot with vertex normals, and the pieces of one render."""

    def __init__(self, resolution):
        pos, tri, _, _ = mesh.load_obj()
        self.glctx = dr.RasterizeCudaContext()
        self.resolution = resolution
        self.pos = torch.from_numpy(pos)
        self.tri = torch.from_numpy(tri)
        self.normals = torch.from_numpy(mesh.vertex_normals(pos, tri))
        self.light = torch.from_numpy(LIGHT.astype(np.float32))
        self.topology = dr.antialias_construct_topology_hash(self.tri)

    def render(self, mvp, eye, env, kd, ks, log_e):
        """The antialiased image [1, H, W, 3] of Spot reflecting ``env``, with diffuse ``kd``
        and highlight ``ks``, exponent ``exp(log_e)``, seen from ``eye`` by ``mvp``."""
        clip = mesh.to_clip(mvp, self.pos)
        res = [self.resolution, self.resolution]
        rast, rast_db = dr.rasterize(self.glctx, clip, self.tri, resolution=res)
        view = self.pos - eye
        view = view / torch.linalg.norm(view, dim=1, keepdim=True)
        n = self.normals
        refl = view - 2.0 * (view * n).sum(1, keepdim=True) * n
        r, r_da = dr.interpolate(refl[None].contiguous(), rast, self.tri, rast_db=rast_db,
                                 diff_attrs="all")
        seen = dr.texture(env, r, r_da, filter_mode="linear-mipmap-linear", boundary_mode="cube")
        # The normal and the direction to the eye, per pixel.
        n_eye, _ = dr.interpolate(torch.cat([n, -view], 1)[None].contiguous(), rast, self.tri)

        def unit(v):
            return v / torch.linalg.norm(v, dim=-1, keepdim=True).clamp_min(1e-6)

        n_pix, to_eye = unit(n_eye[..., :3]), unit(n_eye[..., 3:])
        half = unit(to_eye + self.light)
        diffuse = torch.clamp((n_pix * self.light).sum(-1, keepdim=True), min=0.0)
        spec = torch.clamp((n_pix * half).sum(-1, keepdim=True), min=1e-8)
        colour = seen + kd * diffuse + ks * torch.pow(spec, torch.exp(log_e))
        colour = colour * (rast[..., 3:] > 0)
        return dr.antialias(colour.contiguous(), rast, clip, self.tri,
                            topology_hash=self.topology)


def fit_envphong(resolution=256, iters=300, env_size=64, lr=0.03, eval_views=4, log_every=10,
                 seed=0, out_dir=None, quiet=False):
    """Runs one fit; returns a dict of its log rows and timing."""
    rng = np.random.default_rng(seed)
    scene = Scene(resolution)
    true_env = true_environment(env_size)
    true_kd = torch.tensor(TRUE_KD)
    true_ks = torch.tensor(TRUE_KS)
    true_log_e = torch.tensor(np.log(TRUE_EXPONENT), dtype=torch.float32)
    env = torch.full_like(true_env, 0.5).requires_grad_()
    kd = torch.full((3,), 0.2).requires_grad_()
    ks = torch.full((3,), 0.2).requires_grad_()
    log_e = torch.tensor(np.log(8.0), dtype=torch.float32).requires_grad_()
    optimizer = torch.optim.Adam([env, kd, ks, log_e], lr=lr)
    cameras = [mesh.random_camera(np.random.default_rng(2000 + k)) for k in range(eval_views)]
    with torch.no_grad():
        targets = [scene.render(mvp, eye, true_env, true_kd, true_ks, true_log_e)
                   for mvp, eye in cameras]

    def errors():
        with torch.no_grad():
            env_rms = float(torch.sqrt(((env - true_env) ** 2).mean()))
            image = float(np.mean([
                float(torch.mean((scene.render(mvp, eye, env, kd, ks, log_e) - t) ** 2))
                for (mvp, eye), t in zip(cameras, targets)
            ]))
        return env_rms, image

    rows = []
    start = time.perf_counter()
    step_seconds = 0.0
    for it in range(iters + 1):
        if it % log_every == 0 or it == iters:
            env_rms, image = errors()
            row = {"iteration": it, "image_mse": image, "env_rms": env_rms,
                   "kd_r": float(kd[0]), "kd_g": float(kd[1]), "kd_b": float(kd[2]),
                   "ks_r": float(ks[0]), "ks_g": float(ks[1]), "ks_b": float(ks[2]),
                   "exponent": float(torch.exp(log_e)), "step_seconds": step_seconds}
            rows.append(row)
            if not quiet:
                print(f"it={it} image_mse={image:.6f} env_rms={env_rms:.4f} "
                      f"kd={[round(float(k), 3) for k in kd]} "
                      f"ks={[round(float(k), 3) for k in ks]} e={row['exponent']:.1f} "
                      f"steps={step_seconds:.1f}s", flush=True)
        if it == iters:
            break
        t0 = time.perf_counter()
        mvp, eye = mesh.random_camera(rng)
        with torch.no_grad():
            target = scene.render(mvp, eye, true_env, true_kd, true_ks, true_log_e)
        loss = torch.mean((scene.render(mvp, eye, env, kd, ks, log_e) - target) ** 2)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        with torch.no_grad():
            env.clamp_(min=0.0)
            kd.clamp_(min=0.0)
            ks.clamp_(min=0.0)
        step_seconds += time.perf_counter() - t0

    result = {"resolution": resolution, "env_size": env_size, "rows": rows,
              "wall_s": time.perf_counter() - start, "step_s": step_seconds}
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
        path = os.path.join(out_dir, f"envphong_{resolution}.csv")
        with open(path, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
            writer.writeheader()
            writer.writerows(rows)
        result["csv"] = path
    return result


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--resolution", type=int, default=256)
    p.add_argument("--iters", type=int, default=300)
    p.add_argument("--env-size", type=int, default=64)
    p.add_argument("--lr", type=float, default=0.03)
    p.add_argument("--eval-views", type=int, default=4)
    p.add_argument("--log-every", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None)
    args = p.parse_args()
    r = fit_envphong(args.resolution, args.iters, args.env_size, args.lr, args.eval_views,
                     args.log_every, args.seed, args.out)
    first, last = r["rows"][0], r["rows"][-1]
    print(
        f"envphong {args.resolution}²: image MSE {first['image_mse']:.5f} -> "
        f"{last['image_mse']:.5f} ({last['image_mse'] / first['image_mse']:.3f} of the start), "
        f"environment RMS {first['env_rms']:.4f} -> {last['env_rms']:.4f}, kd "
        f"{[round(last[k], 3) for k in ('kd_r', 'kd_g', 'kd_b')]} (true {list(TRUE_KD)}), ks "
        f"{[round(last[k], 3) for k in ('ks_r', 'ks_g', 'ks_b')]} (true {list(TRUE_KS)}), "
        f"e {last['exponent']:.1f} (true {TRUE_EXPONENT}), {args.iters} iterations, "
        f"{r['step_s']:.0f} s of steps ({1e3 * r['step_s'] / args.iters:.0f} ms each)"
    )


if __name__ == "__main__":
    main()
