//! CPU twins of sphere probing: the discrete decisions in the kernels' f32 operations, the
//! values in f64.

use super::{Constants, FLAG_INSIDE, FLAG_VALID, ProbeItem};
use crate::primitives::binning::TileGrid;
use crate::probe::sampler::Ray;
use crate::probe::targets::{ProbeView, Targets};
use crate::probe::{Aggregate, ProbeSettings};

type V3 = [f32; 3];

fn affine(a: &[f32; 4], p: V3) -> f32 {
    a[0] * p[0] + a[1] * p[1] + a[2] * p[2] + a[3]
}

/// `sphere_extent` of `probe_items.comp`, rounding for rounding: the extent `[lo, hi]` of the
/// screen coordinate `affine(a, p) / affine(a2, p)` over the sphere of radius `tau` around
/// `c`; `None` where the sphere reaches the plane `affine(a2, p) = 0` (or rounding leaves no
/// real roots).
pub fn sphere_extent(a: &[f32; 4], a2: &[f32; 4], c: V3, tau: f32) -> Option<(f32, f32)> {
    let big_a = affine(a, c);
    let big_b = affine(a2, c);
    let (u, w) = ([a[0], a[1], a[2]], [a2[0], a2[1], a2[2]]);
    let tau2 = tau * tau;
    let qa = big_b * big_b - tau2 * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    let qb = big_a * big_b - tau2 * (u[0] * w[0] + u[1] * w[1] + u[2] * w[2]);
    let v = [0, 1, 2].map(|i| big_a * w[i] - big_b * u[i]);
    let x = [
        u[1] * w[2] - u[2] * w[1],
        u[2] * w[0] - u[0] * w[2],
        u[0] * w[1] - u[1] * w[0],
    ];
    let disc = tau2
        * ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
            - tau2 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]));
    if !(qa > 0.0 && disc >= 0.0) {
        return None;
    }
    let r = disc.sqrt();
    Some(((qb - r) / qa, (qb + r) / qa))
}

/// `probe_items.comp`.
pub fn items(targets: &Targets, tau: f64, anchors: &[[f32; 4]]) -> Vec<ProbeItem> {
    let tau = tau as f32;
    let (w, h) = (targets.width as f32, targets.height as f32);
    let smin = w.min(h);
    let mut out = Vec::with_capacity(anchors.len() * targets.views.len());
    for (k, v) in targets.views.iter().enumerate() {
        for a in anchors {
            let p = [a[0], a[1], a[2]];
            let mut valid = true;
            let mut b = [1e30f32, 1e30, -1e30, -1e30];
            for c in 0..8u32 {
                let sign = |bit: u32| if c & bit != 0 { 1.0f32 } else { -1.0 };
                let corner = [
                    p[0] + tau * sign(1),
                    p[1] + tau * sign(2),
                    p[2] + tau * sign(4),
                ];
                let den = affine(&v.a2, corner);
                valid = valid && affine(&v.depth, corner) > 0.0 && den > 0.0;
                let (sx, sy) = (affine(&v.a0, corner) / den, affine(&v.a1, corner) / den);
                b = [b[0].min(sx), b[1].min(sy), b[2].max(sx), b[3].max(sy)];
            }
            if let (Some(ex), Some(ey)) = (
                sphere_extent(&v.a0, &v.a2, p, tau),
                sphere_extent(&v.a1, &v.a2, p, tau),
            ) {
                b = [
                    b[0].max(ex.0),
                    b[1].max(ey.0),
                    b[2].min(ex.1),
                    b[3].min(ey.1),
                ];
            }
            let den = affine(&v.a2, p);
            let sx = affine(&v.a0, p) / den;
            let sy = affine(&v.a1, p) / den;
            let fc = ((sx * smin + w) * 0.5).floor();
            let fr = ((h - sy * smin) * 0.5).floor();
            let inside = den > 0.0
                && fc >= 0.0
                && fc < w
                && fr >= 0.0
                && fr < h
                && targets.inside(k, fc as i64, fr as i64);
            out.push(ProbeItem {
                screen_box: b,
                flags: (u32::from(valid) * FLAG_VALID) | (u32::from(inside) * FLAG_INSIDE),
                sx,
                sy,
                depth: affine(&v.depth, p),
            });
        }
    }
    out
}

