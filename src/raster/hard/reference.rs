//! The f64 CPU twin of the hard rasterizer and of `interpolate`, forward and backward: every
//! rule of the module docs ([`super`]) written plainly, pixel by pixel, as the oracle of the
//! kernels' tests.
//!
//! Coverage is decided in exact integer arithmetic on snapped vertices, so the twin and the
//! kernels (which snap f32 projections) agree on every pixel unless a vertex projects within a
//! rounding error of a snapping boundary, or two candidate depths are within f32's reach of
//! each other: such pixels are flagged in [`Layer::ambiguous`], and tests compare ids exactly
//! on the rest and count these.
//!
//! Gradients are the dual-number derivative ([`super::dual`]) of the same per-pixel function
//! the forward evaluates, for fixed visibility.

use super::dual::Dual;
use super::{SUBPIXELS, Shape};

/// A clip-space vertex `(x, y, z, w)`.
pub type Clip = [f64; 4];

/// One rasterized layer, `[B, H, W, 4]` arrays in nvdiffrast's layout.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    /// `(u, v, z/w, id + 1)`, zero where nothing is drawn.
    pub rast: Vec<f64>,
    /// `(du/dX, du/dY, dv/dX, dv/dY)`, zero where nothing is drawn.
    pub rast_db: Vec<f64>,
    /// Per pixel, the drawn surface's place in the depth order (what the next peeled layer
    /// starts after); `None` where nothing is drawn.
    pub keys: Vec<Option<DepthKey>>,
    /// Pixels whose id the f32 kernels may decide otherwise (see the module docs).
    pub ambiguous: Vec<bool>,
}

/// A surface's place in a pixel's depth order: nearest `z/w` first (unclamped), then the
/// highest triangle id.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthKey {
    /// `z/w` at the pixel centre, before the output's clamp.
    pub zw: f64,
    /// The triangle's index.
    pub triangle: u32,
}

impl DepthKey {
    /// Whether `self` comes before `other` in the pixel's depth order.
    pub fn before(&self, other: &DepthKey) -> bool {
        self.zw < other.zw || (self.zw == other.zw && self.triangle > other.triangle)
    }
}

/// How far from the viewport's centre, in sub-pixel units, a vertex may project and still be
/// snapped (`SNAP_LIMIT` in `kernels/include/hard.glsl`): 2^21, i.e. 2^18 / W viewport
/// half-widths. A snapped triangle's edges then span less than 2^22 units, so an edge function's
/// step across an 8-pixel tile stays below 2^30 and the depth pass's clamped 32-bit edge
/// functions keep their signs.
pub const SNAP_LIMIT: f64 = 2_097_152.0;
/// How the rasterizer tests a triangle's coverage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Coverage {
    /// In front of the eye, inside the depth range and the guard band: snapped, integer edge
    /// functions with the fill rule (nvdiffrast's rule).
    Snapped(Snapped),
    /// Crossing the near or far plane, or the guard band: the centre is inside where the
    /// homogeneous edge functions all have their sum's sign, the interpolated w is positive and
    /// `z/w` is in [−1, 1] (exactly the clipped triangle's coverage, unsnapped).
    Homogeneous,
}

/// Whether every vertex lies beyond the same frustum plane (then nothing is drawn).
pub fn outside_one_plane(tri: &[Clip; 3]) -> bool {
    (0..3).any(|axis| tri.iter().all(|v| v[axis] > v[3]) || tri.iter().all(|v| -v[axis] > v[3]))
}

/// Whether the triangle is snapped: every vertex has `w > 0`, `|z| ≤ w` and
/// `|x| · 8W, |y| · 8H ≤ SNAP_LIMIT · w` (the kernel's test, `hard_setup.comp`).
pub fn snappable(tri: &[Clip; 3], width: u32, height: u32) -> bool {
    let (sx, sy) = (8.0 * f64::from(width), 8.0 * f64::from(height));
    tri.iter().all(|v| {
        v[3] > 0.0
            && v[2].abs() <= v[3]
            && v[0].abs() * sx <= SNAP_LIMIT * v[3]
            && v[1].abs() * sy <= SNAP_LIMIT * v[3]
    })
}

/// The coverage test of a triangle, or `None` when it draws nothing (wholly beyond one frustum
/// plane, or of zero area once snapped).
pub fn coverage(tri: [Clip; 3], width: u32, height: u32) -> Option<Coverage> {
    if outside_one_plane(&tri) {
        return None;
    }
    if !snappable(&tri, width, height) {
        return Some(Coverage::Homogeneous);
    }
    let snapped = tri.map(|v| snap(&v, width, height, SNAP_TOLERANCE));
    Snapped::new(snapped.map(|c| c.0), snapped.iter().any(|c| c.1)).map(Coverage::Snapped)
}

