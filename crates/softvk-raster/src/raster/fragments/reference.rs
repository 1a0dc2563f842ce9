//! The f64 CPU twin of PyTorch3D's mesh rasterizer, forward ([`rasterize`]) and backward
//! ([`rasterize_grad`]): the oracle the fragment kernels are tested against, as
//! [`crate::raster::reference`] is the soft rasterizer's. The contract it implements is the
//! [module's](super).

use super::FragmentSettings;

/// PyTorch3D's `kEpsilon` in `geometry_utils.h`.
const EPSILON: f64 = 1e-8;

/// The K nearest faces of every pixel, `[meshes, H, W, K]` row-major (row 0 at the top), as
/// PyTorch3D's `Fragments`.
#[derive(Clone, Debug, PartialEq)]
pub struct Fragments {
    /// Packed face index, −1 where fewer than K faces reach the pixel.
    pub pix_to_face: Vec<i64>,
    /// The depth at the pixel, `Σ w̃_k z_k` (−1 in an empty slot).
    pub zbuf: Vec<f64>,
    /// The (clipped, corrected) barycentrics (−1 in an empty slot).
    pub bary_coords: Vec<[f64; 3]>,
    /// The signed squared distance to the face's nearest edge, negative inside (−1 in an
    /// empty slot).
    pub dists: Vec<f64>,
}

/// PyTorch3D's `PixToNonSquareNdc(i, S1, S2)`: the NDC coordinate of pixel index `i` along a
/// side of `S1` pixels, the other side `S2`.
pub fn pixel_ndc(i: u32, s1: u32, s2: u32) -> f64 {
    let range = if s1 > s2 {
        2.0 * f64::from(s1) / f64::from(s2)
    } else {
        2.0
    };
    let offset = range / 2.0;
    -offset + (range * f64::from(i) + offset) / f64::from(s1)
}

/// The NDC point that output pixel (`row`, `col`) samples (+X left, +Y up).
pub fn pixel_point(row: u32, col: u32, width: u32, height: u32) -> [f64; 2] {
    [
        pixel_ndc(width - 1 - col, width, height),
        pixel_ndc(height - 1 - row, height, width),
    ]
}

type V2 = [f64; 2];

