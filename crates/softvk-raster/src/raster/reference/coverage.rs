//! One face at one pixel, the steps of the fine pass's inner loop: barycentrics, the distance
//! and the coverage `D` it gives, the clipped barycentrics `w̃` and the perspective-correct
//! depth they interpolate.

use super::setup::FaceSetup;
use crate::raster::settings::Dist;

/// Floor of the clipped barycentric sum before renormalization.
pub const CLIP_SUM_FLOOR: f64 = 1e-5;

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// `w = M_j (x_p, y_p, 1)`.
pub fn barycentric(face: &FaceSetup, xp: f64, yp: f64) -> [f64; 3] {
    face.inv.map(|row| row[0] * xp + row[1] * yp + row[2])
}

/// Strictly inside: the sign δ of the euclidean distance (SoftRas's test).
fn strictly_inside(w: &[f64; 3]) -> bool {
    w.iter().all(|&x| x > 0.0 && x < 1.0)
}

/// Inside with the edges (SoftRas `check_pixel_inside`): hard coverage and hard colour.
pub fn inside_closed(w: &[f64; 3]) -> bool {
    w.iter().all(|&x| (0.0..=1.0).contains(&x))
}

/// Squared distance from `p` to the segment `a b` (a degenerate segment is its point).
pub fn dist2_point_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
    let len2 = ex * ex + ey * ey;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (dx, dy) = (a[0] + t * ex - p[0], a[1] + t * ey - p[1]);
    dx * dx + dy * dy
}

/// Squared euclidean distance from the pixel centre to the triangle's boundary: the nearest of
/// the three edges taken as segments (SPEC; SoftRas's closed form differs for some obtuse
/// configurations).
pub fn euclidean_dist2(v: &[[f64; 3]; 3], xp: f64, yp: f64) -> f64 {
    let p = [xp, yp];
    let q = |k: usize| [v[k][0], v[k][1]];
    dist2_point_segment(p, q(0), q(1))
        .min(dist2_point_segment(p, q(1), q(2)))
        .min(dist2_point_segment(p, q(2), q(0)))
}

/// Coverage `D` of a face at a pixel, or `None` when the face is ignored there (outside and
/// beyond the cut-off `t` = [`cutoff`](crate::raster::settings::cutoff)`(σ)`).
pub fn coverage(
    face: &FaceSetup,
    w: &[f64; 3],
    xp: f64,
    yp: f64,
    dist: Dist,
    sigma: f64,
    t: f64,
) -> Option<f64> {
    match dist {
        Dist::Hard => inside_closed(w).then_some(1.0),
        Dist::Barycentric => {
            let m = w[0].min(w[1]).min(w[2]);
            let signed = m * m.abs();
            (-signed < t).then(|| sigmoid(signed / sigma))
        }
        Dist::Euclidean => {
            let d2 = euclidean_dist2(&face.v, xp, yp);
            if strictly_inside(w) {
                Some(sigmoid(d2 / sigma))
            } else {
                (d2 < t).then(|| sigmoid(-d2 / sigma))
            }
        }
    }
}

/// `w̃`: w clamped to [0, 1] and renormalized, the sum floored at [`CLIP_SUM_FLOOR`].
pub fn clip_barycentric(w: [f64; 3]) -> [f64; 3] {
    let c = w.map(|x| x.clamp(0.0, 1.0));
    let sum = (c[0] + c[1] + c[2]).max(CLIP_SUM_FLOOR);
    c.map(|x| x / sum)
}

/// Perspective-correct depth `z = 1 / Σ_k (w̃_k / z_k)`.
pub fn depth(face: &FaceSetup, w_clip: &[f64; 3]) -> f64 {
    1.0 / (w_clip[0] / face.v[0][2] + w_clip[1] / face.v[1][2] + w_clip[2] / face.v[2][2])
}

#[cfg(test)]
mod tests {
    use super::super::setup::setup_face;
    use super::*;
    use crate::raster::settings::{DIST_EPS, cutoff};

    #[test]
    fn euclidean_distance_is_to_edges_as_segments() {
        // Obtuse triangle; a point beyond the obtuse vertex is nearest to that vertex.
        let v = [[0.0, 0.0, 1.0], [4.0, 0.0, 1.0], [2.0, 0.5, 1.0]];
        assert!((euclidean_dist2(&v, 2.0, 1.5) - 1.0).abs() < 1e-12);
        // Beyond an end of the long edge: distance to the vertex, not to the edge's line.
        assert!((euclidean_dist2(&v, -3.0, -4.0) - 25.0).abs() < 1e-12);
        // Inside: distance to the nearest edge.
        let d = euclidean_dist2(&v, 2.0, 0.1);
        assert!((d - 0.01).abs() < 1e-12);
    }

    #[test]
    fn coverage_is_half_on_the_edge_and_ignored_past_the_cutoff() {
        let v = [[-0.5, -0.5, 2.0], [0.5, -0.5, 2.0], [0.0, 0.5, 2.0]];
        let sigma = 1e-3;
        let t = cutoff(sigma, DIST_EPS);
        let face = setup_face(v, Dist::Euclidean, t);
        assert!((t - 9.2102403669758 * sigma).abs() < 1e-12);
        let at =
            |x: f64, y: f64, dist| coverage(&face, &barycentric(&face, x, y), x, y, dist, sigma, t);
        assert!((at(0.0, -0.5, Dist::Euclidean).unwrap() - 0.5).abs() < 1e-9);
        let r = t.sqrt();
        assert!(at(0.0, -0.5 - 0.999 * r, Dist::Euclidean).is_some());
        assert!(at(0.0, -0.5 - 1.001 * r, Dist::Euclidean).is_none());
        // Just inside the cut-off the coverage is ε_d.
        let d = at(0.0, -0.5 - 0.999_999 * r, Dist::Euclidean).unwrap();
        assert!((d - DIST_EPS).abs() < 1e-8, "{d}");
        assert!(at(0.0, 0.0, Dist::Euclidean).unwrap() > 0.5);
        assert_eq!(at(0.0, 0.0, Dist::Hard), Some(1.0));
        assert_eq!(at(0.0, -0.51, Dist::Hard), None);
        assert!(at(0.0, 0.0, Dist::Barycentric).unwrap() > 0.5);
    }
}