/// The homogeneous test of [`Coverage::Homogeneous`] at NDC `f`.
pub fn homogeneous_covers(tri: &[Clip; 3], f: [f64; 2]) -> bool {
    let rel: Vec<[f64; 2]> = tri
        .iter()
        .map(|v| [v[0] - f[0] * v[3], v[1] - f[1] * v[3]])
        .collect();
    let ar = |i: usize, j: usize| rel[i][0] * rel[j][1] - rel[i][1] * rel[j][0];
    let a = [ar(1, 2), ar(2, 0), ar(0, 1)];
    let at: f64 = a.iter().sum();
    let wsum: f64 = (0..3).map(|k| a[k] * tri[k][3]).sum();
    let zsum: f64 = (0..3).map(|k| a[k] * tri[k][2]).sum();
    at != 0.0 && a.iter().all(|&ak| ak * at >= 0.0) && wsum * at > 0.0 && zsum.abs() <= wsum.abs()
}

/// Whether f32 arithmetic may decide [`homogeneous_covers`] otherwise at `f`: an edge function,
/// the interpolated w or the depth-range test within rounding of its threshold.
pub fn homogeneous_uncertain(tri: &[Clip; 3], f: [f64; 2]) -> bool {
    let rel: Vec<[f64; 2]> = tri
        .iter()
        .map(|v| [v[0] - f[0] * v[3], v[1] - f[1] * v[3]])
        .collect();
    let terms = |i: usize, j: usize| {
        let (p, q) = (rel[i][0] * rel[j][1], rel[i][1] * rel[j][0]);
        (p - q, p.abs() + q.abs())
    };
    let a = [terms(1, 2), terms(2, 0), terms(0, 1)];
    let scale = a.iter().map(|t| t.1).fold(0.0, f64::max);
    let wsum: f64 = (0..3).map(|k| a[k].0 * tri[k][3]).sum();
    let wscale: f64 = (0..3).map(|k| (a[k].0 * tri[k][3]).abs()).sum();
    let zsum: f64 = (0..3).map(|k| a[k].0 * tri[k][2]).sum();
    let tol = HOMOGENEOUS_TOLERANCE;
    a.iter().any(|t| t.0.abs() <= tol * scale)
        || wsum.abs() <= tol * wscale
        || (zsum.abs() - wsum.abs()).abs() <= tol * (zsum.abs() + wsum.abs())
}

/// A vertex projected to the viewport in sub-pixel units from the viewport's centre:
/// `round-half-even(x/w · 8 W)`, `round-half-even(y/w · 8 H)` (unsaturated: the clipped
/// polygon lies in the viewport). Also whether either coordinate is within `tolerance` units
/// of a rounding boundary, where an f32 projection may snap the other way.
pub fn snap(v: &Clip, width: u32, height: u32, tolerance: f64) -> ([i64; 2], bool) {
    let half = (SUBPIXELS / 2) as f64;
    let x = v[0] / v[3] * (half * f64::from(width));
    let y = v[1] / v[3] * (half * f64::from(height));
    let near = |c: f64| (c - c.floor() - 0.5).abs() < tolerance;
    (
        [x.round_ties_even() as i64, y.round_ties_even() as i64],
        near(x) || near(y),
    )
}

/// A snapped (sub)triangle, counter-clockwise (positive area), in sub-pixel units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Snapped {
    /// The corners.
    pub p: [[i64; 2]; 3],
    /// A corner snapped within rounding of a boundary (coverage near its edges is ambiguous).
    pub uncertain: bool,
}

impl Snapped {
    /// From three snapped corners: `None` when their area is zero; clockwise corners are
    /// swapped to counter-clockwise.
    pub fn new(mut p: [[i64; 2]; 3], uncertain: bool) -> Option<Self> {
        let area = cross(p[0], p[1], p[2]);
        if area == 0 {
            return None;
        }
        if area < 0 {
            p.swap(1, 2);
        }
        Some(Self { p, uncertain })
    }

    /// Whether the sample `s` (sub-pixel units from the centre) is inside, with the fill rule:
    /// on an edge, inside when the edge is a left edge (going down) or a bottom edge (going
    /// right, horizontal).
    pub fn covers(&self, s: [i64; 2]) -> bool {
        (0..3).all(|k| {
            let (a, b) = (self.p[k], self.p[(k + 1) % 3]);
            let e = edge_function(a, b, s);
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            e > 0 || (e == 0 && (dy < 0 || (dy == 0 && dx > 0)))
        })
    }

    /// The smallest distance, in sub-pixel units, from `s` to the lines of the three edges,
    /// signed positive inside: where it is small, a corner snapped one unit away could change
    /// `covers`.
    pub fn boundary_distance(&self, s: [i64; 2]) -> f64 {
        (0..3)
            .map(|k| {
                let (a, b) = (self.p[k], self.p[(k + 1) % 3]);
                let len = (((b[0] - a[0]).pow(2) + (b[1] - a[1]).pow(2)) as f64).sqrt();
                edge_function(a, b, s) as f64 / len
            })
            .fold(f64::INFINITY, f64::min)
    }
}

/// `(b − a) × (s − a)`: positive when `s` is left of `a → b` (y up).
pub fn edge_function(a: [i64; 2], b: [i64; 2], s: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (s[1] - a[1]) - (b[1] - a[1]) * (s[0] - a[0])
}

fn cross(a: [i64; 2], b: [i64; 2], c: [i64; 2]) -> i64 {
    edge_function(a, b, c)
}

/// Tolerance of [`snap`]: an f32 projection `x/w · 8 W` is within this many units of the f64
/// one.
const SNAP_TOLERANCE: f64 = 1e-3;

