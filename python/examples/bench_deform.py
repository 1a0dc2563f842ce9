"""Times one iteration of SoftRas's deformation demo (120 views × 64², the 1 352-vertex,
2 700-face sphere; σ 1e-4, hard RGB, neg-IoU + Laplacian + flatten, Adam) from PyTorch, three
ways, and where the time goes:

- ``composed``: SoftRas's steps in Python (lighting, look_at, face set-up) and
  ``srf.soft_rasterize`` on the ``[120, 2700, 3, 3]`` screen-space faces;
- ``SoftRenderer``: ``sr.SoftRenderer.render_mesh``, which takes the engine's fast path;
- ``render_mesh``: ``softvk.torch.render_mesh`` called directly on the vertices;
- ``silhouettes``: ``softvk.torch.render(renderer, mesh, 'silhouettes')``, which renders alpha alone (what
  the demo's loss reads; ``softvk fit-mesh`` renders so too).

    python python/examples/bench_deform.py --iters 10

Prints the median wall time per iteration and its parts: the engine's calls (forward and
backward, including the copies into and out of it), and the rest (Python, torch's autograd, the
loss, the regularizers, Adam). Compare with ``softvk bench --scene fit-120``, the same iteration
in the engine alone.
"""

import argparse
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


def icosphere(subdivisions):
    """``softvk::mesh::Mesh::icosphere``: the icosahedron, each midpoint (one per edge, in order
    of first use) pushed back onto the unit sphere, in float64."""
    t = (1.0 + 5.0 ** 0.5) / 2.0
    positions = [torch.tensor(p, dtype=torch.float64) for p in (
        (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
        (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1))]
    positions = [p / p.norm() for p in positions]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        midpoints = {}

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in midpoints:
                m = positions[a] + positions[b]
                positions.append(m / m.norm())
                midpoints[key] = len(positions) - 1
            return midpoints[key]

        children = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            children += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = children
    return torch.stack(positions), torch.tensor(faces, dtype=torch.int32)


def demo_silhouettes(size, distances, elevations, azimuths):
    """The silhouettes ``softvk bench --scene fit-120`` fits (``fit::mesh_fit::demo_target``:
    an icosphere pushed out into three lobes and a dent), rendered sharp (σ 1e-6), so the
    iterations timed here do the work of the native loop's."""
    vertices, faces = icosphere(3)
    x, y, z = vertices.unbind(1)
    r = 0.42 * (1 + 0.28 * torch.cos(3 * torch.atan2(z, x)) * (1 - y * y) + 0.15 * y)
    vertices = torch.stack((x * r, y * r * 0.9, z * r), 1).float()
    views = len(azimuths)
    renderer = sr.SoftRenderer(image_size=size, sigma_val=1e-6, camera_mode="look_at",
                               viewing_angle=15)
    renderer.transform.set_eyes_from_angles(distances, elevations, azimuths)
    with torch.no_grad():
        mesh = sr.Mesh(vertices[None].repeat(views, 1, 1), faces[None].repeat(views, 1, 1))
        return (renderer.render_mesh(mesh)[:, 3] > 0.5).float()


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
    targets = demo_silhouettes(args.size, distances, elevations, azimuths)

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
        alpha = st.render(renderer, mesh, "silhouettes")
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