fn sub(a: V2, b: V2) -> V2 {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: V2, b: V2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn xy(v: [f64; 3]) -> V2 {
    [v[0], v[1]]
}

/// `EdgeFunctionForward(p, v0, v1)`.
fn edge(p: V2, v0: V2, v1: V2) -> f64 {
    (p[0] - v0[0]) * (v1[1] - v0[1]) - (p[1] - v0[1]) * (v1[0] - v0[0])
}

/// The gradients of [`edge`] to `(p, v0, v1)`, times `g`.
fn edge_grad(p: V2, v0: V2, v1: V2, g: f64) -> (V2, V2, V2) {
    (
        [g * (v1[1] - v0[1]), g * (v0[0] - v1[0])],
        [g * (p[1] - v1[1]), g * (v1[0] - p[0])],
        [g * (v0[1] - p[1]), g * (p[0] - v0[0])],
    )
}

/// `BarycentricCoordinatesForward`: the edge functions over the area (plus 1e-8).
fn barycentric(p: V2, v: [V2; 3]) -> [f64; 3] {
    let area = edge(v[2], v[0], v[1]) + EPSILON;
    [
        edge(p, v[1], v[2]) / area,
        edge(p, v[2], v[0]) / area,
        edge(p, v[0], v[1]) / area,
    ]
}

/// The adjoint of [`barycentric`] to the vertices.
fn barycentric_grad(p: V2, v: [V2; 3], g: [f64; 3]) -> [V2; 3] {
    let area = edge(v[2], v[0], v[1]) + EPSILON;
    let mut d = [[0.0; 2]; 3];
    // w_k = e_k / area, e_k = edge(p, v_{k+1}, v_{k+2}).
    for (k, &gk) in g.iter().enumerate() {
        let (a, b) = ((k + 1) % 3, (k + 2) % 3);
        let e = edge(p, v[a], v[b]);
        let (_, de_a, de_b) = edge_grad(p, v[a], v[b], gk / area);
        // area = edge(v2, v0, v1): its gradient to (v2, v0, v1).
        let (da_2, da_0, da_1) = edge_grad(v[2], v[0], v[1], -gk * e / (area * area));
        for (i, dv) in [(a, de_a), (b, de_b), (2, da_2), (0, da_0), (1, da_1)] {
            d[i][0] += dv[0];
            d[i][1] += dv[1];
        }
    }
    d
}

/// `BarycentricPerspectiveCorrectionForward`.
fn perspective(w: [f64; 3], z: [f64; 3]) -> [f64; 3] {
    let top = [w[0] * z[1] * z[2], w[1] * z[0] * z[2], w[2] * z[0] * z[1]];
    let denom = (top[0] + top[1] + top[2]).max(EPSILON);
    top.map(|t| t / denom)
}

/// The adjoint of [`perspective`]: to the barycentrics and to the depths.
fn perspective_grad(w: [f64; 3], z: [f64; 3], g: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let top = [w[0] * z[1] * z[2], w[1] * z[0] * z[2], w[2] * z[0] * z[1]];
    let denom = (top[0] + top[1] + top[2]).max(EPSILON);
    let d_denom = -(top[0] * g[0] + top[1] * g[1] + top[2] * g[2]) / (denom * denom);
    let d_top = [0, 1, 2].map(|k| d_denom + g[k] / denom);
    let d_w = [
        d_top[0] * z[1] * z[2],
        d_top[1] * z[0] * z[2],
        d_top[2] * z[0] * z[1],
    ];
    let d_z = [
        d_top[1] * w[1] * z[2] + d_top[2] * w[2] * z[1],
        d_top[0] * w[0] * z[2] + d_top[2] * w[2] * z[0],
        d_top[0] * w[0] * z[1] + d_top[1] * w[1] * z[0],
    ];
    (d_w, d_z)
}

/// `BarycentricClipForward`: clamped at 0, divided by their sum (at least 1e-5).
fn clip(w: [f64; 3]) -> [f64; 3] {
    let c = w.map(|x| x.max(0.0));
    let sum = (c[0] + c[1] + c[2]).max(1e-5);
    c.map(|x| x / sum)
}

/// `BarycentricClipBackward`.
fn clip_grad(w: [f64; 3], g: [f64; 3]) -> [f64; 3] {
    let c = w.map(|x| x.max(0.0));
    let mut sum = c[0] + c[1] + c[2];
    let mut through_sum = 1.0;
    if sum < 1e-5 {
        through_sum = 0.0;
        sum = 1e-5;
    }
    let d_sum = c.map(|x| -x / (sum * sum) * through_sum);
    [0, 1, 2].map(|k| {
        if w[k] < 0.0 {
            return 0.0;
        }
        let mut d = g[k] / sum;
        for j in 0..3 {
            d += g[j] * d_sum[j];
        }
        d
    })
}

/// `PointLineDistanceForward`: the squared distance from `p` to the segment `v0 v1`.
fn segment_dist2(p: V2, v0: V2, v1: V2) -> f64 {
    let d = sub(v1, v0);
    let l2 = dot(d, d);
    if l2 <= EPSILON {
        let r = sub(p, v1);
        return dot(r, r);
    }
    let t = (dot(d, sub(p, v0)) / l2).clamp(0.0, 1.0);
    let r = sub(p, [v0[0] + t * d[0], v0[1] + t * d[1]]);
    dot(r, r)
}

/// `PointLineDistanceBackward`: the gradient to `(v0, v1)`, the nearest point held fixed.
fn segment_dist2_grad(p: V2, v0: V2, v1: V2, g: f64) -> (V2, V2) {
    let d = sub(v1, v0);
    let t = (dot(d, sub(p, v0)) / dot(d, d)).clamp(0.0, 1.0);
    let proj = [(1.0 - t) * v0[0] + t * v1[0], (1.0 - t) * v0[1] + t * v1[1]];
    let r = sub(proj, p);
    (
        [g * (1.0 - t) * 2.0 * r[0], g * (1.0 - t) * 2.0 * r[1]],
        [g * t * 2.0 * r[0], g * t * 2.0 * r[1]],
    )
}

/// The three edges in PyTorch3D's order (01, 02, 12) and their squared distances.
fn edge_dists(p: V2, v: [V2; 3]) -> [f64; 3] {
    [
        segment_dist2(p, v[0], v[1]),
        segment_dist2(p, v[0], v[2]),
        segment_dist2(p, v[1], v[2]),
    ]
}

/// `PointTriangleDistanceBackward`: through the nearest edge (ties: 01, then 02, then 12).
fn triangle_dist2_grad(p: V2, v: [V2; 3], g: f64) -> [V2; 3] {
    let e = edge_dists(p, v);
    let mut out = [[0.0; 2]; 3];
    let (a, b) = if e[0] <= e[1] && e[0] <= e[2] {
        (0, 1)
    } else if e[1] <= e[0] && e[1] <= e[2] {
        (0, 2)
    } else {
        (1, 2)
    };
    let (da, db) = segment_dist2_grad(p, v[a], v[b], g);
    out[a] = da;
    out[b] = db;
    out
}

/// A face's barycentrics at `p`: as the edge functions give them, after the perspective
/// correction (if asked; what "inside" tests), and after the clip (if asked; what the depth and
/// the outputs use).
fn barycentrics(p: V2, v: [V2; 3], z: [f64; 3], s: &FragmentSettings) -> [[f64; 3]; 3] {
    let w0 = barycentric(p, v);
    let w = if s.perspective_correct {
        perspective(w0, z)
    } else {
        w0
    };
    let w_clip = if s.clip_barycentric_coords {
        clip(w)
    } else {
        w
    };
    [w0, w, w_clip]
}

/// One face's values at one pixel, when the face reaches it.
struct Hit {
    z: f64,
    signed_dist: f64,
    bary_clip: [f64; 3],
}

/// Whether PyTorch3D skips the face at every pixel: zero area, culled, a vertex nearer than
/// 1e-8, or (softvk's rule, where PyTorch3D's arithmetic is NaN) a coordinate not finite.
pub fn face_skipped(face: &[[f64; 3]; 3], s: &FragmentSettings) -> bool {
    let v = face.map(xy);
    let area = edge(v[0], v[1], v[2]);
    let z_min = face[0][2].min(face[1][2]).min(face[2][2]);
    (s.cull_backfaces && area < 0.0)
        || area.abs() <= EPSILON
        || z_min < EPSILON
        || face.iter().flatten().any(|c| !c.is_finite())
}

/// What a face gives pixel `p` (PyTorch3D's inner loop), or `None` where it is skipped.
fn hit(face: &[[f64; 3]; 3], p: V2, s: &FragmentSettings) -> Option<Hit> {
    if face_skipped(face, s) {
        return None;
    }
    let v = face.map(xy);
    let z = face.map(|c| c[2]);
    let grow = s.blur_radius.sqrt();
    let (lo, hi) = v.iter().fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), c| {
            (
                [lo[0].min(c[0]), lo[1].min(c[1])],
                [hi[0].max(c[0]), hi[1].max(c[1])],
            )
        },
    );
    if p[0] > hi[0] + grow || p[0] < lo[0] - grow || p[1] > hi[1] + grow || p[1] < lo[1] - grow {
        return None;
    }
    let [_, w, w_clip] = barycentrics(p, v, z, s);
    let pz = w_clip[0] * z[0] + w_clip[1] * z[1] + w_clip[2] * z[2];
    if pz < 0.0 {
        return None;
    }
    let e = edge_dists(p, v);
    let dist = e[0].min(e[1]).min(e[2]);
    let inside = w.iter().all(|&x| x > 0.0);
    if !inside && dist >= s.blur_radius {
        return None;
    }
    Some(Hit {
        z: pz,
        signed_dist: if inside { -dist } else { dist },
        bary_clip: w_clip,
    })
}

