"""Learns Spot's albedo map from renders of the textured cow from random views, in the style of
nvdiffrast's samples, on softvk's nvdiffrast API (``softvk.nvdiffrast.torch``): rasterize ->
interpolate the texture coordinates with their pixel derivatives -> texture
('linear-mipmap-linear', the level from those derivatives) -> antialias -> L2 -> backward.

    SOFTVK_VALIDATION=0 /usr/bin/python3 python/examples/nvdiffrast/albedo.py \
        --resolution 256 --iters 300 --out /tmp/nvsamples/albedo

The true albedo is Spot's texture (``assets/spot_texture.png``) box-filtered to ``--tex-size``
texels a side; the learned one starts a uniform grey (0.5). Each iteration draws a random camera
orbiting the cow, renders the true and the learned albedo under the same fixed Lambertian light
(so that shape shows and the albedo must be recovered under shading), and takes one Adam step on
the mean squared pixel difference.

The albedo's error is the RMS difference from the true map over the texels the mesh's texture
chart covers (the texels whose centre falls inside a triangle of the UV layout, found by
rasterizing the layout itself); texels outside the chart are never sampled and are left out.
The image error is the mean squared difference over ``--eval-views`` fixed cameras. Writes
``albedo_<resolution>.csv`` (one row every ``--log-every`` iterations, measured before that
iteration's step) to ``--out`` and prints a summary line.
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

LIGHT = np.array([0.4, 0.8, 0.45]) / np.linalg.norm([0.4, 0.8, 0.45])


def true_albedo(size):
    """Spot's texture, box-filtered to ``size`` x ``size``, float32 [1, size, size, 3], row 0
    at v = 0 (the image's bottom row, as OBJ texture coordinates put it)."""
    from PIL import Image

    image = np.asarray(Image.open(mesh.ASSETS / "spot_texture.png").convert("RGB"), np.float64)
    h, w, _ = image.shape
    if h % size or w % size:
        raise ValueError(f"--tex-size {size} must divide the texture's {h} x {w}")
    boxed = image.reshape(size, h // size, size, w // size, 3).mean((1, 3)) / 255.0
    return torch.from_numpy(boxed[::-1].copy().astype(np.float32))[None]


def chart_mask(glctx, uv, uv_tri, size):
    """Which texels of a ``size``² map the UV layout covers: [size, size] bool (the layout
    rasterized with u, v as x, y; row 0 at v = 0, as the texture's)."""
    clip = torch.cat([2.0 * uv - 1.0, torch.zeros_like(uv[:, :1]), torch.ones_like(uv[:, :1])], 1)
    rast, _ = dr.rasterize(glctx, clip[None].contiguous(), uv_tri, resolution=[size, size])
    return rast[0, ..., 3] > 0


class Scene:
    """Spot with its texture coordinates, and the pieces of one render."""

    def __init__(self, resolution):
        pos, tri, uv, uv_tri = mesh.load_obj()
        self.glctx = dr.RasterizeCudaContext()
        self.resolution = resolution
        self.pos = torch.from_numpy(pos)
        self.tri = torch.from_numpy(tri)
        self.uv = torch.from_numpy(uv)
        self.uv_tri = torch.from_numpy(uv_tri)
        normals = mesh.vertex_normals(pos, tri)
        shade = 0.25 + 0.75 * np.clip(normals @ LIGHT, 0.0, None)
        self.shade = torch.from_numpy(shade.astype(np.float32)[:, None])
        self.topology = dr.antialias_construct_topology_hash(self.tri)

    def render(self, mvp, albedo):
        """The antialiased image [1, H, W, 3] of Spot with ``albedo`` under the fixed light."""
        clip = mesh.to_clip(mvp, self.pos)
        res = [self.resolution, self.resolution]
        rast, rast_db = dr.rasterize(self.glctx, clip, self.tri, resolution=res)
        texc, texd = dr.interpolate(self.uv[None], rast, self.uv_tri, rast_db=rast_db,
                                    diff_attrs="all")
        shade, _ = dr.interpolate(self.shade[None], rast, self.tri)
        colour = dr.texture(albedo, texc, texd, filter_mode="linear-mipmap-linear")
        colour = colour * shade * (rast[..., 3:] > 0)
        return dr.antialias(colour, rast, clip, self.tri, topology_hash=self.topology)


def fit_albedo(resolution=256, iters=300, tex_size=256, lr=0.03, eval_views=4, log_every=10,
               seed=0, out_dir=None, quiet=False):
    """Runs one fit; returns a dict of its log rows and timing."""
    rng = np.random.default_rng(seed)
    scene = Scene(resolution)
    truth = true_albedo(tex_size)
    mask = chart_mask(scene.glctx, scene.uv, scene.uv_tri, tex_size)
    albedo = torch.full_like(truth, 0.5).requires_grad_()
    optimizer = torch.optim.Adam([albedo], lr=lr)
    cameras = [mesh.random_camera(np.random.default_rng(1000 + k))[0] for k in range(eval_views)]
    with torch.no_grad():
        targets = [scene.render(mvp, truth) for mvp in cameras]

    def errors():
        with torch.no_grad():
            tex_rms = float(torch.sqrt(((albedo - truth)[0][mask] ** 2).mean()))
            image = float(np.mean([
                float(torch.mean((scene.render(mvp, albedo) - t) ** 2))
                for mvp, t in zip(cameras, targets)
            ]))
        return tex_rms, image

    rows = []
    start = time.perf_counter()
    step_seconds = 0.0
    for it in range(iters + 1):
        if it % log_every == 0 or it == iters:
            tex_rms, image = errors()
            rows.append({"iteration": it, "albedo_rms": tex_rms, "image_mse": image,
                         "step_seconds": step_seconds})
            if not quiet:
                print(f"it={it} albedo_rms={tex_rms:.5f} image_mse={image:.6f} "
                      f"steps={step_seconds:.1f}s", flush=True)
        if it == iters:
            break
        t0 = time.perf_counter()
        mvp, _ = mesh.random_camera(rng)
        with torch.no_grad():
            target = scene.render(mvp, truth)
        loss = torch.mean((scene.render(mvp, albedo) - target) ** 2)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        with torch.no_grad():
            albedo.clamp_(0.0, 1.0)
        step_seconds += time.perf_counter() - t0

    result = {"resolution": resolution, "tex_size": tex_size, "rows": rows,
              "wall_s": time.perf_counter() - start, "step_s": step_seconds,
              "chart_texels": int(mask.sum()), "albedo": albedo.detach()}
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
        path = os.path.join(out_dir, f"albedo_{resolution}.csv")
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
    p.add_argument("--tex-size", type=int, default=256)
    p.add_argument("--lr", type=float, default=0.03)
    p.add_argument("--eval-views", type=int, default=4)
    p.add_argument("--log-every", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None)
    args = p.parse_args()
    r = fit_albedo(args.resolution, args.iters, args.tex_size, args.lr, args.eval_views,
                   args.log_every, args.seed, args.out)
    first, last = r["rows"][0], r["rows"][-1]
    print(
        f"albedo {args.resolution}²: albedo RMS {first['albedo_rms']:.4f} -> "
        f"{last['albedo_rms']:.4f} ({last['albedo_rms'] / first['albedo_rms']:.3f} of the start), "
        f"image MSE {first['image_mse']:.5f} -> {last['image_mse']:.5f} "
        f"({last['image_mse'] / first['image_mse']:.3f}), {args.iters} iterations, "
        f"{r['step_s']:.0f} s of steps ({1e3 * r['step_s'] / args.iters:.0f} ms each), "
        f"{r['chart_texels']} chart texels"
    )


if __name__ == "__main__":
    main()
