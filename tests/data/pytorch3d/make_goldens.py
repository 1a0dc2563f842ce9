#!/usr/bin/env python3
"""Golden files of PyTorch3D's CPU `rasterize_meshes` (the naive path, bin_size=0), forward and
backward, one `.npz` per scene in this folder. See README.md.

Run with a Python that has torch and a CPU build of PyTorch3D:

    $P3D/bin/python tests/data/pytorch3d/make_goldens.py [--out DIR]

PyTorch3D's CPU kernels take float32 only (`accessor<float, N>` in
csrc/rasterize_meshes/rasterize_meshes_cpu.cpp; a float64 Meshes raises "expected scalar type
Float but found Double"), so the geometry and upstream gradients are drawn in float64 and
rounded to float32 once; the float32 values PyTorch3D saw are what the files hold.

Every scene is checked before it is written, against an independent float64 re-implementation
here (`reference_forward`, and torch float64 autograd for the backward): the same pix_to_face,
values within 3e-6, each gradient component within a quarter of 1e-4 of itself plus 1e-5
of the scene's largest.
A scene must also keep clear of every decision a float32 / float64 difference could flip (a
barycentric near 0, a distance near the blur radius, two depths within 1e-6 that are not exactly
equal, two edges nearly equally near, ...); a random scene that does not is redrawn with the next
seed (the seed used is stored in the file).
"""

import argparse
import io
import math
import os
import sys
import zipfile

import numpy as np
import torch

import pytorch3d
from pytorch3d.renderer.mesh.rasterize_meshes import rasterize_meshes
from pytorch3d.structures import Meshes

K_EPS = 1e-8  # kEpsilon, csrc/utils/geometry_utils.h
HERE = os.path.dirname(os.path.abspath(__file__))

# Margins kept from every float-sensitive decision (see module docstring).
BARY_MARGIN = 1e-6
BLUR_MARGIN_REL = 1e-4
Z_MARGIN = 1e-6
EDGE_MARGIN_REL = 1e-4
AREA_MARGIN = 1e-6
# Comparison of PyTorch3D (float32) with the float64 reference.
VALUE_TOL = 3e-6
GRAD_REL, GRAD_FLOOR, GRAD_HEADROOM = 1e-4, 1e-5, 0.25


class Reject(Exception):
    """The scene comes too close to a float-sensitive decision; redraw it."""


# ----------------------------------------------------------------------------------------------
# Scenes
# ----------------------------------------------------------------------------------------------


def random_mesh(rng, n_faces, x_ext=1.2, y_ext=1.2, zlim=(1.0, 5.0), share=0.3, winding="mixed",
                sizes=(0.15, 0.3, 0.5, 0.8), centre_ext=None):
    """Triangles of mixed sizes around random centres, depths per vertex in zlim; about `share`
    of them reuse an edge (two vertices) of an earlier face, so vertices collect gradients from
    several faces. Returns float64 verts [V,3], int64 faces [F,3] (mesh-local indices)."""
    verts, faces = [], []
    for i in range(n_faces):
        size = rng.choice(sizes) * rng.uniform(0.8, 1.2)
        if faces and rng.uniform() < share:
            a, b = faces[rng.integers(len(faces))][rng.permutation(3)[:2]]
            mid = (verts[a][:2] + verts[b][:2]) / 2
            edge = verts[b][:2] - verts[a][:2]
            normal = np.array([-edge[1], edge[0]]) / (np.linalg.norm(edge) + 1e-12)
            xy = mid + normal * rng.choice([-1, 1]) * rng.uniform(0.4, 1.0) * size
            xy = np.clip(xy, [-x_ext, -y_ext], [x_ext, y_ext])
            verts.append(np.array([xy[0], xy[1], rng.uniform(*zlim)]))
            tri = [a, b, len(verts) - 1]
        else:
            ce = centre_ext or (x_ext - 0.1, y_ext - 0.1)
            c = rng.uniform([-ce[0], -ce[1]], [ce[0], ce[1]])
            t0 = rng.uniform(0, 2 * math.pi)
            tri = []
            for k in range(3):
                t = t0 + k * 2 * math.pi / 3 + rng.uniform(-0.5, 0.5)
                r = size * rng.uniform(0.5, 1.0)
                xy = np.clip(c + r * np.array([math.cos(t), math.sin(t)]), [-x_ext, -y_ext], [x_ext, y_ext])
                verts.append(np.array([xy[0], xy[1], rng.uniform(*zlim)]))
                tri.append(len(verts) - 1)
        tri = np.array(tri)
        if winding == "mixed" and rng.uniform() < 0.5:
            tri = tri[[0, 2, 1]]
        faces.append(tri)
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)


