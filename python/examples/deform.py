"""Deforms a sphere to match silhouettes, in the style of SoftRas's deformation demo, through
softvk's SoftRas-compatible module.

    python python/examples/deform.py --target assets/spot_triangulated.obj --iters 300

The target's silhouettes are generated here: the target mesh, normalised into the unit box as
SoftRas's ``load_obj(normalization=True)`` does, seen from ``--views`` cameras around it (elevation
30°, distance 2.732, viewing angle 15°, as SoftRas's demo). The model is SoftRas's: the template
(``sphere_1352.obj`` × 0.5) moved by a displacement per vertex and a centre, bounded by a
sigmoid/tanh parametrisation, with its Laplacian and flatten regularisers, Adam (0.01, 0.5/0.99),
and the loss 1 − IoU + 0.03 Laplacian + 0.0003 flatten. Prints the mean IoU of the fitted
silhouettes every ``--log-every`` iterations and writes the fitted mesh to ``--out``.
"""

import argparse
import os
import pathlib
import sys
import time

import torch
import torch.nn as nn
import torch.nn.functional as F

import softvk.soft_renderer as sr

ASSETS = pathlib.Path(os.environ.get("SOFTVK_ASSETS") or pathlib.Path(__file__).resolve().parents[2] / "assets")


class Model(nn.Module):
    """SoftRas's deformation model over a template mesh."""

    def __init__(self, template_path):
        super().__init__()
        template = sr.Mesh.from_obj(str(template_path))
        self.register_buffer("vertices", template.vertices * 0.5)
        self.register_buffer("faces", template.faces)
        self.displace = nn.Parameter(torch.zeros_like(template.vertices))
        self.center = nn.Parameter(torch.zeros(1, 1, 3))
        self.laplacian_loss = sr.LaplacianLoss(self.vertices[0], self.faces[0])
        self.flatten_loss = sr.FlattenLoss(self.faces[0])

    def forward(self, batch_size):
        base = torch.log(self.vertices.abs() / (1 - self.vertices.abs()))
        centroid = torch.tanh(self.center)
        vertices = torch.sigmoid(base + self.displace) * torch.sign(self.vertices)
        vertices = F.relu(vertices) * (1 - centroid) - F.relu(-vertices) * (centroid + 1)
        vertices = vertices + centroid
        laplacian = self.laplacian_loss(vertices).mean()
        flatten = self.flatten_loss(vertices).mean()
        mesh = sr.Mesh(vertices.repeat(batch_size, 1, 1), self.faces.repeat(batch_size, 1, 1))
        return mesh, laplacian, flatten


def neg_iou_loss(predict, target):
    intersect = (predict * target).sum((1, 2))
    union = (predict + target - predict * target).sum((1, 2)) + 1e-6
    return 1.0 - (intersect / union).mean()


def mean_iou(predict, target):
    """The mean IoU of binary silhouettes (alpha > 0.5)."""
    p, t = predict > 0.5, target > 0.5
    return ((p & t).sum((1, 2)).float() / (p | t).sum((1, 2)).clamp(min=1).float()).mean().item()


def cameras(views, distance=2.732, elevation=30.0):
    azimuths = torch.arange(views, dtype=torch.float32) * (360.0 / views)
    return torch.full((views,), distance), torch.full((views,), elevation), azimuths


def make_renderer(size, views):
    renderer = sr.SoftRenderer(image_size=size, sigma_val=1e-4, aggr_func_rgb="hard",
                               camera_mode="look_at", viewing_angle=15)
    renderer.transform.set_eyes_from_angles(*cameras(views))
    return renderer


def target_silhouettes(target_path, size, views):
    """The target's silhouettes, rendered sharp (σ 1e-6) after SoftRas's normalisation."""
    mesh = sr.Mesh.from_obj(str(target_path), normalization=True)
    renderer = make_renderer(size, views)
    renderer.set_sigma(1e-6)
    with torch.no_grad():
        images = renderer.render_mesh(sr.Mesh(mesh.vertices.repeat(views, 1, 1), mesh.faces.repeat(views, 1, 1)))
    return (images[:, 3] > 0.5).float()


def fit(target, template, size=64, views=24, iters=300, log_every=50, out=None, log=print):
    """Fits ``template`` to ``target``'s silhouettes; returns the final mean IoU."""
    targets = target_silhouettes(target, size, views)
    model = Model(template)
    renderer = make_renderer(size, views)
    optimizer = torch.optim.Adam(model.parameters(), 0.01, betas=(0.5, 0.99))
    start = time.time()
    for i in range(iters):
        mesh, laplacian, flatten = model(views)
        images = renderer.render_mesh(mesh)
        loss = neg_iou_loss(images[:, 3], targets) + 0.03 * laplacian + 0.0003 * flatten
        if i == 0:
            log(f"iter 0: mean IoU {mean_iou(images[:, 3].detach(), targets):.4f} (the template)")
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if (i + 1) % log_every == 0 or i + 1 == iters:
            iou = mean_iou(images[:, 3].detach(), targets)
            log(f"iter {i + 1}: loss {loss.item():.4f}, mean IoU {iou:.4f}, {time.time() - start:.1f} s")
    with torch.no_grad():
        mesh = model(views)[0]
        iou = mean_iou(renderer.render_mesh(mesh)[:, 3], targets)
    if out is not None:
        model(1)[0].save_obj(str(out), save_texture=False)
    return iou


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", default=ASSETS / "spot_triangulated.obj", type=pathlib.Path)
    parser.add_argument("--template", default=ASSETS / "sphere_1352.obj", type=pathlib.Path)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--iters", type=int, default=300)
    parser.add_argument("--log-every", type=int, default=50)
    parser.add_argument("--out", type=pathlib.Path, default=pathlib.Path("deformed.obj"))
    args = parser.parse_args(argv)
    iou = fit(args.target, args.template, args.size, args.views, args.iters, args.log_every, args.out)
    print(f"final mean IoU {iou:.4f}; mesh written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
