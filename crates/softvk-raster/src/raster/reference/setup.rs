//! The setup pass of the f64 forward, once per face (SoftRas's `forward_soft_rasterize_inv`
//! kernel, `kernels/raster/raster/face_setup.comp` on the GPU): screen vertices, the inverse barycentric
//! matrix with its determinant clamp, facing, and the grown box outside which a face is ignored.

use glam::DVec3;

use crate::camera::Camera;
use crate::lighting::positions_f64;
use crate::mesh::Mesh;
use crate::raster::settings::Dist;

/// SoftRas clamps the barycentric determinant away from 0 to ±1e-10.
pub const MIN_DET: f64 = 1e-10;

/// Absolute padding of the grown bounding boxes, so float rounding in the distance or the
/// barycentrics can never make a touched pixel fall just outside (screen coordinates are O(1),
/// rounding O(1e-16)).
const BBOX_PAD: f64 = 1e-9;

/// Per-face data computed once before the pixel loop (SoftRas `faces_info`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceSetup {
    /// Screen-space vertices `(x_s, y_s, z)`.
    pub v: [[f64; 3]; 3],
    /// Rows of `M_j`, the inverse of `[[x], [y], [1, 1, 1]]` with the determinant clamped to
    /// ±[`MIN_DET`]: `w_k = inv[k] · (x_p, y_p, 1)`.
    pub inv: [[f64; 3]; 3],
    /// Front-facing in screen space (SPEC §1).
    pub front: bool,
    /// All screen coordinates finite. A vertex on the camera plane of a perspective camera has
    /// none; such a face is skipped entirely rather than poisoning pixels with NaN.
    pub finite: bool,
    /// `[x_min, y_min, x_max, y_max]` from [`face_screen_bbox_grown`].
    pub bbox: [f64; 4],
}

/// SPEC §1 facing: front when `(y2 - y0)(x1 - x0) < (y1 - y0)(x2 - x0)` (clockwise on a y-up
/// screen, which is what an outward face towards the camera projects to).
pub fn is_front_facing(v: &[[f64; 3]; 3]) -> bool {
    (v[2][1] - v[0][1]) * (v[1][0] - v[0][0]) < (v[1][1] - v[0][1]) * (v[2][0] - v[0][0])
}

/// The screen determinant of `[[x0, x1, x2], [y0, y1, y2], [1, 1, 1]]`, unclamped.
pub(crate) fn screen_det(v: &[[f64; 3]; 3]) -> f64 {
    v[2][0] * (v[0][1] - v[1][1]) + v[0][0] * (v[1][1] - v[2][1]) + v[1][0] * (v[2][1] - v[0][1])
}

/// SoftRas's clamp: positive determinants to at least `MIN_DET`, others (zero included) to at
/// most `-MIN_DET`.
pub(crate) fn clamp_det(det: f64) -> f64 {
    if det > 0.0 {
        det.max(MIN_DET)
    } else {
        det.min(-MIN_DET)
    }
}

/// Whether the screen determinant is at the level of its own rounding error, so that its sign
/// and size say nothing: `|det| ≤ 4 ε_mach Σ|x_i (y_j − y_k)|`. Such a face (collapsed,
/// collinear, or seen exactly edge-on) has barycentrics that are rounding noise divided by the
/// clamped determinant; they can fall inside [0, 1] anywhere along its supporting line.
pub fn is_numerically_degenerate(v: &[[f64; 3]; 3]) -> bool {
    let terms = (v[2][0] * (v[0][1] - v[1][1])).abs()
        + (v[0][0] * (v[1][1] - v[2][1])).abs()
        + (v[1][0] * (v[2][1] - v[0][1])).abs();
    screen_det(v).abs() <= 4.0 * f64::EPSILON * terms
}

