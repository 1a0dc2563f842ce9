"""PyTorch3D's tutorial "Fit a mesh via rendering", as a script whose rasterizer is selectable.

    python fit_mesh.py --rasterizer pytorch3d --mode silhouette
    python fit_mesh.py --rasterizer softvk --mode textured --image-size 128 --views 10 \
        --iterations 200 --out /tmp/fit

The tutorial (docs/tutorials/fit_textured_mesh.ipynb): a textured target mesh, centred and scaled
so that its largest absolute coordinate is 1, is rendered from ``num_views`` = 20 cameras at
distance 2.7 (elevations linspace(0, 360), azimuths linspace(-180, 180)), in RGB (SoftPhongShader,
one face per pixel, no blur, a point light at (0, 0, -3)) and as soft silhouettes
(SoftSilhouetteShader, sigma 1e-4, blur_radius = log(1/1e-4 - 1) * sigma, 50 faces per pixel).
A level-4 ico-sphere is deformed by per-vertex offsets, with SGD (lr 1.0, momentum 0.9) for
2000 iterations, each on two random views, to minimise

- ``--mode silhouette``: silhouette MSE + edge loss + 0.01 normal consistency + laplacian
  (uniform), the source rendered with SoftSilhouetteShader;
- ``--mode textured``: the same plus the RGB MSE, the source carrying learnable per-vertex colours
  (TexturesVertex, initially 0.5 grey), rendered with SoftPhongShader (50 faces per pixel,
  ``perspective_correct=False``) against the target rendered with its own texture.

What changed:
- ``--rasterizer {softvk,pytorch3d}`` chooses the class of every ``MeshRasterizer`` (the targets'
  and the optimised one): ``softvk.pytorch3d.MeshRasterizer`` (imported only when asked for) or
  PyTorch3D's own. Meshes, cameras, shaders and losses are PyTorch3D's in both cases.
- The target is spot, the cow in ``assets/spot_triangulated.obj`` (with its .mtl and texture),
  instead of the tutorial's cow, which would be downloaded.
- Everything runs on CPU tensors, seeded (``--seed`` seeds torch and the views' random order);
  ``--image-size``, ``--views`` and ``--iterations`` make it small; no plots.
- At the end one JSON line: settings, the final iteration's losses, the mean over the views of the
  IoU of the fitted mesh's silhouettes with the target's (both thresholded at 0.5), and timings
  (total, per iteration, and inside the optimised rasterizer's forward). ``--out DIR`` writes
  ``fit_mesh_<mode>.png`` (rows: fitted and target silhouettes, and in textured mode fitted and
  target RGB; one column a view) and the fitted mesh, in the target's original frame, as
  ``fit_mesh_<mode>.obj``.
"""

import argparse
import json
import math
import pathlib
import sys
import time

import numpy as np
import torch
from pytorch3d.io import save_obj
from pytorch3d.loss import mesh_edge_loss, mesh_laplacian_smoothing, mesh_normal_consistency
from pytorch3d.renderer import (
    FoVPerspectiveCameras,
    MeshRenderer,
    PointLights,
    RasterizationSettings,
    SoftPhongShader,
    SoftSilhouetteShader,
    TexturesVertex,
    look_at_view_transform,
)
from pytorch3d.utils import ico_sphere
from tutorial_common import ForwardTimer, load_spot, rasterizer_class, save_png

# The tutorial's loss weights.
WEIGHTS = {"rgb": 1.0, "silhouette": 1.0, "edge": 1.0, "normal": 0.01, "laplacian": 1.0}