/// Two depths closer than this may be ordered either way by the f32 kernels.
const DEPTH_TOLERANCE: f64 = 1e-5;

/// Within this many sub-pixel units of an uncertain triangle's edges, coverage is ambiguous.
const EDGE_TOLERANCE: f64 = 2.0;

/// A homogeneous edge function within this fraction of the largest term of its sum may have
/// the other sign in f32.
const HOMOGENEOUS_TOLERANCE: f64 = 1e-5;

/// Pixel `(x, y)`'s sample in sub-pixel units from the viewport centre.
pub fn sample(x: u32, y: u32, width: u32, height: u32) -> [i64; 2] {
    let half = SUBPIXELS / 2;
    let s = |c: u32, n: u32| SUBPIXELS * i64::from(c) + half - half * i64::from(n);
    [s(x, width), s(y, height)]
}

/// Pixel `(x, y)`'s centre in NDC.
pub fn pixel_ndc(x: u32, y: u32, width: u32, height: u32) -> [f64; 2] {
    [
        (2.0 * f64::from(x) + 1.0) / f64::from(width) - 1.0,
        (2.0 * f64::from(y) + 1.0) / f64::from(height) - 1.0,
    ]
}

/// The arithmetic the per-pixel function needs: f64 for the forward, [`Dual`] for the
/// backward.
pub trait Scalar:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Mul<f64, Output = Self>
    + std::ops::Div<Output = Self>
{
    /// A constant.
    fn of(c: f64) -> Self;
    /// The value.
    fn value(self) -> f64;
    /// Clamped to `[lo, hi]`.
    fn clamp_to(self, lo: f64, hi: f64) -> Self;
    /// The larger of `self` and `c`.
    fn at_least(self, c: f64) -> Self;
}

impl Scalar for f64 {
    fn of(c: f64) -> Self {
        c
    }
    fn value(self) -> f64 {
        self
    }
    fn clamp_to(self, lo: f64, hi: f64) -> Self {
        self.clamp(lo, hi)
    }
    fn at_least(self, c: f64) -> Self {
        self.max(c)
    }
}

impl<const N: usize> Scalar for Dual<N> {
    fn of(c: f64) -> Self {
        Dual::constant(c)
    }
    fn value(self) -> f64 {
        self.value
    }
    fn clamp_to(self, lo: f64, hi: f64) -> Self {
        self.clamp(lo, hi)
    }
    fn at_least(self, c: f64) -> Self {
        self.max_constant(c)
    }
}

/// What a drawn pixel reports, for the triangle `p` (clip space) at NDC `f`: the
/// perspective-correct barycentrics of vertices 0 and 1, clamped (each to [0, 1], their sum
/// to at most 1); `z/w` unclamped; and `(du/dX, du/dY, dv/dX, dv/dY)` per pixel (from the
/// clamped u, v, as nvdiffrast).
#[derive(Clone, Copy, Debug)]
pub struct Shaded<T> {
    /// u, v.
    pub uv: [T; 2],
    /// z/w before the output's clamp.
    pub zw: f64,
    /// The pixel derivatives.
    pub db: [T; 4],
}

/// The per-pixel function of the rasterizer (and its backward, on duals). Homogeneous 2D edge
/// functions of the pixel centre: `p_k' = (x_k − f_x w_k, y_k − f_y w_k)`, `a_0 = p_1' × p_2'`,
/// `a_1 = p_2' × p_0'`, `a_2 = p_0' × p_1'`; `u = a_0 / Σa`, `v = a_1 / Σa`,
/// `z/w = Σ z_k a_k / Σ w_k a_k`. The pixel derivatives follow from `∂a_k/∂f_x` and `∂a_k/∂f_y`
/// (which do not depend on the pixel) and `∂f/∂X = 2/W`, `∂f/∂Y = 2/H`.
pub fn shade<T: Scalar>(
    xyw: [[T; 3]; 3],
    z: [f64; 3],
    f: [f64; 2],
    width: u32,
    height: u32,
) -> Shaded<T> {
    let rel: [[T; 2]; 3] =
        std::array::from_fn(|k| [xyw[k][0] - xyw[k][2] * f[0], xyw[k][1] - xyw[k][2] * f[1]]);
    let area = |i: usize, j: usize| rel[i][0] * rel[j][1] - rel[i][1] * rel[j][0];
    let a = [area(1, 2), area(2, 0), area(0, 1)];
    let at = a[0] + a[1] + a[2];
    let iw = T::of(1.0) / at;
    let wsum = a[0] * xyw[0][2] + a[1] * xyw[1][2] + a[2] * xyw[2][2];
    let zsum = a[0].value() * z[0] + a[1].value() * z[1] + a[2].value() * z[2];
    let zw = zsum / wsum.value();
    let u0 = (a[0] * iw).clamp_to(0.0, 1.0);
    let v0 = (a[1] * iw).clamp_to(0.0, 1.0);
    let scale = T::of(1.0) / (u0 + v0).at_least(1.0);
    let (u, v) = (u0 * scale, v0 * scale);
    // ∂a_k/∂f: a_0 = p_1' × p_2' with ∂p_k'/∂f_x = (−w_k, 0), ∂p_k'/∂f_y = (0, −w_k).
    let dadf = |i: usize, j: usize| {
        [
            xyw[i][1] * xyw[j][2] - xyw[i][2] * xyw[j][1],
            xyw[i][2] * xyw[j][0] - xyw[i][0] * xyw[j][2],
        ]
    };
    let da = [dadf(1, 2), dadf(2, 0), dadf(0, 1)];
    let dat = [
        da[0][0] + da[1][0] + da[2][0],
        da[0][1] + da[1][1] + da[2][1],
    ];
    let sx = T::of(2.0 / f64::from(width)) * iw;
    let sy = T::of(2.0 / f64::from(height)) * iw;
    let db = [
        sx * (da[0][0] - u * dat[0]),
        sy * (da[0][1] - u * dat[1]),
        sx * (da[1][0] - v * dat[0]),
        sy * (da[1][1] - v * dat[1]),
    ];
    Shaded { uv: [u, v], zw, db }
}

