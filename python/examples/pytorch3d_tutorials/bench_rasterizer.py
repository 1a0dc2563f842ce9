"""PyTorch3D's rasterizer against softvk's, in one run: the fragment pass alone, with the
projection, with its backward, and a whole optimization iteration, on CPU tensors.

    python bench_rasterizer.py [--image-size 256] [--faces-per-pixel 50] [--repeat 5]

The scene is spot (the cow of ``assets/``, 5 856 faces) through a ``FoVPerspectiveCameras``
filling most of the image, rasterized as PyTorch3D's silhouette tutorials do
(``blur_radius = log(1 / 1e-4 - 1) * 1e-4``). Each measurement alternates the two rasterizers,
``--repeat`` rounds after one warm-up call each, and reports medians:

- ``fragment_pass``: each package's ``rasterize_meshes`` alone, on the meshes already projected,
  with the settings ``MeshRasterizer`` derives (perspective correction, clipped barycentrics,
  the near-plane clip at znear / 2);
- ``forward``: ``MeshRasterizer(meshes)`` (PyTorch3D's projection, then the fragment pass);
- ``forward_backward``: that and ``torch.autograd.grad`` of a loss over every output;
- ``iteration``: one step of the "fit a mesh" tutorial's silhouette loop (``fit_mesh.py``'s: a
  level-4 icosphere's offsets, two views' ``SoftSilhouetteShader`` renders against spot's, edge,
  normal and Laplacian terms, SGD).

Prints one JSON line, with softvk's GPU pass times.
"""

import argparse
import json
import math
import os
import pathlib
import statistics
import time