/// The line of a ray: `pixel_to_screen` and `view_ray` of `probe.glsl`.
pub fn ray_line(view: &ProbeView, ray: &Ray, width: u32, height: u32, inv_s: f32) -> (V3, V3) {
    let sx = (2.0 * ray.px - width as f32) * inv_s;
    let sy = (height as f32 - 2.0 * ray.py) * inv_s;
    let f =
        |a: &[f32; 4], b: &[f32; 4], c: &[f32; 4]| [0, 1, 2].map(|i| a[i] + sx * b[i] + sy * c[i]);
    (
        f(&view.o0, &view.ox, &view.oy),
        f(&view.d0, &view.dx, &view.dy),
    )
}

/// `hit_bound` of `probe.glsl`: τ² |d|².
pub fn hit_bound(d: V3, tau2: f32) -> f32 {
    tau2 * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
}

/// `ray_hits` of `probe.glsl`: |(p − o) × d|² < τ² |d|².
pub fn ray_hits(o: V3, d: V3, bound: f32, p: V3) -> bool {
    let v = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
    let cx = v[1] * d[2] - v[2] * d[1];
    let cy = v[2] * d[0] - v[0] * d[2];
    let cz = v[0] * d[1] - v[1] * d[0];
    cx * cx + cy * cy + cz * cz < bound
}

/// `ray_tile` of `probe.glsl`.
pub fn ray_tile(ray: &Ray, grid: &TileGrid) -> u32 {
    let col = (ray.px as u32).min(grid.width - 1);
    let row = (ray.py as u32).min(grid.height - 1);
    ray.view * grid.tiles_x * grid.tiles_y
        + (row / grid.tile_size) * grid.tiles_x
        + col / grid.tile_size
}

/// The anchors each ray uses, in anchor order: valid in its view, assigned to it (when
/// boundary-aware) and within τ of its line.
pub fn hits(
    targets: &Targets,
    settings: &ProbeSettings,
    anchors: &[[f32; 4]],
    rays: &[Ray],
) -> Vec<Vec<u32>> {
    let c = Constants::new(settings, targets.width, targets.height);
    let items = items(targets, f64::from(c.tau), anchors);
    let n = anchors.len();
    rays.iter()
        .map(|r| {
            let view = &targets.views[r.view as usize];
            let (o, d) = ray_line(view, r, targets.width, targets.height, c.inv_s);
            let bound = hit_bound(d, c.ray_tau2(r.label));
            (0..n)
                .filter(|&j| {
                    let flags = items[r.view as usize * n + j].flags;
                    let assigned =
                        !settings.boundary_aware || (r.label >= 0.5) == (flags & FLAG_INSIDE != 0);
                    flags & FLAG_VALID != 0
                        && assigned
                        && ray_hits(o, d, bound, [anchors[j][0], anchors[j][1], anchors[j][2]])
                })
                .map(|j| j as u32)
                .collect()
        })
        .collect()
}