/// Screen-space box `[x_min, y_min, x_max, y_max]` outside which the face is ignored at every
/// pixel, for the given distance function and σ. The GPU binning assigns faces to tiles by it,
/// so it must be conservative; a test checks it on random and adversarial triangles.
///
/// - Euclidean: the vertices' box grown by `√T`. Outside, a face counts only while `d² < T`,
///   i.e. within `√T` of the triangle; inside lies within the triangle, because with a clamped
///   determinant the barycentrics are `s·w` with `s = |det| / MIN_DET ≤ 1`, which keeps their
///   signs.
/// - Hard: the vertices' box (inside means all `w ∈ [0, 1]`, within the triangle as above).
/// - Barycentric: a face counts where `min_k w_k > −√T`. With exact barycentrics that region
///   is the triangle scaled about its centroid by `1 + 3√T` (its corners solve
///   `w_i = w_j = −√T`: `V_k + 3√T (V_k − centroid)`), which reaches farther than `√T` from a
///   large triangle, so the euclidean box would lose pixels (SoftRas's `check_border` does cut
///   them; the SPEC's rule does not, and this follows the SPEC). With a clamped determinant the
///   barycentrics are scaled by `s < 1` and the factor becomes `1 + 3√T / s`.
/// - A [numerically degenerate](is_numerically_degenerate) face gets the infinite box in every
///   mode: its coverage is not bounded by its vertices.
///
/// Every finite box is padded by 1e-9 against rounding.
pub fn face_screen_bbox_grown(v: &[[f64; 3]; 3], dist: Dist, t: f64) -> [f64; 4] {
    if is_numerically_degenerate(v) {
        return [
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::INFINITY,
        ];
    }
    let r = t.sqrt();
    let xs = [v[0][0], v[1][0], v[2][0]];
    let ys = [v[0][1], v[1][1], v[2][1]];
    let min = |a: [f64; 3]| a[0].min(a[1]).min(a[2]);
    let max = |a: [f64; 3]| a[0].max(a[1]).max(a[2]);
    let (x0, y0, x1, y1) = (min(xs), min(ys), max(xs), max(ys));
    match dist {
        Dist::Euclidean => pad([x0 - r, y0 - r, x1 + r, y1 + r]),
        Dist::Hard => pad([x0, y0, x1, y1]),
        Dist::Barycentric => {
            let s = (screen_det(v).abs() / MIN_DET).min(1.0);
            let k = 1.0 + 3.0 * r / s;
            let cx = (xs[0] + xs[1] + xs[2]) / 3.0;
            let cy = (ys[0] + ys[1] + ys[2]) / 3.0;
            pad([
                cx + k * (x0 - cx),
                cy + k * (y0 - cy),
                cx + k * (x1 - cx),
                cy + k * (y1 - cy),
            ])
        }
    }
}

fn pad(b: [f64; 4]) -> [f64; 4] {
    [
        b[0] - BBOX_PAD,
        b[1] - BBOX_PAD,
        b[2] + BBOX_PAD,
        b[3] + BBOX_PAD,
    ]
}

/// Whether a pixel centre lies outside a face's box (SoftRas `check_border`, strict).
pub fn outside_bbox(bbox: &[f64; 4], xp: f64, yp: f64) -> bool {
    xp < bbox[0] || yp < bbox[1] || xp > bbox[2] || yp > bbox[3]
}

/// The setup pass for one face, from its screen-space vertices.
pub fn setup_face(v: [[f64; 3]; 3], dist: Dist, t: f64) -> FaceSetup {
    let [p0, p1, p2] = v;
    let adj = [
        [p1[1] - p2[1], p2[0] - p1[0], p1[0] * p2[1] - p2[0] * p1[1]],
        [p2[1] - p0[1], p0[0] - p2[0], p2[0] * p0[1] - p0[0] * p2[1]],
        [p0[1] - p1[1], p1[0] - p0[0], p0[0] * p1[1] - p1[0] * p0[1]],
    ];
    let det = clamp_det(screen_det(&v));
    FaceSetup {
        v,
        inv: adj.map(|row| row.map(|a| a / det)),
        front: is_front_facing(&v),
        finite: v.iter().flatten().all(|c| c.is_finite()),
        bbox: face_screen_bbox_grown(&v, dist, t),
    }
}