import torch


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--image-size", type=int, default=256)
    parser.add_argument("--faces-per-pixel", type=int, default=50)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--mesh", default=None, help="OBJ (default: the repository's spot)")
    args = parser.parse_args()

    from pytorch3d.io import load_objs_as_meshes
    from pytorch3d.loss import mesh_edge_loss, mesh_laplacian_smoothing, mesh_normal_consistency
    from pytorch3d.renderer import (
        BlendParams,
        FoVPerspectiveCameras,
        MeshRasterizer,
        MeshRenderer,
        RasterizationSettings,
        SoftSilhouetteShader,
        look_at_view_transform,
    )
    from pytorch3d.utils import ico_sphere

    import softvk
    from softvk.pytorch3d import MeshRasterizer as SoftvkRasterizer

    repo = pathlib.Path(__file__).resolve().parents[3]
    path = args.mesh or str(repo / "assets" / "spot_triangulated.obj")
    mesh = load_objs_as_meshes([path], load_textures=False)
    verts = mesh.verts_packed()
    verts = (verts - verts.mean(0)) / (verts - verts.mean(0)).norm(dim=1).max()
    R, T = look_at_view_transform(2.0, 10, 30)
    cameras = FoVPerspectiveCameras(R=R, T=T)
    settings = RasterizationSettings(
        image_size=args.image_size,
        blur_radius=math.log(1.0 / 1e-4 - 1.0) * 1e-4,
        faces_per_pixel=args.faces_per_pixel,
    )
    rasterizers = {
        "pytorch3d": MeshRasterizer(cameras=cameras, raster_settings=settings),
        "softvk": SoftvkRasterizer(cameras=cameras, raster_settings=settings),
    }
    gen = torch.Generator().manual_seed(0)
    weights = None

    def forward(name, v):
        return rasterizers[name](mesh.update_padded(v[None]))

    # The fragment pass alone: each package's `rasterize_meshes` on the meshes already in NDC,
    # with the settings MeshRasterizer derives (PyTorch3D's projection, done once here).
    from pytorch3d.renderer.mesh.rasterize_meshes import rasterize_meshes as p3d_rasterize_meshes

    from softvk.pytorch3d import rasterize_meshes as softvk_rasterize_meshes

    projected = rasterizers["pytorch3d"].transform(mesh.update_padded(verts[None]))
    pass_args = dict(
        image_size=settings.image_size,
        blur_radius=settings.blur_radius,
        faces_per_pixel=settings.faces_per_pixel,
        perspective_correct=True,
        clip_barycentric_coords=True,
        z_clip_value=cameras.get_znear().min().item() / 2,
    )
    passes_fn = {"pytorch3d": p3d_rasterize_meshes, "softvk": softvk_rasterize_meshes}

    def fragment_pass(name):
        return passes_fn[name](projected, **pass_args)

    def forward_backward(name):
        nonlocal weights
        v = verts.detach().clone().requires_grad_(True)
        f = forward(name, v)
        outs = (f.zbuf, f.bary_coords, f.dists)
        if weights is None:
            weights = [torch.rand(o.shape, generator=gen) for o in outs]
        loss = sum((o * w).sum() for o, w in zip(outs, weights))
        torch.autograd.grad(loss, v)

    # One iteration of the silhouette fit: two views, the tutorial's weights and optimizer.
    Rv, Tv = look_at_view_transform(2.7, torch.tensor([0.0, 30.0]), torch.tensor([0.0, 120.0]))
    views = FoVPerspectiveCameras(R=Rv, T=Tv)
    target = mesh.update_padded(verts[None])
    blend = BlendParams(sigma=1e-4, gamma=1e-4)
    renderers = {
        name: MeshRenderer(
            rasterizer=cls(cameras=views, raster_settings=settings),
            shader=SoftSilhouetteShader(blend_params=blend),
        )
        for name, cls in (("pytorch3d", MeshRasterizer), ("softvk", SoftvkRasterizer))
    }
    with torch.no_grad():
        target_sil = renderers["pytorch3d"](target.extend(2))[..., 3]
    source = ico_sphere(4)
    fits = {}
    for name in rasterizers:
        offsets = torch.zeros_like(source.verts_packed(), requires_grad=True)
        fits[name] = (offsets, torch.optim.SGD([offsets], lr=1.0, momentum=0.9))

    def iteration(name):
        offsets, optimizer = fits[name]
        optimizer.zero_grad()
        m = source.offset_verts(offsets)
        sil = renderers[name](m.extend(2))[..., 3]
        loss = (
            ((sil - target_sil) ** 2).mean()
            + mesh_edge_loss(m)
            + 0.01 * mesh_normal_consistency(m)
            + mesh_laplacian_smoothing(m, method="uniform")
        )
        loss.backward()
        optimizer.step()

    times = {
        name: {"fragment_pass": [], "forward": [], "forward_backward": [], "iteration": []}
        for name in rasterizers
    }
    softvk._native.fragments_time_passes()
    softvk._native.fragments_pass_times()  # drop the warm-up's
    passes = {}
    with torch.no_grad():
        for name in rasterizers:
            forward(name, verts)
    for name in rasterizers:
        forward_backward(name)
        iteration(name)
    for _ in range(args.repeat):
        for name in rasterizers:
            with torch.no_grad():
                t = time.perf_counter()
                fragment_pass(name)
                times[name]["fragment_pass"].append(time.perf_counter() - t)
                t = time.perf_counter()
                forward(name, verts)
                times[name]["forward"].append(time.perf_counter() - t)
            t = time.perf_counter()
            forward_backward(name)
            times[name]["forward_backward"].append(time.perf_counter() - t)
            t = time.perf_counter()
            iteration(name)
            times[name]["iteration"].append(time.perf_counter() - t)
            # softvk's GPU passes of this round (forward, then forward and backward).
            for pass_name, depth, ms in softvk._native.fragments_pass_times():
                if depth == 0:
                    passes.setdefault(pass_name, []).append(ms)
    medians = {
        name: {k: statistics.median(v) for k, v in t.items()} for name, t in times.items()
    }
    result = {
        "mesh": pathlib.Path(path).name,
        "faces": int(mesh.faces_packed().shape[0]),
        "image_size": args.image_size,
        "faces_per_pixel": args.faces_per_pixel,
        "repeat": args.repeat,
        "torch_threads": torch.get_num_threads(),
        "device": softvk.device_name(),
        "load": os.getloadavg()[0],
        "ms": {n: {k: round(1e3 * v, 1) for k, v in m.items()} for n, m in medians.items()},
        # Median GPU ms per call of each softvk pass (a call: the forward alone, with the
        # backward, or an iteration's; setup and binning count run in each).
        "softvk_gpu_ms": {
            k: round(statistics.median(v), 2) for k, v in sorted(passes.items())
        },
        "speedup": {
            k: round(medians["pytorch3d"][k] / medians["softvk"][k], 1)
            for k in ("fragment_pass", "forward", "forward_backward", "iteration")
        },
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