def scene_skipped(rng):
    """Faces PyTorch3D drops or skips at some pixels, amid ordinary ones: a zero-area face
    (collinear vertices), a face with a vertex at z <= 0 (dropped whole: z_min < kEpsilon), and a
    face whose blur-extrapolated depth goes negative past a near vertex (skipped there)."""
    v, f = random_mesh(rng, 6)
    extra_v = np.array(
        [
            [-0.5, -0.5, 2.0], [0.0, 0.0, 2.5], [0.5, 0.5, 3.0],  # collinear: zero area
            [-0.6, 0.2, 2.0], [0.3, 0.7, -0.5], [0.2, -0.4, 3.0],  # a vertex behind
            [0.76, -0.76, 0.02], [-0.1, -0.55, 3.0], [0.45, 0.3, 3.0],  # near vertex, z 0.02
        ]
    )
    n = len(v)
    extra_f = np.arange(9).reshape(3, 3) + n
    return np.concatenate([v, extra_v]), np.concatenate([f, extra_f])


def scene_ties():
    """Equal depths, by construction exact in float32 and in float64: four coplanar faces at
    z = 2 fanned around (0, 0) (equal area, equal winding, vertices on a 1/8 lattice, so pixels
    on their shared diagonals get bit-equal depths), exact duplicates of two of them (one on new
    vertices at the same coordinates, one on the same vertex indices), a constant-depth
    parallelogram in front (z = 1.5, two equal halves sharing a 45-degree diagonal that pixels lie
    on; not a rectangle, whose right angles would put pixels exactly equidistant from two edges)
    over part of them, and a sloped face cutting through z = 2."""
    c = [0.0, 0.0, 2.0]
    v = [
        c, [0.5, -0.5, 2.0], [0.5, 0.5, 2.0], [-0.5, 0.5, 2.0], [-0.5, -0.5, 2.0],  # 0-4 fan
        c, [0.5, -0.5, 2.0], [0.5, 0.5, 2.0],  # 5-7 copy of fan face 0 on new vertices
        [0.25, 0.125, 1.5], [0.75, 0.125, 1.5], [0.875, 0.75, 1.5], [0.375, 0.75, 1.5],  # 8-11
        [-0.71, -0.58, 1.03], [0.66, -0.31, 2.97], [-0.42, 0.79, 2.41],  # 12-14 sloped
    ]
    f = [
        [0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1],  # fan, all the same winding
        [5, 6, 7],  # duplicate of face 0 (new vertices)
        [0, 3, 4],  # duplicate of face 2 (same vertices)
        [8, 9, 10], [8, 10, 11],  # parallelogram in front (equal halves)
        [12, 13, 14],  # sloped face
    ]
    return np.array(v, dtype=np.float64), np.array(f, dtype=np.int64)


