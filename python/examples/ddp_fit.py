"""Data-parallel fitting with torchrun: each rank renders its share of the views on its own
softvk context, DistributedDataParallel (gloo) averages the gradients, and every rank steps the
same parameters.

    torchrun --nproc_per_node 2 python/examples/ddp_fit.py --iters 50

A sphere is deformed (SoftRas's sigmoid/tanh parametrisation, as its deformation demo) to match
the silhouettes of an ellipsoid from 24 views around it; rank r renders views r, r + W, ...
Each process opens its own Vulkan device on its first render (softvk never shares one across
processes); ``--device-per-rank`` picks device LOCAL_RANK (``SOFTVK_DEVICE``) for a node with
one GPU a rank. ``--out DIR`` writes each rank's final parameters as ``rank<r>.pt``.
"""

import argparse
import math
import os
import pathlib
import sys

import torch
import torch.distributed as dist


def icosphere(subdivisions=2):
    """An icosphere of radius 1 (vertices ``[V, 3]``, faces ``[F, 3]``, outward winding)."""
    t = (1 + 5**0.5) / 2
    vertices = [
        (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t),
        (0, -1, -t), (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1),
    ]
    faces = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
        (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
        (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]
    vertices = [tuple(c / math.sqrt(sum(x * x for x in v)) for c in v) for v in vertices]
    for _ in range(subdivisions):
        midpoint, refined = {}, []

        def middle(a, b):
            key = (min(a, b), max(a, b))
            if key not in midpoint:
                m = [(p + q) / 2 for p, q in zip(vertices[a], vertices[b])]
                n = math.sqrt(sum(x * x for x in m))
                vertices.append(tuple(x / n for x in m))
                midpoint[key] = len(vertices) - 1
            return midpoint[key]

        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            refined += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = refined
    # SoftRas's faces are seen from the side cross(v2 - v1, v0 - v1) points to: flip the order.
    return torch.tensor(vertices), torch.tensor(faces)[:, [0, 2, 1]]


def eyes(views, distance=2.732, elevation=30.0):
    """SoftRas's get_points_from_angles for ``views`` azimuths around the object."""
    az = torch.arange(views, dtype=torch.float64) * (360.0 / views)
    el = torch.full_like(az, elevation)
    el, az = torch.deg2rad(el), torch.deg2rad(az)
    return torch.stack(
        [distance * el.cos() * az.sin(), distance * el.sin(), -distance * el.cos() * az.cos()], 1
    )


class Deform(torch.nn.Module):
    """SoftRas's deformation demo model: template vertices moved by a per-vertex displacement
    and a centre, kept inside the unit box by its sigmoid/tanh parametrisation."""

    def __init__(self, template):
        super().__init__()
        self.register_buffer("base", torch.logit((template.abs() * 0.5).clamp(1e-4, 1 - 1e-4)))
        self.register_buffer("sign", torch.sign(template))
        self.displace = torch.nn.Parameter(torch.zeros_like(template))
        self.center = torch.nn.Parameter(torch.zeros(1, 3))

    def forward(self):
        base = torch.sigmoid(self.base + self.displace) * self.sign
        return torch.relu(base) * (1 - self.center) - torch.relu(-base) * (self.center + 1) + self.center


def neg_iou(predict, target):
    intersect = (predict * target).sum((1, 2))
    union = (predict + target - predict * target).sum((1, 2)) + 1e-6
    return 1.0 - (intersect / union).mean()


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=50)
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--size", type=int, default=32)
    parser.add_argument("--device-per-rank", action="store_true")
    parser.add_argument("--out", type=pathlib.Path)
    args = parser.parse_args(argv)

    if args.device_per_rank:
        os.environ["SOFTVK_DEVICE"] = os.environ.get("LOCAL_RANK", "0")
    dist.init_process_group("gloo")
    rank, world = dist.get_rank(), dist.get_world_size()
    import softvk.torch as st  # the first render opens this process's own device

    template, faces = icosphere(2)
    raster = dict(image_size=args.size, sigma_val=1e-4, viewing_angle=15)
    mine = eyes(args.views)[rank::world]
    target_vertices = (template * torch.tensor([0.35, 0.5, 0.3]))[None].expand(len(mine), -1, -1)
    with torch.no_grad():
        targets = st.render_mesh(target_vertices, faces, eyes=mine, **raster)[:, 3]

    torch.manual_seed(0)
    model = torch.nn.parallel.DistributedDataParallel(Deform(template * 0.5))
    optimizer = torch.optim.Adam(model.parameters(), lr=0.01, betas=(0.5, 0.99))
    for it in range(args.iters):
        vertices = model()[None].expand(len(mine), -1, -1)
        silhouettes = st.render_mesh(vertices, faces, eyes=mine, **raster)[:, 3]
        loss = neg_iou(silhouettes, targets)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        if rank == 0 and (it % 10 == 0 or it == args.iters - 1):
            print(f"iter {it}: rank 0 loss {loss.item():.4f}", flush=True)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        torch.save(
            {k: v.detach().clone() for k, v in model.module.state_dict().items()},
            args.out / f"rank{rank}.pt",
        )
        torch.save(torch.tensor(loss.item()), args.out / f"loss{rank}.pt")
    dist.destroy_process_group()
    return 0


if __name__ == "__main__":
    sys.exit(main())