def shape_losses(mesh):
    """The tutorial's regularisers of the shape."""
    return {
        "edge": mesh_edge_loss(mesh),
        "normal": mesh_normal_consistency(mesh),
        "laplacian": mesh_laplacian_smoothing(mesh, method="uniform"),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rasterizer", choices=["softvk", "pytorch3d"], default="softvk")
    parser.add_argument("--mode", choices=["silhouette", "textured"], default="silhouette")
    parser.add_argument("--image-size", type=int, default=128)
    parser.add_argument("--iterations", type=int, default=2000)
    parser.add_argument("--views", type=int, default=20)
    parser.add_argument("--views-per-iteration", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=None,
                        help="directory for fit_mesh_<mode>.png and .obj")
    args = parser.parse_args()

    started = time.perf_counter()
    torch.manual_seed(args.seed)
    rng = np.random.RandomState(args.seed)
    device = torch.device("cpu")
    MeshRasterizer = rasterizer_class(args.rasterizer)
    target, center, scale = load_spot(device)
    num_views = args.views

    # The cameras around the target, and the light in front of it.
    elev = torch.linspace(0, 360, num_views)
    azim = torch.linspace(-180, 180, num_views)
    R, T = look_at_view_transform(dist=2.7, elev=elev, azim=azim)
    cameras = FoVPerspectiveCameras(device=device, R=R, T=T)
    view_cameras = [FoVPerspectiveCameras(device=device, R=R[None, i], T=T[None, i])
                    for i in range(num_views)]
    camera = view_cameras[min(1, num_views - 1)]  # the renderers' default camera
    lights = PointLights(device=device, location=[[0.0, 0.0, -3.0]])

    # The target's RGB images (one face per pixel, no blur) and soft silhouettes.
    rgb_renderer = MeshRenderer(
        rasterizer=MeshRasterizer(cameras=camera, raster_settings=RasterizationSettings(
            image_size=args.image_size, blur_radius=0.0, faces_per_pixel=1)),
        shader=SoftPhongShader(device=device, cameras=camera, lights=lights),
    )
    sigma = 1e-4
    blur_radius = math.log(1.0 / 1e-4 - 1.0) * sigma
    silhouette_renderer = MeshRenderer(
        rasterizer=MeshRasterizer(cameras=camera, raster_settings=RasterizationSettings(
            image_size=args.image_size, blur_radius=blur_radius, faces_per_pixel=50)),
        shader=SoftSilhouetteShader(),
    )
    with torch.no_grad():
        targets = target.extend(num_views)
        target_rgb = rgb_renderer(targets, cameras=cameras, lights=lights)[..., :3]
        target_silhouette = silhouette_renderer(targets, cameras=cameras, lights=lights)[..., 3]

    # The renderer optimised through, with its rasterizer's forward timed.
    timer = ForwardTimer()
    if args.mode == "silhouette":
        renderer = MeshRenderer(
            rasterizer=timer.wrap(MeshRasterizer(cameras=camera, raster_settings=RasterizationSettings(
                image_size=args.image_size, blur_radius=blur_radius, faces_per_pixel=50))),
            shader=SoftSilhouetteShader(),
        )
    else:
        renderer = MeshRenderer(
            rasterizer=timer.wrap(MeshRasterizer(cameras=camera, raster_settings=RasterizationSettings(
                image_size=args.image_size, blur_radius=blur_radius, faces_per_pixel=50,
                perspective_correct=False))),
            shader=SoftPhongShader(device=device, cameras=camera, lights=lights),
        )

    # The source: a level-4 ico-sphere moved by per-vertex offsets (and, textured, coloured).
    src_mesh = ico_sphere(4, device)
    deform_verts = torch.zeros(src_mesh.verts_packed().shape, device=device, requires_grad=True)
    params = [deform_verts]
    if args.mode == "textured":
        verts_rgb = torch.full([1, deform_verts.shape[0], 3], 0.5, device=device, requires_grad=True)
        params.append(verts_rgb)
    optimizer = torch.optim.SGD(params, lr=1.0, momentum=0.9)

    def deformed():
        mesh = src_mesh.offset_verts(deform_verts)
        if args.mode == "textured":
            mesh.textures = TexturesVertex(verts_features=verts_rgb)
        return mesh

    names = (["rgb"] if args.mode == "textured" else []) + ["silhouette", "edge", "normal", "laplacian"]
    loop_start = time.perf_counter()
    for i in range(args.iterations):
        optimizer.zero_grad()
        mesh = deformed()
        loss = {k: torch.tensor(0.0, device=device) for k in names}
        loss.update(shape_losses(mesh))
        for j in rng.permutation(num_views).tolist()[:args.views_per_iteration]:
            images = renderer(mesh, cameras=view_cameras[j], lights=lights)
            loss["silhouette"] = loss["silhouette"] + (
                (images[..., 3] - target_silhouette[j]) ** 2).mean() / args.views_per_iteration
            if args.mode == "textured":
                loss["rgb"] = loss["rgb"] + (
                    (images[..., :3] - target_rgb[j]) ** 2).mean() / args.views_per_iteration
        total = sum(loss[k] * WEIGHTS[k] for k in names)
        total.backward()
        optimizer.step()
        if i % 50 == 0 or i == args.iterations - 1:
            print(f"iter {i:5d}  loss {total.item():.6f}", file=sys.stderr)
    loop_seconds = time.perf_counter() - loop_start
    raster_seconds, raster_calls = timer.seconds, timer.calls

    # The fitted mesh (after the last step) against the target, in every view.
    with torch.no_grad():
        fitted = deformed()
        silhouettes = silhouette_renderer(fitted.extend(num_views), cameras=cameras,
                                          lights=lights)[..., 3]
        pred, real = silhouettes > 0.5, target_silhouette > 0.5
        union = (pred | real).sum((1, 2)).float()
        ious = torch.where(union > 0, (pred & real).sum((1, 2)).float() / union.clamp(min=1),
                           torch.ones_like(union))

    result = {
        "script": "fit_mesh",
        "rasterizer": args.rasterizer,
        "mode": args.mode,
        "image_size": args.image_size,
        "iterations": args.iterations,
        "views": num_views,
        "views_per_iteration": args.views_per_iteration,
        "seed": args.seed,
        "final_loss": total.item() if args.iterations else None,
        "final_losses": {k: loss[k].item() for k in names} if args.iterations else None,
        "iou": ious.mean().item(),
        "total_s": round(time.perf_counter() - started, 3),
        "s_per_iter": round(loop_seconds / max(args.iterations, 1), 4),
        "raster_forward_s": round(raster_seconds, 3),
        "raster_forward_calls": raster_calls,
    }

    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        rows = [list(silhouettes.numpy()), list(target_silhouette.numpy())]
        if args.mode == "textured":
            with torch.no_grad():
                fitted_rgb = renderer(fitted.extend(num_views), cameras=cameras, lights=lights)
            rows += [list(fitted_rgb[..., :3].numpy()), list(target_rgb.numpy())]
        save_png(args.out / f"fit_mesh_{args.mode}.png", rows)
        verts, faces = fitted.get_mesh_verts_faces(0)
        save_obj(str(args.out / f"fit_mesh_{args.mode}.obj"), verts * scale + center, faces)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