/// The fragments of the meshes whose faces are `face_verts[first..first + count]` for each
/// `(first, count)` of `meshes` (PyTorch3D's packed faces: `pix_to_face` holds indices into
/// `face_verts`). `neighbors`, when given, holds for each face the other half of a face that
/// PyTorch3D's near-plane clipping cut in two, or −1 (its `clipped_faces_neighbor_idx`).
pub fn rasterize(
    face_verts: &[[[f64; 3]; 3]],
    meshes: &[(usize, usize)],
    neighbors: Option<&[i64]>,
    s: &FragmentSettings,
) -> Fragments {
    let (w, h, k) = (s.width, s.height, s.faces_per_pixel);
    let slots = meshes.len() * (w * h) as usize * k;
    let mut out = Fragments {
        pix_to_face: vec![-1; slots],
        zbuf: vec![-1.0; slots],
        bary_coords: vec![[-1.0; 3]; slots],
        dists: vec![-1.0; slots],
    };
    // PyTorch3D's deque, kept sorted by (z, f): the nearest first, then the lower index.
    let mut list: Vec<(f64, usize, Hit)> = Vec::new();
    for (n, &(first, count)) in meshes.iter().enumerate() {
        for row in 0..h {
            for col in 0..w {
                let p = pixel_point(row, col, w, h);
                list.clear();
                for (f, face) in face_verts.iter().enumerate().skip(first).take(count) {
                    let Some(hit) = hit(face, p, s) else {
                        continue;
                    };
                    let other = neighbors.map_or(-1, |nb| nb[f]);
                    let at = list.iter().position(|e| e.1 as i64 == other && other >= 0);
                    match at {
                        // The other half is in the list: replaced if this half is nearer.
                        Some(i) => {
                            if hit.signed_dist.abs() < list[i].2.signed_dist.abs() {
                                list[i] = (hit.z, f, hit);
                            }
                        }
                        None => list.push((hit.z, f, hit)),
                    }
                    list.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                    list.truncate(k);
                }
                let base = ((n * h as usize + row as usize) * w as usize + col as usize) * k;
                for (slot, (_, f, hit)) in list.iter().enumerate() {
                    out.pix_to_face[base + slot] = *f as i64;
                    out.zbuf[base + slot] = hit.z;
                    out.bary_coords[base + slot] = hit.bary_clip;
                    out.dists[base + slot] = hit.signed_dist;
                }
            }
        }
    }
    out
}