def scene_specs():
    """(name, base seed, builder(rng) -> list of (verts, faces) per mesh, settings)."""
    def one(n, **kw):
        return lambda rng: [random_mesh(rng, n, **kw)]

    def settings(H, W, blur, K, persp=False, clip=False, cull=False):
        return dict(image_size=(H, W), blur_radius=blur, faces_per_pixel=K,
                    perspective_correct=persp, clip_barycentric_coords=clip, cull_backfaces=cull)

    return [
        ("square_basic", 1000, one(12), settings(16, 16, 0.0, 1)),
        ("square_blur_k4", 2000, one(12), settings(16, 16, 0.01, 4)),
        ("non_square", 3000, one(12, x_ext=1.2 * 20 / 12), settings(12, 20, 0.005, 3)),
        ("non_square_tall", 4000, one(12, y_ext=1.2 * 20 / 12), settings(20, 12, 0.005, 3)),
        ("batched", 5000, lambda rng: [random_mesh(rng, n) for n in (5, 12, 8)],
         settings(16, 16, 0.002, 3)),
        ("culled", 6000, one(14), settings(16, 16, 0.003, 2, cull=True)),
        ("perspective_clipped", 7000, one(12), settings(16, 16, 0.01, 4, persp=True, clip=True)),
        ("perspective_unclipped", 7500, one(12), settings(16, 16, 0.01, 4, persp=True)),
        ("clipped_affine", 7700, one(12), settings(16, 16, 0.01, 4, clip=True)),
        ("k_larger", 8000, one(7, sizes=(0.5, 0.8, 1.0), centre_ext=(0.5, 0.5)),
         settings(16, 16, 0.005, 8)),
        ("ties", 9000, lambda rng: [scene_ties()], settings(16, 16, 0.001, 4)),
        ("skipped_faces", 9500, lambda rng: [scene_skipped(rng)], settings(16, 16, 0.01, 3)),
    ]


# ----------------------------------------------------------------------------------------------
# Float64 reference (independent of PyTorch3D's code, following its semantics)
# ----------------------------------------------------------------------------------------------


def ndc_range(s1, s2):
    return 2.0 * s1 / s2 if s1 > s2 else 2.0


def pixel_ndc(H, W):
    """NDC x of output column c, y of output row r: PixToNonSquareNdc(W-1-c, W, H) and
    PixToNonSquareNdc(H-1-r, H, W) (csrc/rasterize_points/rasterization_utils.h)."""
    def ndc(i, s1, s2):
        r = ndc_range(s1, s2)
        return -r / 2 + (r * i + r / 2) / s1
    xs = np.array([ndc(W - 1 - c, W, H) for c in range(W)])
    ys = np.array([ndc(H - 1 - r, H, W) for r in range(H)])
    return xs, ys


def edge_fn(p, a, b):
    """EdgeFunctionForward(p, a, b); arrays [..., 2]."""
    return (p[..., 0] - a[..., 0]) * (b[..., 1] - a[..., 1]) - (p[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0])


def seg_dist2(p, a, b):
    """Squared distance of p to segment ab and the nearest point."""
    ab = b - a
    l2 = (ab * ab).sum(-1)
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum(l2, 1e-300), 0.0, 1.0)
    q = a + t[..., None] * ab
    return ((p - q) ** 2).sum(-1), q