fn corners(shape: &Shape, pos: &[f64], tri: &[[u32; 3]], b: u32, t: u32) -> [Clip; 3] {
    let base = shape.vertex_base(b);
    tri[t as usize].map(|v| {
        let o = 4 * (base + v as usize);
        [pos[o], pos[o + 1], pos[o + 2], pos[o + 3]]
    })
}

/// Rasterizes every minibatch item of `shape` (validated by [`Shape::check`]); with `previous`
/// (the keys of the layer before), the next depth-peeling layer instead of the nearest.
pub fn rasterize(
    shape: &Shape,
    pos: &[f64],
    tri: &[[u32; 3]],
    previous: Option<&[Option<DepthKey>]>,
) -> Layer {
    let (w, h) = (shape.width, shape.height);
    let n = shape.pixels();
    let mut layer = Layer {
        rast: vec![0.0; 4 * n],
        rast_db: vec![0.0; 4 * n],
        keys: vec![None; n],
        ambiguous: vec![false; n],
    };
    for b in 0..shape.batch() {
        let drawn: Vec<(u32, [Clip; 3], Coverage)> = shape
            .triangles_of(b)
            .filter_map(|t| {
                let c = corners(shape, pos, tri, b, t);
                coverage(c, w, h).map(|cov| (t, c, cov))
            })
            .collect();
        for y in 0..h {
            for x in 0..w {
                let i = (b as usize * h as usize + y as usize) * w as usize + x as usize;
                let s = sample(x, y, w, h);
                let f = pixel_ndc(x, y, w, h);
                let after = previous.and_then(|p| p[i]);
                if previous.is_some() && after.is_none() {
                    continue; // the layer before drew nothing here: nothing is behind it
                }
                let mut best: Option<(DepthKey, [Clip; 3])> = None;
                let mut ambiguous = false;
                let mut zs = Vec::new();
                for (t, c, cov) in &drawn {
                    let covered = match cov {
                        Coverage::Snapped(q) => {
                            if q.uncertain && q.boundary_distance(s).abs() < EDGE_TOLERANCE {
                                ambiguous = true;
                            }
                            q.covers(s)
                        }
                        Coverage::Homogeneous => {
                            if homogeneous_uncertain(c, f) {
                                ambiguous = true;
                            }
                            homogeneous_covers(c, f)
                        }
                    };
                    if !covered {
                        continue;
                    }
                    let key = DepthKey {
                        zw: shade_f64(c, f, w, h).zw,
                        triangle: *t,
                    };
                    if !key.zw.is_finite() {
                        continue; // edge-on at this centre: not drawn
                    }
                    zs.push(key.zw);
                    if let Some(prev) = after {
                        if key.triangle != prev.triangle
                            && (key.zw - prev.zw).abs() < DEPTH_TOLERANCE
                        {
                            ambiguous = true;
                        }
                        if !prev.before(&key) {
                            continue;
                        }
                    }
                    if best.is_none_or(|(k, _)| key.before(&k)) {
                        best = Some((key, *c));
                    }
                }
                if let Some((key, c)) = best {
                    if zs
                        .iter()
                        .filter(|&&z| (z - key.zw).abs() < DEPTH_TOLERANCE)
                        .count()
                        > 1
                    {
                        ambiguous = true;
                    }
                    let sh = shade_f64(&c, f, w, h);
                    layer.rast[4 * i..4 * i + 4].copy_from_slice(&[
                        sh.uv[0],
                        sh.uv[1],
                        sh.zw.clamp(-1.0, 1.0),
                        f64::from(key.triangle + 1),
                    ]);
                    layer.rast_db[4 * i..4 * i + 4].copy_from_slice(&sh.db);
                    layer.keys[i] = Some(key);
                }
                layer.ambiguous[i] = ambiguous;
            }
        }
    }
    layer
}

fn shade_f64(c: &[Clip; 3], f: [f64; 2], w: u32, h: u32) -> Shaded<f64> {
    shade(c.map(|v| [v[0], v[1], v[3]]), c.map(|v| v[2]), f, w, h)
}

/// The drawn triangle of a `rast` pixel (channel 3 is its id + 1), or `None`.
pub fn drawn_triangle(rast: &[f64], i: usize, triangle_count: u32) -> Option<u32> {
    let id = rast[4 * i + 3];
    (id >= 1.0 && id <= f64::from(triangle_count)).then(|| id as u32 - 1)
}