/// Screen-space vertices of every face.
pub fn project_faces(mesh: &Mesh, camera: &Camera) -> Vec<[[f64; 3]; 3]> {
    project_faces_of(&positions_f64(mesh), &mesh.faces, camera)
}

/// [`project_faces`] of f64 positions.
pub fn project_faces_of(
    positions: &[DVec3],
    faces: &[[u32; 3]],
    camera: &Camera,
) -> Vec<[[f64; 3]; 3]> {
    let screen: Vec<[f64; 3]> = positions.iter().map(|&p| camera.to_screen(p)).collect();
    faces
        .iter()
        .map(|f| f.map(|i| screen[i as usize]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::coverage::{barycentric, coverage};
    use super::super::tests::Rng;
    use super::*;
    use crate::camera::pixel_center;
    use crate::raster::settings::{DIST_EPS, cutoff};

    #[test]
    fn outward_faces_towards_the_camera_are_front_facing() {
        let mesh = Mesh::icosphere(1);
        let cam = Camera::default();
        let normals = crate::lighting::face_normals(&mesh);
        for (f, v) in project_faces(&mesh, &cam).iter().enumerate() {
            let c: DVec3 = mesh.faces[f]
                .iter()
                .map(|&i| DVec3::from(mesh.positions[i as usize].map(f64::from)))
                .sum::<DVec3>()
                / 3.0;
            let towards = normals[f].dot(cam.eye - c);
            if towards.abs() > 1e-3 {
                assert_eq!(is_front_facing(v), towards > 0.0, "face {f}");
            }
        }
    }

    fn random_triangle(rng: &mut Rng) -> [[f64; 3]; 3] {
        let mut v: [[f64; 3]; 3] =
            std::array::from_fn(|_| [rng.range(-1.3, 1.3), rng.range(-1.3, 1.3), 2.0]);
        match (rng.next_f64() * 7.0) as u32 {
            // Sliver: the third vertex close to the first edge.
            0 => {
                let t = rng.range(-0.5, 1.5);
                let e = rng.range(-1e-4, 1e-4);
                v[2][0] = v[0][0] + t * (v[1][0] - v[0][0]);
                v[2][1] = v[0][1] + t * (v[1][1] - v[0][1]) + e;
            }
            // Near-degenerate: determinant around the clamp.
            1 => {
                let t = rng.range(0.2, 0.8);
                v[2][0] = v[0][0] + t * (v[1][0] - v[0][0]) + rng.range(-1e-10, 1e-10);
                v[2][1] = v[0][1] + t * (v[1][1] - v[0][1]);
            }
            // All three vertices on one row of pixel centres: exactly collinear.
            3 => {
                let row = (rng.next_f64() * 40.0) as u32;
                let y = pixel_center(0, row, 48, 40).1;
                for p in &mut v {
                    p[1] = y;
                }
            }
            // Small triangle.
            2 => {
                let base = v[0];
                for p in &mut v[1..] {
                    p[0] = base[0] + rng.range(-0.05, 0.05);
                    p[1] = base[1] + rng.range(-0.05, 0.05);
                }
            }
            _ => {}
        }
        v
    }

    /// Every (face, pixel) pair that is not ignored lies in the face's grown box, for every
    /// distance function, on random (also sliver and near-degenerate) triangles. Coverage is
    /// evaluated here without any box, so the test is independent of the cull.
    #[test]
    fn grown_bbox_contains_every_touched_pixel() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let (w, h) = (48u32, 40u32);
        // Adversarial slivers lying on a row (y = 0.025) or column (x = 1/40) of pixel centres,
        // with heights around and below the determinant clamp, and a point on a pixel centre.
        let mut special = Vec::new();
        for height in [0.0, 1e-13, 2e-12, 5e-11, 1e-9, 1e-6] {
            let y = 0.025;
            special.push([[-0.5, y, 2.0], [0.5, y, 2.0], [0.1, y + height, 2.0]]);
            let x = 0.025;
            special.push([[x, -0.5, 2.0], [x + height, 0.2, 2.0], [x, 0.5, 2.0]]);
        }
        special.push([[0.025, 0.025, 2.0]; 3]);
        let mut touched_outside_plain_bbox = [0usize; 3];
        for (di, dist) in [Dist::Euclidean, Dist::Barycentric, Dist::Hard]
            .into_iter()
            .enumerate()
        {
            for sigma in [1e-5, 1e-3, 2e-2, 1e-1] {
                let t = cutoff(sigma, DIST_EPS);
                let random = (0..60).map(|_| random_triangle(&mut rng));
                for v in special.clone().into_iter().chain(random) {
                    let face = setup_face(v, dist, t);
                    let plain = face_screen_bbox_grown(&v, Dist::Hard, t);
                    for row in 0..h {
                        for col in 0..w {
                            let (xp, yp) = pixel_center(col, row, w, h);
                            let wb = barycentric(&face, xp, yp);
                            if coverage(&face, &wb, xp, yp, dist, sigma, t).is_none() {
                                continue;
                            }
                            assert!(
                                !outside_bbox(&face.bbox, xp, yp),
                                "{dist:?} σ={sigma} {v:?}: pixel ({xp}, {yp}) outside {:?}",
                                face.bbox
                            );
                            if outside_bbox(&plain, xp, yp) {
                                touched_outside_plain_bbox[di] += 1;
                            }
                        }
                    }
                }
            }
        }
        // The growth matters: soft faces do reach past their vertices' box.
        assert!(touched_outside_plain_bbox[0] > 0 && touched_outside_plain_bbox[1] > 0);
        assert_eq!(touched_outside_plain_bbox[2], 0);
    }

    /// The barycentric distance reaches further than √T from a large triangle, so the euclidean
    /// growth would lose pixels there (SoftRas's √T border test does exactly that).
    #[test]
    fn barycentric_reach_exceeds_sqrt_t_for_large_triangles() {
        let v = [[-1.0, -1.0, 2.0], [1.0, -1.0, 2.0], [0.0, 1.0, 2.0]];
        let sigma = 1e-2;
        let t = cutoff(sigma, DIST_EPS);
        let face = setup_face(v, Dist::Barycentric, t);
        let euclid = face_screen_bbox_grown(&v, Dist::Euclidean, t);
        // Just below the bottom edge, beyond √T, but within the scaled triangle.
        let (xp, yp) = (0.0, -1.0 - 1.5 * t.sqrt());
        let w = barycentric(&face, xp, yp);
        assert!(coverage(&face, &w, xp, yp, Dist::Barycentric, sigma, t).is_some());
        assert!(outside_bbox(&euclid, xp, yp));
        assert!(!outside_bbox(&face.bbox, xp, yp));
    }

    #[test]
    fn coincident_vertices_cover_everything_in_barycentric_and_hard_modes() {
        let v = [[0.2, 0.2, 2.0]; 3];
        assert!(is_numerically_degenerate(&v));
        for dist in [Dist::Barycentric, Dist::Hard] {
            let face = setup_face(v, dist, cutoff(1e-4, DIST_EPS));
            let w = barycentric(&face, -0.9, 0.9);
            assert!(coverage(&face, &w, -0.9, 0.9, dist, 1e-4, cutoff(1e-4, DIST_EPS)).is_some());
        }
        for dist in [Dist::Euclidean, Dist::Barycentric, Dist::Hard] {
            let b = setup_face(v, dist, cutoff(1e-4, DIST_EPS)).bbox;
            assert!(b[0] == f64::NEG_INFINITY && b[3] == f64::INFINITY);
        }
        // A thin but well-conditioned sliver keeps a finite box.
        let sliver = [
            [-0.5, 0.025, 2.0],
            [0.5, 0.025, 2.0],
            [0.1, 0.025 + 1e-13, 2.0],
        ];
        assert!(!is_numerically_degenerate(&sliver));
        assert!(
            face_screen_bbox_grown(&sliver, Dist::Barycentric, cutoff(1e-4, DIST_EPS))[2]
                .is_finite()
        );
    }
}