def reference_forward(fv, first, count, st, tie_ok):
    """Float64 forward. fv: [F,3,3]. Returns (pix_to_face, zbuf, bary, dists) and raises Reject
    when a decision is within the margins."""
    H, W = st["image_size"]
    K, blur = st["faces_per_pixel"], st["blur_radius"]
    persp, clip, cull = st["perspective_correct"], st["clip_barycentric_coords"], st["cull_backfaces"]
    N = len(first)
    xs, ys = pixel_ndc(H, W)
    P = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None]), -1)  # [H,W,2]
    out_f = np.full((N, H, W, K), -1, np.int64)
    out_z = np.full((N, H, W, K), -1.0)
    out_b = np.full((N, H, W, K, 3), -1.0)
    out_d = np.full((N, H, W, K), -1.0)
    for n in range(N):
        cands = [[[] for _ in range(W)] for _ in range(H)]
        for f in range(first[n], first[n] + count[n]):
            v = fv[f]
            v0, v1, v2 = v[0, :2], v[1, :2], v[2, :2]
            area = edge_fn(v0, v1, v2)  # face_area: (v0 - v1) x (v2 - v1)
            if abs(abs(area) - K_EPS) < AREA_MARGIN and area != 0:
                raise Reject(f"face {f}: area {area} near kEpsilon")
            if cull and area < 0:
                continue
            if abs(area) <= K_EPS:
                continue
            if v[:, 2].min() < K_EPS:
                continue
            r = math.sqrt(blur)
            lo, hi = v[:, :2].min(0) - r, v[:, :2].max(0) + r
            inbox = (P[..., 0] >= lo[0]) & (P[..., 0] <= hi[0]) & (P[..., 1] >= lo[1]) & (P[..., 1] <= hi[1])
            a = edge_fn(v2, v0, v1) + K_EPS
            b0 = np.stack([edge_fn(P, v1, v2), edge_fn(P, v2, v0), edge_fn(P, v0, v1)], -1) / a
            z = v[:, 2]
            if persp:
                top = b0 * np.array([z[1] * z[2], z[0] * z[2], z[0] * z[1]])
                bary = top / np.maximum(top.sum(-1, keepdims=True), K_EPS)[..., :]
            else:
                bary = b0
            if clip:
                w = np.maximum(bary, 0.0)
                bclip = w / np.maximum(w.sum(-1, keepdims=True), 1e-5)
            else:
                bclip = bary
            pz = bclip[..., 0] * z[0] + bclip[..., 1] * z[1] + bclip[..., 2] * z[2]
            e = np.stack([seg_dist2(P, v0, v1)[0], seg_dist2(P, v0, v2)[0], seg_dist2(P, v1, v2)[0]], -1)
            q = np.stack([seg_dist2(P, v0, v1)[1], seg_dist2(P, v0, v2)[1], seg_dist2(P, v1, v2)[1]], -2)
            dist = e.min(-1)
            inside = (bary > 0).all(-1)
            for yi in range(H):
                for xi in range(W):
                    if not inbox[yi, xi]:
                        continue
                    bb = bary[yi, xi]
                    nz = np.abs(bb[bb != 0])
                    if nz.size and nz.min() < BARY_MARGIN:
                        raise Reject(f"face {f} pixel {yi},{xi}: barycentric {bb}")
                    if abs(pz[yi, xi]) < Z_MARGIN:
                        raise Reject(f"face {f} pixel {yi},{xi}: depth {pz[yi, xi]} near 0")
                    if pz[yi, xi] < 0:
                        continue
                    d = dist[yi, xi]
                    if not inside[yi, xi]:
                        if blur > 0 and abs(d - blur) < BLUR_MARGIN_REL * blur:
                            raise Reject(f"face {f} pixel {yi},{xi}: dist {d} near blur {blur}")
                        if d >= blur:
                            continue
                    # the nearest edge, for the backward: clear of the others unless the same point
                    order = np.argsort(e[yi, xi], kind="stable")
                    d1, d2 = e[yi, xi][order[0]], e[yi, xi][order[1]]
                    if d2 - d1 < EDGE_MARGIN_REL * max(d2, 1e-12):
                        if np.abs(q[yi, xi][order[0]] - q[yi, xi][order[1]]).max() > 1e-12:
                            raise Reject(f"face {f} pixel {yi},{xi}: two edges equally near")
                    sd = -d if inside[yi, xi] else d
                    cands[yi][xi].append((pz[yi, xi], f, sd, bclip[yi, xi]))
        for yi in range(H):
            for xi in range(W):
                c = sorted(cands[yi][xi], key=lambda t: (t[0], t[1]))
                for j in range(min(len(c), K + 1) - 1):
                    gap = c[j + 1][0] - c[j][0]
                    if gap == 0 and not tie_ok:
                        raise Reject(f"pixel {yi},{xi}: exact depth tie")
                    if 0 < gap < Z_MARGIN * max(1.0, abs(c[j][0])):
                        raise Reject(f"pixel {yi},{xi}: depths {c[j][0]} {c[j + 1][0]} nearly tie")
                for k, (zz, f, sd, bc) in enumerate(c[:K]):
                    out_f[n, yi, xi, k], out_z[n, yi, xi, k] = f, zz
                    out_d[n, yi, xi, k], out_b[n, yi, xi, k] = sd, bc
    return out_f, out_z, out_b, out_d


