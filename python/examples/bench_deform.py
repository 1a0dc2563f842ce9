"""Times one iteration of SoftRas's deformation demo (120 views × 64², the 1 352-vertex,
2 700-face sphere; σ 1e-4, hard RGB, neg-IoU + Laplacian + flatten, Adam) from PyTorch, three
ways, and where the time goes:

- ``composed``: SoftRas's steps in Python (lighting, look_at, face set-up) and
  ``srf.soft_rasterize`` on the ``[120, 2700, 3, 3]`` screen-space faces;
- ``SoftRenderer``: ``sr.SoftRenderer.render_mesh``, which takes the engine's fast path;
- ``render_mesh``: ``softvk.torch.render_mesh`` called directly on the vertices;
- ``silhouettes``: ``render_mesh(mesh, mode='silhouettes')``, which renders alpha alone (what
  the demo's loss reads; ``softvk fit-mesh`` renders so too).

    python python/examples/bench_deform.py --iters 10

Prints the median wall time per iteration and its parts: the engine's calls (forward and
backward, including the copies into and out of it), and the rest (Python, torch's autograd, the
loss, the regularizers, Adam). Compare with ``softvk bench --scene fit-120``, the same iteration
in the engine alone.
"""

import argparse
import os
import pathlib
import statistics
import sys
import time

import torch

import softvk
import softvk._native as native
import softvk.soft_renderer as sr
import softvk.soft_renderer.functional as srf
import softvk.torch as st

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from deform import ASSETS, Model, cameras, neg_iou_loss  # noqa: E402


class EngineClock:
    """Wall time inside the engine's calls (``_native.rasterize``, ``render_mesh`` and their
    backward), measured by wrapping them."""

    def __init__(self):
        self.forward = 0.0
        self.backward = 0.0
        for name in ("rasterize", "render_mesh"):
            setattr(native, name, self._timed(getattr(native, name), "forward"))

    def _timed(self, function, part):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            out = function(*args, **kwargs)
            setattr(self, part, getattr(self, part) + time.perf_counter() - start)
            if part == "forward":
                return out[0], _TimedRaster(out[1], self)
            return out

        return timed

    def reset(self):
        self.forward = self.backward = 0.0


class _TimedRaster:
    def __init__(self, raster, clock):
        self.raster, self.clock = raster, clock

    def backward(self, *args):
        start = time.perf_counter()
        out = self.raster.backward(*args)
        self.clock.backward += time.perf_counter() - start
        return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iters", type=int, default=10)
    parser.add_argument("--views", type=int, default=120)
    parser.add_argument("--size", type=int, default=64)
    args = parser.parse_args(argv)

    clock = EngineClock()
    template = ASSETS / "sphere_1352.obj"
    distances, elevations, azimuths = cameras(args.views)
    eyes = srf.get_points_from_angles(distances, elevations, azimuths)
    targets = (torch.rand(args.views, args.size, args.size, generator=torch.Generator().manual_seed(0)) > 0.5).float()

    renderer = sr.SoftRenderer(image_size=args.size, sigma_val=1e-4, aggr_func_rgb="hard",
                               camera_mode="look_at", viewing_angle=15)
    renderer.transform.set_eyes(eyes)

    def composed(mesh):
        copy = sr.Mesh(mesh.vertices, mesh.faces, mesh.textures)
        return renderer.rasterizer(renderer.transform(renderer.lighting(copy)))

    def direct(mesh):
        return st.render_mesh(mesh.vertices, mesh.faces[0], mesh.textures, eyes=eyes,
                              image_size=args.size, sigma_val=1e-4, aggr_func_rgb="hard",
                              viewing_angle=15)

    def silhouettes(mesh):
        alpha = renderer.render_mesh(mesh, mode="silhouettes")
        return alpha[:, None].expand(-1, 4, -1, -1)

    ways = {"composed": composed, "SoftRenderer": renderer.render_mesh, "render_mesh": direct,
            "silhouettes": silhouettes}
    print(f"device: {softvk.device_name()}; {args.views} views x {args.size}^2, "
          f"median of {args.iters} iterations after one warm-up")
    for name, render in ways.items():
        model = Model(template)
        optimizer = torch.optim.Adam(model.parameters(), 0.01, betas=(0.5, 0.99))
        rows = []
        for i in range(args.iters + 1):
            clock.reset()
            start = time.perf_counter()
            mesh, laplacian, flatten = model(args.views)
            images = render(mesh)
            loss = neg_iou_loss(images[:, 3], targets) + 0.03 * laplacian + 0.0003 * flatten
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            total = time.perf_counter() - start
            if i:
                rows.append((total, clock.forward, clock.backward))
        total, forward, backward = (statistics.median(r[k] for r in rows) for k in range(3))
        print(f"{name:>12}: {1e3 * total:7.1f} ms/iteration = engine forward {1e3 * forward:6.1f} "
              f"+ engine backward {1e3 * backward:6.1f} + rest {1e3 * (total - forward - backward):6.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