/// The backward of [`rasterize`] for the visibility in `rast`: `dy` is the upstream gradient of
/// `rast` (channels 0 and 1 are used: z/w and the id take none) and `ddb` that of `rast_db`;
/// returns the gradient of `pos` (x, y and w; z gets none).
pub fn rasterize_grad(
    shape: &Shape,
    pos: &[f64],
    tri: &[[u32; 3]],
    rast: &[f64],
    dy: &[f64],
    ddb: Option<&[f64]>,
) -> Vec<f64> {
    let (w, h) = (shape.width, shape.height);
    let mut grad = vec![0.0; pos.len()];
    for b in 0..shape.batch() {
        let base = shape.vertex_base(b);
        for y in 0..h {
            for x in 0..w {
                let i = (b as usize * h as usize + y as usize) * w as usize + x as usize;
                let Some(t) = drawn_triangle(rast, i, shape.triangle_count) else {
                    continue;
                };
                let c = corners(shape, pos, tri, b, t);
                // Inputs 3k, 3k + 1, 3k + 2: vertex k's x, y and w.
                let xyw: [[Dual<9>; 3]; 3] = std::array::from_fn(|k| {
                    std::array::from_fn(|m| Dual::input(c[k][[0, 1, 3][m]], 3 * k + m))
                });
                let sh = shade(xyw, c.map(|v| v[2]), pixel_ndc(x, y, w, h), w, h);
                let mut g = [0.0; 9];
                let mut add = |d: &Dual<9>, up: f64| {
                    if up != 0.0 {
                        g.iter_mut().zip(d.grad).for_each(|(g, d)| *g += up * d);
                    }
                };
                add(&sh.uv[0], dy[4 * i]);
                add(&sh.uv[1], dy[4 * i + 1]);
                if let Some(ddb) = ddb {
                    for k in 0..4 {
                        add(&sh.db[k], ddb[4 * i + k]);
                    }
                }
                for (k, &v) in tri[t as usize].iter().enumerate() {
                    let o = 4 * (base + v as usize);
                    grad[o] += g[3 * k];
                    grad[o + 1] += g[3 * k + 1];
                    grad[o + 3] += g[3 * k + 2];
                }
            }
        }
    }
    grad
}

/// Where `interpolate` finds a pixel's attribute rows: `attr [V, A]` shared by the minibatch
/// (also `[1, V, A]`, broadcast), or `[B, V, A]`, one set per item (instanced mode only).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AttrLayout {
    /// Vertices V.
    pub vertex_count: u32,
    /// Attributes A per vertex.
    pub attr_count: u32,
    /// One set of attributes per minibatch item.
    pub per_item: bool,
}

impl AttrLayout {
    fn row(&self, b: usize, v: u32) -> usize {
        let set = if self.per_item { b } else { 0 };
        set * self.vertex_count as usize + v as usize
    }
}

/// `interpolate` for `rast` `[B, H, W, 4]` (`pixels` = B·H·W): `out [B, H, W, A]` =
/// `u a_0 + v a_1 + (1 − u − v) a_2`, and with `diff` (the attributes to differentiate) and
/// `rast_db`, `out_da [B, H, W, 2N]`: `(∂a/∂X, ∂a/∂Y)` for each listed attribute in order.
/// Zero where nothing is drawn.
pub fn interpolate(
    attr: &[f64],
    layout: AttrLayout,
    rast: &[f64],
    tri: &[[u32; 3]],
    pixels_per_item: usize,
    rast_db: Option<&[f64]>,
    diff: &[u32],
) -> (Vec<f64>, Vec<f64>) {
    let pixels = rast.len() / 4;
    let a = layout.attr_count as usize;
    let mut out = vec![0.0; pixels * a];
    let mut out_da = vec![0.0; pixels * 2 * diff.len()];
    for i in 0..pixels {
        let Some(t) = drawn_triangle(rast, i, tri.len() as u32) else {
            continue;
        };
        let rows = tri[t as usize].map(|v| a * layout.row(i / pixels_per_item, v));
        let (u, v) = (rast[4 * i], rast[4 * i + 1]);
        let bary = [u, v, 1.0 - u - v];
        for j in 0..a {
            out[i * a + j] = (0..3).map(|k| bary[k] * attr[rows[k] + j]).sum();
        }
        if let Some(db) = rast_db {
            for (n, &j) in diff.iter().enumerate() {
                let j = j as usize;
                let du = attr[rows[0] + j] - attr[rows[2] + j];
                let dv = attr[rows[1] + j] - attr[rows[2] + j];
                let o = i * 2 * diff.len() + 2 * n;
                out_da[o] = db[4 * i] * du + db[4 * i + 2] * dv;
                out_da[o + 1] = db[4 * i + 1] * du + db[4 * i + 3] * dv;
            }
        }
    }
    (out, out_da)
}

/// The gradients of [`interpolate`]: to `attr`, to `rast` (channels 0 and 1) and, with
/// `rast_db` and `dda` (the upstream gradient of `out_da`), to `rast_db`.
pub struct InterpolateGrads {
    /// Same shape as `attr`.
    pub attr: Vec<f64>,
    /// `[B, H, W, 4]`.
    pub rast: Vec<f64>,
    /// `[B, H, W, 4]` (zero without `rast_db`).
    pub rast_db: Vec<f64>,
}