def reference_backward(fv64, faces, V, pix_to_face, st, gz, gb, gd):
    """Float64 gradient to the packed vertices of sum(gz*zbuf + gb*bary + gd*dists), by torch
    autograd through a re-implementation of the forward at the given pix_to_face."""
    H, W = st["image_size"]
    xs, ys = pixel_ndc(H, W)
    n, yi, xi, k = np.nonzero(pix_to_face >= 0)
    f = torch.from_numpy(pix_to_face[n, yi, xi, k])
    verts = torch.zeros(V, 3, dtype=torch.float64)
    verts[torch.from_numpy(faces).reshape(-1)] = torch.from_numpy(fv64).reshape(-1, 3)
    verts.requires_grad_(True)
    v = verts[torch.from_numpy(faces)][f]  # [S,3,3]
    p = torch.from_numpy(np.stack([xs[xi], ys[yi]], -1))
    v0, v1, v2 = v[:, 0, :2], v[:, 1, :2], v[:, 2, :2]

    def E(p, a, b):
        return (p[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]) - (p[:, 1] - a[:, 1]) * (b[:, 0] - a[:, 0])

    area = E(v2, v0, v1) + K_EPS
    b0 = torch.stack([E(p, v1, v2), E(p, v2, v0), E(p, v0, v1)], -1) / area[:, None]
    z = v[:, :, 2]
    if st["perspective_correct"]:
        top = b0 * torch.stack([z[:, 1] * z[:, 2], z[:, 0] * z[:, 2], z[:, 0] * z[:, 1]], -1)
        bary = top / top.sum(-1, keepdim=True).clamp(min=K_EPS)
    else:
        bary = b0
    if st["clip_barycentric_coords"]:
        w = bary.clamp(min=0.0)
        bclip = w / w.sum(-1, keepdim=True).clamp(min=1e-5)
    else:
        bclip = bary
    pz = (bclip * z).sum(-1)

    def seg(p, a, b):
        ab = b - a
        t = (((p - a) * ab).sum(-1) / (ab * ab).sum(-1)).clamp(0.0, 1.0)
        return ((p - a - t[:, None] * ab) ** 2).sum(-1)

    e = torch.stack([seg(p, v0, v1), seg(p, v0, v2), seg(p, v1, v2)], -1)
    dist = e.min(-1).values
    inside = (bary > 0).all(-1)
    sd = torch.where(inside, -dist, dist)
    idx = (n, yi, xi, k)
    loss = (torch.from_numpy(gz[idx]) * pz).sum() + (torch.from_numpy(gb[idx]) * bclip).sum() + (
        torch.from_numpy(gd[idx]) * sd).sum()
    loss.backward()
    return verts.grad.numpy()


# ----------------------------------------------------------------------------------------------
# One scene
# ----------------------------------------------------------------------------------------------


