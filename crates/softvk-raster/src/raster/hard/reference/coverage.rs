//! Coverage: which triangles are snapped and which take the homogeneous test, the snapping
//! itself, the exact integer edge functions on the snapped vertices, and where the f32 kernels
//! may decide a pixel otherwise.

use super::super::SUBPIXELS;
use super::Clip;
/// How far from the viewport's centre, in sub-pixel units, a vertex may project and still be
/// snapped (`SNAP_LIMIT` in `kernels/raster/include/hard.glsl`): 2^21, i.e. 2^18 / W viewport
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