/// The gradient of `Σ grad_zbuf·zbuf + grad_bary·bary_coords + grad_dists·dists` to the face
/// vertices, given the forward's `pix_to_face` (`[meshes, H, W, K]`, as [`rasterize`] returns
/// it): PyTorch3D's backward.
pub fn rasterize_grad(
    face_verts: &[[[f64; 3]; 3]],
    pix_to_face: &[i64],
    grad_zbuf: &[f64],
    grad_bary: &[[f64; 3]],
    grad_dists: &[f64],
    s: &FragmentSettings,
) -> Vec<[[f64; 3]; 3]> {
    let (w, h, k) = (s.width as usize, s.height as usize, s.faces_per_pixel);
    let mut grad = vec![[[0.0; 3]; 3]; face_verts.len()];
    for (i, &f) in pix_to_face.iter().enumerate() {
        let Ok(f) = usize::try_from(f) else {
            continue;
        };
        let pixel = i / k;
        let (row, col) = ((pixel / w) % h, pixel % w);
        let p = pixel_point(row as u32, col as u32, s.width, s.height);
        let face = &face_verts[f];
        let v = face.map(xy);
        let z = face.map(|c| c[2]);
        let [w0, wp, w_clip] = barycentrics(p, v, z, s);
        let inside = wp.iter().all(|&x| x > 0.0);
        let sign = if inside { -1.0 } else { 1.0 };
        let d_dist = triangle_dist2_grad(p, v, sign * grad_dists[i]);
        let gz = grad_zbuf[i];
        let mut d_w = [0, 1, 2].map(|c| grad_bary[i][c] + gz * z[c]);
        if s.clip_barycentric_coords {
            d_w = clip_grad(wp, d_w);
        }
        if s.perspective_correct {
            let (d_w0, d_z) = perspective_grad(w0, z, d_w);
            d_w = d_w0;
            for c in 0..3 {
                grad[f][c][2] += d_z[c];
            }
        }
        let d_v = barycentric_grad(p, v, d_w);
        for c in 0..3 {
            grad[f][c][0] += d_v[c][0] + d_dist[c][0];
            grad[f][c][1] += d_v[c][1] + d_dist[c][1];
            grad[f][c][2] += gz * w_clip[c];
        }
    }
    grad
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings(width: u32, height: u32, k: usize) -> FragmentSettings {
        FragmentSettings {
            width,
            height,
            blur_radius: 0.0,
            faces_per_pixel: k,
            perspective_correct: false,
            clip_barycentric_coords: false,
            cull_backfaces: false,
        }
    }

    #[test]
    fn pixel_centres_span_the_shorter_side_with_x_left_and_y_up() {
        // Square 4×4: centres at ±0.25, ±0.75; column 0 is +X (left), row 0 is +Y (top).
        assert_eq!(pixel_point(0, 0, 4, 4), [0.75, 0.75]);
        assert_eq!(pixel_point(3, 3, 4, 4), [-0.75, -0.75]);
        // 8 wide, 4 high: the height spans [-1, 1], the width [-2, 2].
        assert_eq!(pixel_point(0, 0, 8, 4), [1.75, 0.75]);
        assert_eq!(pixel_point(3, 7, 8, 4), [-1.75, -0.75]);
    }

    #[test]
    fn the_nearest_faces_come_first_and_equal_depths_by_index() {
        // Three big faces over the whole view: two at depth 2 (indices 0 and 2), one at 1.
        let big = |z: f64| [[-3.0, -3.0, z], [3.0, -3.0, z], [0.0, 3.0, z]];
        let faces = [big(2.0), big(1.0), big(2.0)];
        let s = settings(2, 2, 4);
        let out = rasterize(&faces, &[(0, 3)], None, &s);
        assert_eq!(&out.pix_to_face[..4], &[1, 0, 2, -1]);
        // (The depths carry PyTorch3D's 1e-8 on the area: w_k = e_k / (area + 1e-8).)
        for (z, want) in out.zbuf[..4].iter().zip([1.0, 2.0, 2.0, -1.0]) {
            assert!((z - want).abs() < 1e-8, "{z} {want}");
        }
        assert_eq!(out.bary_coords[3], [-1.0; 3]);
        assert!(out.dists[0] < 0.0 && out.dists[3] == -1.0);
        // Culling drops faces of negative area: these wind the other way.
        let culled = rasterize(
            &faces,
            &[(0, 3)],
            None,
            &FragmentSettings {
                cull_backfaces: true,
                ..s
            },
        );
        let area = edge(xy(faces[0][0]), xy(faces[0][1]), xy(faces[0][2]));
        assert!(area < 0.0);
        assert!(culled.pix_to_face.iter().all(|&f| f == -1));
    }

    #[test]
    fn the_backward_matches_central_differences() {
        // Coordinates off the pixel grid's lines, so that no pixel sits on a face's edge line,
        // where the clip's kink would be (central differences across it are not a derivative).
        let faces = [
            [
                [0.613, -0.487, 2.0],
                [-0.391, 0.722, 2.6],
                [-0.688, -0.579, 3.1],
            ],
            [
                [0.207, 0.813, 1.5],
                [0.917, -0.183, 2.2],
                [-0.286, -0.094, 1.8],
            ],
            [
                [-0.893, 0.117, 2.4],
                [0.109, 0.311, 2.0],
                [-0.514, 0.902, 2.9],
            ],
        ];
        let meshes = [(0, 3)];
        for (perspective_correct, clip_barycentric_coords) in
            [(false, false), (true, false), (false, true), (true, true)]
        {
            let s = FragmentSettings {
                width: 7,
                height: 5,
                blur_radius: 0.03,
                faces_per_pixel: 3,
                perspective_correct,
                clip_barycentric_coords,
                cull_backfaces: false,
            };
            let out = rasterize(&faces, &meshes, None, &s);
            let n = out.pix_to_face.len();
            let weight = |i: usize, c: usize| ((i * 7 + c * 3) % 11) as f64 / 11.0 - 0.45;
            let gz: Vec<f64> = (0..n).map(|i| weight(i, 0)).collect();
            let gb: Vec<[f64; 3]> = (0..n)
                .map(|i| [weight(i, 1), weight(i, 2), weight(i, 3)])
                .collect();
            let gd: Vec<f64> = (0..n).map(|i| weight(i, 4)).collect();
            // The loss over the forward's own selection (a small step keeps it: no pixel is
            // near a cut-off or a tie here, checked by the equal pix_to_face below).
            let loss = |fv: &[[[f64; 3]; 3]]| {
                let o = rasterize(fv, &meshes, None, &s);
                assert_eq!(o.pix_to_face, out.pix_to_face);
                (0..n)
                    .map(|i| {
                        if o.pix_to_face[i] < 0 {
                            return 0.0;
                        }
                        gz[i] * o.zbuf[i]
                            + gd[i] * o.dists[i]
                            + (0..3).map(|c| gb[i][c] * o.bary_coords[i][c]).sum::<f64>()
                    })
                    .sum::<f64>()
            };
            let grad = rasterize_grad(&faces, &out.pix_to_face, &gz, &gb, &gd, &s);
            let h = 1e-6;
            let mut largest = 0.0f64;
            for f in 0..3 {
                for c in 0..3 {
                    for a in 0..3 {
                        let (mut up, mut down) = (faces, faces);
                        up[f][c][a] += h;
                        down[f][c][a] -= h;
                        let fd = (loss(&up) - loss(&down)) / (2.0 * h);
                        let got = grad[f][c][a];
                        largest = largest.max(fd.abs());
                        assert!(
                            (got - fd).abs() <= 1e-6 * fd.abs() + 1e-6,
                            "{perspective_correct} {clip_barycentric_coords} face {f} corner {c} \
                             axis {a}: {got} against {fd}"
                        );
                    }
                }
            }
            assert!(largest > 0.1);
        }
    }
}