def make_scene(name, seed, build, st):
    rng = np.random.default_rng(seed)
    parts = build(rng)
    verts_list = [torch.from_numpy(v).float() for v, _ in parts]
    faces_list = [torch.from_numpy(fc) for _, fc in parts]
    meshes = Meshes(verts=verts_list, faces=faces_list)
    verts_packed = meshes.verts_packed().detach().clone().requires_grad_(True)
    faces_packed = meshes.faces_packed()
    vfirst = meshes.mesh_to_verts_packed_first_idx()
    nverts = meshes.num_verts_per_mesh()
    # A Meshes on the leaf tensor, so autograd reaches verts_packed itself.
    m2 = Meshes(
        verts=[verts_packed[a:a + c] for a, c in zip(vfirst.tolist(), nverts.tolist())],
        faces=faces_list,
    )
    ffirst, fcount = m2.mesh_to_faces_packed_first_idx(), m2.num_faces_per_mesh()
    assert torch.equal(m2.faces_packed(), faces_packed)

    pix_to_face, zbuf, bary, dists = rasterize_meshes(
        m2, image_size=st["image_size"], blur_radius=st["blur_radius"],
        faces_per_pixel=st["faces_per_pixel"], bin_size=0, max_faces_per_bin=None,
        perspective_correct=st["perspective_correct"],
        clip_barycentric_coords=st["clip_barycentric_coords"],
        cull_backfaces=st["cull_backfaces"], z_clip_value=None, cull_to_frustum=False,
    )
    assert zbuf.dtype == torch.float32
    zb, ba, di = zbuf.detach(), bary.detach(), dists.detach()
    mask = (pix_to_face >= 0)
    grng = np.random.default_rng(seed + 1)
    zero = torch.zeros((), dtype=torch.float32)
    gz = torch.where(mask, torch.from_numpy(grng.standard_normal(zbuf.shape)).float(), zero)
    gb = torch.where(mask[..., None], torch.from_numpy(grng.standard_normal(bary.shape)).float(), zero)
    gd = torch.where(mask, torch.from_numpy(grng.standard_normal(dists.shape)).float(), zero)
    loss = (gz * zbuf).sum() + (gb * bary).sum() + (gd * dists).sum()
    (grad_verts,) = torch.autograd.grad(loss, verts_packed)

    # --- checks against the float64 reference ---
    vp = verts_packed.detach().double().numpy()
    fp = faces_packed.numpy()
    fv = vp[fp]
    tie_ok = name == "ties"
    rf, rz, rb, rd = reference_forward(fv, ffirst.tolist(), fcount.tolist(), st, tie_ok)
    p2f = pix_to_face.numpy()
    if not np.array_equal(rf, p2f):
        raise SystemExit(f"{name}: pix_to_face differs from the float64 reference at "
                         f"{np.argwhere(rf != p2f)[:5].tolist()}")
    errs = {k: float(np.abs(a - b).max()) for k, a, b in
            (("zbuf", rz, zb.numpy()), ("bary", rb, ba.numpy()), ("dists", rd, di.numpy()))}
    if max(errs.values()) > VALUE_TOL:
        raise Reject(f"values off the float64 reference by more than {VALUE_TOL}: {errs}")
    g64 = reference_backward(fv, fp, len(vp), p2f, st, gz.double().numpy(), gb.double().numpy(),
                             gd.double().numpy())
    want = grad_verts.double().numpy()
    scale = np.abs(want).max()
    tol = GRAD_HEADROOM * (GRAD_REL * np.abs(want) + GRAD_FLOOR * scale)
    ratio = float((np.abs(g64 - want) / tol).max() * GRAD_HEADROOM)
    if ratio > GRAD_HEADROOM:
        raise Reject(f"gradient off the float64 one by {ratio:.3f} of the test tolerance")

    out = dict(
        verts_packed=vp.astype(np.float32),
        faces_packed=fp.astype(np.int64),
        mesh_to_face_first_idx=ffirst.numpy().astype(np.int64),
        num_faces_per_mesh=fcount.numpy().astype(np.int64),
        verts_first_idx=vfirst.numpy().astype(np.int64),
        num_verts_per_mesh=nverts.numpy().astype(np.int64),
        image_size=np.array(st["image_size"], np.int64),
        blur_radius=np.array(st["blur_radius"], np.float64),
        faces_per_pixel=np.array(st["faces_per_pixel"], np.int64),
        perspective_correct=np.array(int(st["perspective_correct"]), np.int64),
        clip_barycentric_coords=np.array(int(st["clip_barycentric_coords"]), np.int64),
        cull_backfaces=np.array(int(st["cull_backfaces"]), np.int64),
        pix_to_face=p2f.astype(np.int64),
        zbuf=zb.numpy(),
        bary_coords=ba.numpy(),
        dists=di.numpy(),
        grad_zbuf=gz.numpy(),
        grad_bary=gb.numpy(),
        grad_dists=gd.numpy(),
        grad_verts=grad_verts.numpy(),
        seed=np.array(seed, np.int64),
        torch_version=np.array(torch.__version__),
        pytorch3d_version=np.array(pytorch3d.__version__),
    )
    stats = dict(errs, grad_ratio=ratio, slots=int(mask.sum()),
                 ties=int(((np.diff(zb.numpy(), axis=-1) == 0) & (p2f[..., 1:] >= 0)).sum()))
    return out, stats