/// ψ of a ray with `hits` and dψ/dφ of each hit (zero without hits).
pub fn aggregate(settings: &ProbeSettings, hits: &[u32], phi: &[f64]) -> (f64, Vec<f64>) {
    if hits.is_empty() {
        return (0.0, Vec::new());
    }
    let values: Vec<f64> = hits.iter().map(|&j| phi[j as usize]).collect();
    match settings.aggregate {
        Aggregate::Max => {
            let mut best = 0;
            for (i, &v) in values.iter().enumerate() {
                if v > values[best] {
                    best = i;
                }
            }
            let mut g = vec![0.0; values.len()];
            g[best] = 1.0;
            (values[best], g)
        }
        Aggregate::LogSumExp => {
            let t = settings.temperature;
            let m = values.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(v));
            let s: f64 = values.iter().map(|&v| ((v - m) / t).exp()).sum();
            let psi = m + t * s.ln();
            (psi, values.iter().map(|&v| ((v - psi) / t).exp()).collect())
        }
        Aggregate::Union => {
            let prod: f64 = values.iter().map(|&v| 1.0 - v).product();
            let g = (0..values.len())
                .map(|i| {
                    values
                        .iter()
                        .enumerate()
                        .filter(|&(k, _)| k != i)
                        .map(|(_, &v)| 1.0 - v)
                        .product()
                })
                .collect();
            (1.0 - prod, g)
        }
    }
}

/// The forward's result.
#[derive(Clone, Debug, PartialEq)]
pub struct Forward {
    /// The anchors each ray used, in order.
    pub hits: Vec<Vec<u32>>,
    /// ψ per ray.
    pub psi: Vec<f64>,
    /// L_sil.
    pub loss: f64,
}

/// L_sil of fixed hits: `mean (ψ − S)²`.
pub fn loss(settings: &ProbeSettings, hits: &[Vec<u32>], phi: &[f64], rays: &[Ray]) -> f64 {
    let sum: f64 = hits
        .iter()
        .zip(rays)
        .map(|(h, r)| {
            let e = aggregate(settings, h, phi).0 - f64::from(r.label);
            e * e
        })
        .sum();
    sum / rays.len() as f64
}

/// The forward: hits, ψ, L_sil.
pub fn forward(
    targets: &Targets,
    settings: &ProbeSettings,
    anchors: &[[f32; 4]],
    phi: &[f64],
    rays: &[Ray],
) -> Forward {
    let hits = hits(targets, settings, anchors, rays);
    let psi = hits.iter().map(|h| aggregate(settings, h, phi).0).collect();
    let loss = loss(settings, &hits, phi, rays);
    Forward { hits, psi, loss }
}

/// dL_sil/dφ per anchor: `(2 / N) Σ_i (ψ_i − S_i) dψ_i/dφ_j`.
pub fn backward(
    settings: &ProbeSettings,
    forward: &Forward,
    phi: &[f64],
    rays: &[Ray],
) -> Vec<f64> {
    let mut d = vec![0.0; phi.len()];
    let n = rays.len() as f64;
    for ((h, &psi), r) in forward.hits.iter().zip(&forward.psi).zip(rays) {
        let (_, g) = aggregate(settings, h, phi);
        let e = 2.0 * (psi - f64::from(r.label)) / n;
        for (&j, gj) in h.iter().zip(g) {
            d[j as usize] += e * gj;
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aggregates_match_their_definitions() {
        let phi = [0.2, 0.9, 0.5, 0.7];
        let hits = [0, 2, 3];
        let s = |aggregate| ProbeSettings {
            aggregate,
            temperature: 0.1,
            ..ProbeSettings::default()
        };
        let (psi, g) = aggregate(&s(Aggregate::Max), &hits, &phi);
        assert_eq!((psi, g), (0.7, vec![0.0, 0.0, 1.0]));
        let (psi, g) = aggregate(&s(Aggregate::LogSumExp), &hits, &phi);
        let want = 0.1 * (2f64.exp() + 5f64.exp() + 7f64.exp()).ln();
        assert!((psi - want).abs() < 1e-12);
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let (psi, g) = aggregate(&s(Aggregate::Union), &hits, &phi);
        assert!((psi - (1.0 - 0.8 * 0.5 * 0.3)).abs() < 1e-12);
        assert!((g[1] - 0.8 * 0.3).abs() < 1e-12);
        assert_eq!(aggregate(&s(Aggregate::Union), &[], &phi).0, 0.0);
    }
}