/// The backward of [`interpolate`] (it is linear in `attr` and in `u, v` and `rast_db`
/// separately, so each gradient is written out directly).
#[allow(clippy::too_many_arguments)]
pub fn interpolate_grad(
    attr: &[f64],
    layout: AttrLayout,
    rast: &[f64],
    tri: &[[u32; 3]],
    pixels_per_item: usize,
    rast_db: Option<&[f64]>,
    diff: &[u32],
    dy: &[f64],
    dda: Option<&[f64]>,
) -> InterpolateGrads {
    let pixels = rast.len() / 4;
    let a = layout.attr_count as usize;
    let mut g = InterpolateGrads {
        attr: vec![0.0; attr.len()],
        rast: vec![0.0; 4 * pixels],
        rast_db: vec![0.0; 4 * pixels],
    };
    for i in 0..pixels {
        let Some(t) = drawn_triangle(rast, i, tri.len() as u32) else {
            continue;
        };
        let rows = tri[t as usize].map(|v| a * layout.row(i / pixels_per_item, v));
        let (u, v) = (rast[4 * i], rast[4 * i + 1]);
        let bary = [u, v, 1.0 - u - v];
        for j in 0..a {
            let up = dy[i * a + j];
            for k in 0..3 {
                g.attr[rows[k] + j] += bary[k] * up;
            }
            g.rast[4 * i] += up * (attr[rows[0] + j] - attr[rows[2] + j]);
            g.rast[4 * i + 1] += up * (attr[rows[1] + j] - attr[rows[2] + j]);
        }
        let (Some(db), Some(dda)) = (rast_db, dda) else {
            continue;
        };
        let d = &db[4 * i..4 * i + 4];
        for (n, &j) in diff.iter().enumerate() {
            let j = j as usize;
            let o = i * 2 * diff.len() + 2 * n;
            let (gx, gy) = (dda[o], dda[o + 1]);
            // ∂a/∂X = du/dX (a0 − a2) + dv/dX (a1 − a2), likewise Y.
            let gdu = gx * d[0] + gy * d[1];
            let gdv = gx * d[2] + gy * d[3];
            g.attr[rows[0] + j] += gdu;
            g.attr[rows[1] + j] += gdv;
            g.attr[rows[2] + j] -= gdu + gdv;
            let du = attr[rows[0] + j] - attr[rows[2] + j];
            let dv = attr[rows[1] + j] - attr[rows[2] + j];
            g.rast_db[4 * i] += gx * du;
            g.rast_db[4 * i + 1] += gy * du;
            g.rast_db[4 * i + 2] += gx * dv;
            g.rast_db[4 * i + 3] += gy * dv;
        }
    }
    g
}

#[cfg(test)]
mod tests {
    use super::super::Topology;
    use super::*;

    fn shape(width: u32, height: u32, vertex_count: u32, triangle_count: u32) -> Shape {
        Shape {
            width,
            height,
            vertex_count,
            triangle_count,
            topology: Topology::Instanced { batch: 1 },
        }
    }