def make_near_plane():
    """A floor grid running from behind the camera into the distance, below the eye, so that
    PyTorch3D's near-plane clipping (`clip_faces`, z_clip_value 0.5 as MeshRasterizer sets it for
    znear 1) cuts faces in view, some in two: its C++ rasterizer's inputs after the clip (the cut faces as packed faces, each its own
    three vertices, and `clipped_faces_neighbor_idx`) and its outputs and gradients before
    `convert_clipped_rasterization_to_original_faces`. Not checked against the float64
    reference above (it has no rule for cut faces); the Rust tests check the twin and the
    kernels against it."""
    from pytorch3d.renderer import FoVPerspectiveCameras, MeshRasterizer
    from pytorch3d.renderer.mesh.clip import ClipFrustum, clip_faces
    from pytorch3d.renderer.mesh.rasterize_meshes import _RasterizeFaceVerts

    st = dict(image_size=(24, 32), blur_radius=1e-3, faces_per_pixel=6, perspective_correct=True,
              clip_barycentric_coords=True, cull_backfaces=False)
    # The camera at the origin looking along +z (view space is world space); the floor at
    # y = -0.2, x in [-1.5, 1.5], z in [0.05, 3], an 8 x 8 grid of quads, jittered.
    cams = FoVPerspectiveCameras(R=torch.eye(3)[None], T=torch.zeros(1, 3))
    grng = np.random.default_rng(5)
    xs, zs = np.linspace(-1.5, 1.5, 9), np.linspace(0.05, 3.0, 9)
    verts = np.array([[x + grng.uniform(-0.05, 0.05), -0.2 + grng.uniform(-0.03, 0.03),
                       z + grng.uniform(-0.05, 0.05)] for z in zs for x in xs], np.float32)
    faces = []
    for i in range(8):
        for j in range(8):
            a, b, c, d = 9 * i + j, 9 * i + j + 1, 9 * (i + 1) + j, 9 * (i + 1) + j + 1
            faces += [[a, b, d], [a, d, c]]
    floor = Meshes(verts=[torch.from_numpy(verts)], faces=[torch.tensor(faces)])
    projected = MeshRasterizer(cameras=cams).transform(floor)
    fv0 = projected.verts_packed()[projected.faces_packed()].detach()
    frustum = ClipFrustum(left=-1, right=1, top=-1, bottom=1, perspective_correct=True,
                          z_clip_value=0.5, cull=False)
    clipped = clip_faces(fv0, projected.mesh_to_faces_packed_first_idx(),
                         projected.num_faces_per_mesh(), frustum=frustum)
    neighbors = clipped.clipped_faces_neighbor_idx
    assert neighbors is not None and int((neighbors >= 0).sum()) > 0
    fv = clipped.face_verts.detach().clone().requires_grad_(True)
    ffirst, fcount = clipped.mesh_to_face_first_idx, clipped.num_faces_per_mesh
    pix_to_face, zbuf, bary, dists = _RasterizeFaceVerts.apply(
        fv, ffirst, fcount, neighbors, st["image_size"], st["blur_radius"],
        st["faces_per_pixel"], 0, 10000, st["perspective_correct"],
        st["clip_barycentric_coords"], st["cull_backfaces"])
    mask = pix_to_face >= 0
    grng = np.random.default_rng(7)  # the upstream gradients
    zero = torch.zeros((), dtype=torch.float32)
    gz = torch.where(mask, torch.from_numpy(grng.standard_normal(zbuf.shape)).float(), zero)
    gb = torch.where(mask[..., None], torch.from_numpy(grng.standard_normal(bary.shape)).float(), zero)
    gd = torch.where(mask, torch.from_numpy(grng.standard_normal(dists.shape)).float(), zero)
    loss = (gz * zbuf).sum() + (gb * bary).sum() + (gd * dists).sum()
    (grad_fv,) = torch.autograd.grad(loss, fv)
    # Which pixels hold a face whose other half reached them too (the rule's work).
    p2f = pix_to_face.numpy()
    nb = neighbors.numpy()
    halves = int(sum(1 for f in np.unique(p2f[p2f >= 0]) if nb[f] >= 0))
    n = fv.shape[0]
    out = dict(
        verts_packed=fv.detach().numpy().reshape(-1, 3),
        faces_packed=np.arange(3 * n, dtype=np.int64).reshape(n, 3),
        mesh_to_face_first_idx=ffirst.numpy().astype(np.int64),
        num_faces_per_mesh=fcount.numpy().astype(np.int64),
        clipped_faces_neighbor_idx=nb.astype(np.int64),
        image_size=np.array(st["image_size"], np.int64),
        blur_radius=np.array(st["blur_radius"], np.float64),
        faces_per_pixel=np.array(st["faces_per_pixel"], np.int64),
        perspective_correct=np.array(1, np.int64),
        clip_barycentric_coords=np.array(1, np.int64),
        cull_backfaces=np.array(0, np.int64),
        pix_to_face=p2f.astype(np.int64),
        zbuf=zbuf.detach().numpy(),
        bary_coords=bary.detach().numpy(),
        dists=dists.detach().numpy(),
        grad_zbuf=gz.numpy(),
        grad_bary=gb.numpy(),
        grad_dists=gd.numpy(),
        grad_verts=grad_fv.numpy().reshape(-1, 3),
        torch_version=np.array(torch.__version__),
        pytorch3d_version=np.array(pytorch3d.__version__),
    )
    stats = dict(faces=n, cut_in_two=int((nb >= 0).sum()), halves_drawn=halves,
                 slots=int(mask.sum()))
    return out, stats