    /// An n×n grid of quads over `[-s, s]²` at depth `z`, each split along a diagonal that
    /// alternates, as clip-space vertices with w = 1.
    fn grid(n: u32, s: f64, z: f64) -> (Vec<f64>, Vec<[u32; 3]>) {
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let x = -s + 2.0 * s * f64::from(i) / f64::from(n);
                let y = -s + 2.0 * s * f64::from(j) / f64::from(n);
                pos.extend([x, y, z, 1.0]);
            }
        }
        let mut tri = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let v = |di: u32, dj: u32| (j + dj) * (n + 1) + i + di;
                if (i + j) % 2 == 0 {
                    tri.push([v(0, 0), v(1, 0), v(1, 1)]);
                    tri.push([v(0, 0), v(1, 1), v(0, 1)]);
                } else {
                    tri.push([v(0, 0), v(1, 0), v(0, 1)]);
                    tri.push([v(1, 0), v(1, 1), v(0, 1)]);
                }
            }
        }
        (pos, tri)
    }

    fn clip(pos: &[f64], t: [u32; 3]) -> [Clip; 3] {
        t.map(|v| {
            let o = 4 * v as usize;
            [pos[o], pos[o + 1], pos[o + 2], pos[o + 3]]
        })
    }

    #[test]
    fn edges_through_pixel_centres_draw_each_centre_once() {
        // 8×8 image, grid vertices on pixel centres: every inner edge passes through centres,
        // so only the fill rule decides them. Each centre inside the grid's square must be
        // covered by exactly one triangle (counted by brute force over all triangles).
        let (w, h) = (8, 8);
        // Pixel centres at NDC (2x + 1)/8 − 1: x = 1 → −0.625, x = 6 → 0.625.
        let (pos, tri) = grid(5, 0.625, 0.5);
        let drawn: Vec<Snapped> = tri
            .iter()
            .map(|&t| match coverage(clip(&pos, t), w, h) {
                Some(Coverage::Snapped(q)) => q,
                other => panic!("triangle {t:?}: {other:?}"),
            })
            .collect();
        let mut edge_hits = 0;
        for y in 0..h {
            for x in 0..w {
                let s = sample(x, y, w, h);
                let count = drawn.iter().filter(|q| q.covers(s)).count();
                // The square's left and bottom sides (centres x = 1, y = 1) are in, its right
                // and top sides (x = 6, y = 6) out.
                let inside = (1..6).contains(&x) && (1..6).contains(&y);
                assert_eq!(count, usize::from(inside), "pixel ({x}, {y})");
                edge_hits += drawn
                    .iter()
                    .filter(|q| (0..3).any(|k| edge_function(q.p[k], q.p[(k + 1) % 3], s) == 0))
                    .count();
            }
        }
        assert!(
            edge_hits > 30,
            "the grid puts centres on edges ({edge_hits})"
        );
        // The rule on one triangle: its left and bottom edges are in, the third out.
        let one = Snapped::new([[0, 0], [32, 0], [0, 32]], false).unwrap();
        assert!(one.covers([0, 16]), "left edge is in");
        assert!(one.covers([16, 0]), "bottom edge is in");
        assert!(
            !one.covers([16, 16]),
            "the hypotenuse (going up-left) is out"
        );
        // Clockwise, the same triangle covers the same centres.
        let cw = Snapped::new([[0, 0], [0, 32], [32, 0]], false).unwrap();
        assert!(cw.covers([0, 16]) && cw.covers([16, 0]) && !cw.covers([16, 16]));
    }

    /// Sutherland–Hodgman against `w + z ≥ 0` (the near plane), for the test below.
    fn clip_near(tri: &[Clip; 3]) -> Vec<Clip> {
        let d = |v: &Clip| v[3] + v[2];
        let mut out = Vec::new();
        for i in 0..3 {
            let (a, b) = (tri[i], tri[(i + 1) % 3]);
            if d(&a) >= 0.0 {
                out.push(a);
            }
            if (d(&a) >= 0.0) != (d(&b) >= 0.0) {
                let t = d(&a) / (d(&a) - d(&b));
                out.push(std::array::from_fn(|k| a[k] + t * (b[k] - a[k])));
            }
        }
        out
    }

    #[test]
    fn a_triangle_through_the_near_plane_is_drawn_where_its_front_part_projects() {
        // One vertex behind the eye (w < 0): the homogeneous test must draw exactly the centres
        // inside the projection of the part in front of the near plane (clipped here by
        // Sutherland–Hodgman and tested in 2D), away from that polygon's edges.
        let (w, h) = (16, 12);
        let tri = [
            [-0.8, -0.7, 0.2, 1.0],
            [0.9, -0.6, 0.5, 1.2],
            [0.1, 0.9, -2.0, -0.5],
        ];
        assert_eq!(coverage(tri, w, h), Some(Coverage::Homogeneous));
        let poly: Vec<[f64; 2]> = clip_near(&tri)
            .iter()
            .map(|v| [v[0] / v[3], v[1] / v[3]])
            .collect();
        assert_eq!(poly.len(), 4);
        let mut drawn = 0;
        let mut near_edge = 0;
        for y in 0..h {
            for x in 0..w {
                let f = pixel_ndc(x, y, w, h);
                // Signed distances (NDC) to the polygon's edges, any winding.
                let n = poly.len();
                let d: Vec<f64> = (0..n)
                    .map(|k| {
                        let (a, b) = (poly[k], poly[(k + 1) % n]);
                        let e = (b[0] - a[0]) * (f[1] - a[1]) - (b[1] - a[1]) * (f[0] - a[0]);
                        e / (b[0] - a[0]).hypot(b[1] - a[1])
                    })
                    .collect();
                if d.iter().any(|e| e.abs() < 1e-3) {
                    near_edge += 1;
                    continue;
                }
                let inside = d.iter().all(|&e| e > 0.0) || d.iter().all(|&e| e < 0.0);
                assert_eq!(homogeneous_covers(&tri, f), inside, "pixel ({x}, {y})");
                drawn += usize::from(inside);
            }
        }
        assert!(drawn > 20, "{drawn} pixels drawn");
        assert!(near_edge < 5, "{near_edge} pixels near an edge");
    }

    #[test]
    fn a_triangle_beyond_one_plane_is_not_drawn_and_one_past_the_far_plane_is_cut() {
        let behind = [
            [0.0, 0.0, -2.0, -1.0],
            [0.5, 0.0, -2.0, -1.0],
            [0.0, 0.5, -2.0, -1.5],
        ];
        assert_eq!(coverage(behind, 8, 8), None);
        // Depth from −0.5 (left) to 3 (right): only the part with z/w ≤ 1 is drawn.
        let far = [
            [-1.0, -1.0, -0.5, 1.0],
            [1.0, -1.0, 3.0, 1.0],
            [-1.0, 1.0, -0.5, 1.0],
        ];
        assert_eq!(coverage(far, 8, 8), Some(Coverage::Homogeneous));
        for x in 0..8 {
            let f = pixel_ndc(x, 0, 8, 8);
            let z = -0.5 + 3.5 * (f[0] + 1.0) / 2.0;
            assert_eq!(homogeneous_covers(&far, f), z <= 1.0, "column {x}");
        }
    }

    #[test]
    fn equal_depths_go_to_the_later_triangle_and_peeling_returns_both() {
        // Two triangles with the same vertices: the later (id 1) wins, the next layer is id 0,
        // and the layer after that is empty.
        let pos = vec![
            -0.9, -0.9, 0.1, 1.0, 0.9, -0.9, 0.1, 1.0, 0.0, 0.9, 0.1, 1.0,
        ];
        let tri = [[0, 1, 2], [0, 1, 2]];
        let sh = shape(8, 8, 3, 2);
        let first = rasterize(&sh, &pos, &tri, None);
        let centre = 4 * 8 + 4;
        assert_eq!(first.rast[4 * centre + 3], 2.0);
        let second = rasterize(&sh, &pos, &tri, Some(&first.keys));
        assert_eq!(second.rast[4 * centre + 3], 1.0);
        assert_eq!(
            second.rast[4 * centre..4 * centre + 3],
            first.rast[4 * centre..4 * centre + 3]
        );
        let third = rasterize(&sh, &pos, &tri, Some(&second.keys));
        assert!(third.rast.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn shade_duals_match_central_differences() {
        let c: [Clip; 3] = [
            [-0.6, -0.5, 0.1, 1.1],
            [0.7, -0.4, 0.3, 0.9],
            [0.05, 0.8, 0.2, 1.3],
        ];
        let f = [0.1, -0.05];
        let xyw: [[Dual<9>; 3]; 3] = std::array::from_fn(|k| {
            std::array::from_fn(|m| Dual::input(c[k][[0, 1, 3][m]], 3 * k + m))
        });
        let sh = shade(xyw, c.map(|v| v[2]), f, 32, 24);
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        for input in 0..9 {
            let at = |d: f64| {
                let mut q = c;
                q[input / 3][[0, 1, 3][input % 3]] += d;
                let s = shade_f64(&q, f, 32, 24);
                [s.uv[0], s.uv[1], s.db[0], s.db[1], s.db[2], s.db[3]]
            };
            let (p, m) = (at(h), at(-h));
            let duals = [sh.uv[0], sh.uv[1], sh.db[0], sh.db[1], sh.db[2], sh.db[3]];
            for o in 0..6 {
                let fd = (p[o] - m[o]) / (2.0 * h);
                worst = worst.max((fd - duals[o].grad[input]).abs());
            }
        }
        assert!(worst < 1e-7, "worst |dual − central difference| {worst:e}");
    }

    #[test]
    fn interpolate_grad_matches_central_differences() {
        let (pos, tri) = grid(2, 0.8, 0.3);
        let sh = shape(6, 5, 9, tri.len() as u32);
        let layer = rasterize(&sh, &pos, &tri, None);
        let layout = AttrLayout {
            vertex_count: 9,
            attr_count: 2,
            per_item: false,
        };
        let attr: Vec<f64> = (0..18).map(|i| (f64::from(i) * 0.37).sin()).collect();
        let diff = [1u32, 0];
        let pixels = 30;
        let dy: Vec<f64> = (0..pixels * 2).map(|i| (i as f64 * 0.11).cos()).collect();
        let dda: Vec<f64> = (0..pixels * 4).map(|i| (i as f64 * 0.23).sin()).collect();
        let loss = |attr: &[f64], rast: &[f64], db: &[f64]| {
            let (o, da) = interpolate(attr, layout, rast, &tri, pixels, Some(db), &diff);
            o.iter().zip(&dy).map(|(a, b)| a * b).sum::<f64>()
                + da.iter().zip(&dda).map(|(a, b)| a * b).sum::<f64>()
        };
        let g = interpolate_grad(
            &attr,
            layout,
            &layer.rast,
            &tri,
            pixels,
            Some(&layer.rast_db),
            &diff,
            &dy,
            Some(&dda),
        );
        let h = 1e-6;
        let fd = |v: &mut Vec<f64>, i: usize, which: u8| {
            let base = v[i];
            let eval = |d: f64, v: &mut Vec<f64>| {
                v[i] = base + d;
                let r = match which {
                    0 => loss(v, &layer.rast, &layer.rast_db),
                    1 => loss(&attr, v, &layer.rast_db),
                    _ => loss(&attr, &layer.rast, v),
                };
                v[i] = base;
                r
            };
            (eval(h, v) - eval(-h, v)) / (2.0 * h)
        };
        let mut worst: f64 = 0.0;
        let mut a = attr.clone();
        for i in 0..a.len() {
            worst = worst.max((fd(&mut a, i, 0) - g.attr[i]).abs());
        }
        let mut r = layer.rast.clone();
        let mut d = layer.rast_db.clone();
        for i in 0..4 * pixels {
            if i % 4 < 2 {
                worst = worst.max((fd(&mut r, i, 1) - g.rast[i]).abs());
            }
            worst = worst.max((fd(&mut d, i, 2) - g.rast_db[i]).abs());
        }
        assert!(
            worst < 1e-7,
            "worst |analytic − central difference| {worst:e}"
        );
        assert!(g.attr.iter().any(|&v| v != 0.0) && g.rast_db.iter().any(|&v| v != 0.0));
    }
}