def save_npz(path, arrays):
    """As np.savez_compressed, but byte-for-byte reproducible (fixed entry times)."""
    with zipfile.ZipFile(path, "w") as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asanyarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=HERE)
    args = ap.parse_args()
    torch.manual_seed(0)
    for name, base, build, st in scene_specs():
        for attempt in range(200):
            try:
                out, stats = make_scene(name, base + 2 * attempt, build, st)
                break
            except Reject as e:
                if name in ("ties",):
                    raise SystemExit(f"{name}: {e}")
                print(f"  {name} seed {base + 2 * attempt}: redraw ({e})", file=sys.stderr)
        else:
            raise SystemExit(f"{name}: no seed kept clear of the margins")
        path = os.path.join(args.out, name + ".npz")
        save_npz(path, out)
        print(f"{name}: seed {int(out['seed'])}, {stats['slots']} slots, {stats['ties']} tied pairs, "
              f"max |diff| zbuf {stats['zbuf']:.1e} bary {stats['bary']:.1e} dists {stats['dists']:.1e}, "
              f"grad {stats['grad_ratio']:.3f} of tolerance, {os.path.getsize(path)} bytes")
    out, stats = make_near_plane()
    path = os.path.join(args.out, "near_plane.npz")
    save_npz(path, out)
    print(f"near_plane: {stats}, {os.path.getsize(path)} bytes")


if __name__ == "__main__":
    main()
