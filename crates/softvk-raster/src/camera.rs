//! Cameras and pixel centres (SPEC §1), as SoftRas's `look_at.py`, `perspective.py`,
//! `orthogonal.py`, `projection.py` and `get_points_from_angles.py` define them.
//!
//! Screen space is what the rasterizer works in: `(x_s, y_s)` in [-1, 1] across the shorter
//! image side, y up, and `z` the camera-space depth (not divided), which the depth
//! interpolation and the near/far test use.

use glam::DVec3;

/// `F.normalize(v, eps)`: `v / max(|v|, eps)`. SoftRas normalizes this way, so a degenerate
/// axis becomes the zero vector rather than NaN.
fn normalize_eps(v: DVec3, eps: f64) -> DVec3 {
    v / v.length().max(eps)
}

/// SoftRas `look_at`: rows x, y, z of the world-to-camera rotation, with
/// `z = normalize(at - eye)`, `x = normalize(cross(up, z))`, `y = normalize(cross(z, x))`.
/// Camera coordinates are `R (p - eye)`; the camera looks along +z.
///
/// SoftRas normalizes with eps = 1e-5 (to match the chainer version); kept here so that an `up`
/// parallel to the view direction gives the same (degenerate) camera as SoftRas.
pub fn look_at(eye: DVec3, at: DVec3, up: DVec3) -> [[f64; 3]; 3] {
    let z = normalize_eps(at - eye, 1e-5);
    let x = normalize_eps(up.cross(z), 1e-5);
    let y = normalize_eps(z.cross(x), 1e-5);
    [x.to_array(), y.to_array(), z.to_array()]
}

/// SoftRas `get_points_from_angles` in degrees:
/// `(d cos(el) sin(az), d sin(el), -d cos(el) cos(az))`. Azimuth 0 puts the eye on -z.
pub fn eye_from_angles(distance: f64, elevation_deg: f64, azimuth_deg: f64) -> DVec3 {
    let (el, az) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    DVec3::new(
        distance * el.cos() * az.sin(),
        distance * el.sin(),
        -distance * el.cos() * az.cos(),
    )
}

/// How camera (or, for `Matrix`, world) points reach screen space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// SoftRas `perspective`: `x_s = x / (z tan a)`, `y_s = y / (z tan a)` with `a` the viewing
    /// angle in degrees (SoftRas uses the full angle here, not half; default 30°).
    Perspective {
        /// The viewing angle `a`, degrees.
        viewing_angle_deg: f64,
    },
    /// SoftRas `orthogonal`: `x_s = s x`, `y_s = s y`.
    Orthographic {
        /// The scale `s`.
        scale: f64,
    },
    /// SoftRas `projection` (camera_mode 'projection'): a 3×4 matrix `P = K [R | t]` applied to
    /// *world* points (the camera's eye/at/up are not used: P carries the extrinsics), Brown
    /// distortion, then pixels mapped to [-1, 1] by `orig_size`.
    Matrix {
        /// The 3×4 projection matrix, rows.
        p: [[f64; 4]; 3],
        /// Brown distortion `[k1, k2, p1, p2, k3]`, applied to the pixel coordinates.
        dist_coeffs: [f64; 5],
        /// Size in pixels of the image P projects to.
        orig_size: f64,
    },
}

impl Default for Projection {
    fn default() -> Self {
        Projection::Perspective {
            viewing_angle_deg: 30.0,
        }
    }
}

impl Projection {
    /// SoftRas `projection`: `x' = x / (z + 1e-5)`, `r = |(x', y')|`,
    /// `x'' = x'(1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x' y' + p2 (r² + 2 x'²)`,
    /// `y'' = y'(1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y'²) + 2 p2 x' y'`, then
    /// `2 (x'' - orig/2) / orig` for both axes; depth is P's third row, undivided.
    ///
    /// Like SoftRas, y is not flipped: pixel row v grows with `y_s`, so with the rasterizer's
    /// row 0 at the top the picture comes out upside down relative to the photo P describes.
    fn project_matrix(p: &[[f64; 4]; 3], dist: &[f64; 5], orig_size: f64, w: DVec3) -> [f64; 3] {
        let row = |r: &[f64; 4]| r[0] * w.x + r[1] * w.y + r[2] * w.z + r[3];
        let (x, y, z) = (row(&p[0]), row(&p[1]), row(&p[2]));
        let x1 = x / (z + 1e-5);
        let y1 = y / (z + 1e-5);
        let [k1, k2, p1, p2, k3] = *dist;
        let r2 = x1 * x1 + y1 * y1;
        let radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
        let x2 = x1 * radial + 2.0 * p1 * x1 * y1 + p2 * (r2 + 2.0 * x1 * x1);
        let y2 = y1 * radial + p1 * (r2 + 2.0 * y1 * y1) + 2.0 * p2 * x1 * y1;
        let half = orig_size / 2.0;
        [(x2 - half) / half, (y2 - half) / half, z]
    }
}

/// A view: SoftRas `look_at` placement plus a projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Camera position (world).
    pub eye: DVec3,
    /// Point looked at (SoftRas: origin).
    pub at: DVec3,
    /// Up hint (SoftRas: +y).
    pub up: DVec3,
    /// Projection to screen space.
    pub projection: Projection,
}

impl Default for Camera {
    /// SoftRas's default view: distance 2.732 (= 1/tan 30° + 1), elevation 0, azimuth 0,
    /// looking at the origin with +y up, perspective 30°.
    fn default() -> Self {
        Camera::from_angles(2.732, 0.0, 0.0)
    }
}

impl Camera {
    /// Perspective 30° camera at [`eye_from_angles`], looking at the origin with +y up.
    pub fn from_angles(distance: f64, elevation_deg: f64, azimuth_deg: f64) -> Camera {
        Camera {
            eye: eye_from_angles(distance, elevation_deg, azimuth_deg),
            at: DVec3::ZERO,
            up: DVec3::Y,
            projection: Projection::default(),
        }
    }

    /// The camera of points already in screen space `(x_s, y_s, depth)`, as SoftRas's
    /// `SoftRasterizer` takes its `face_vertices`: at the origin, looking along +z with +y up,
    /// orthographic with scale 1. Its look-at rows are the unit axes exactly, so
    /// [`Camera::to_screen`] is the identity, in the f32 face setup as in f64, and the backward's
    /// chain to world positions passes screen gradients through unchanged.
    pub fn screen_space() -> Camera {
        Camera {
            eye: DVec3::ZERO,
            at: DVec3::Z,
            up: DVec3::Y,
            projection: Projection::Orthographic { scale: 1.0 },
        }
    }

    /// `R (p - eye)` with R from [`look_at`].
    pub fn to_camera(&self, p_world: DVec3) -> DVec3 {
        let r = look_at(self.eye, self.at, self.up);
        let d = p_world - self.eye;
        DVec3::new(
            DVec3::from(r[0]).dot(d),
            DVec3::from(r[1]).dot(d),
            DVec3::from(r[2]).dot(d),
        )
    }

    /// Screen-space `(x_s, y_s, z)` of a world point.
    pub fn to_screen(&self, p_world: DVec3) -> [f64; 3] {
        match &self.projection {
            Projection::Perspective { viewing_angle_deg } => {
                let c = self.to_camera(p_world);
                let width = viewing_angle_deg.to_radians().tan();
                [c.x / c.z / width, c.y / c.z / width, c.z]
            }
            Projection::Orthographic { scale } => {
                let c = self.to_camera(p_world);
                [c.x * scale, c.y * scale, c.z]
            }
            Projection::Matrix {
                p,
                dist_coeffs,
                orig_size,
            } => Projection::project_matrix(p, dist_coeffs, *orig_size, p_world),
        }
    }
}

/// Screen position of the centre of pixel (`col`, `row`), row 0 at the top (SPEC §1):
/// `x_p = (2c + 1 - W) / S`, `y_p = (2(H - 1 - r) + 1 - H) / S` with `S = min(W, H)`.
///
/// For W = H this is exactly SoftRas; for other shapes the shorter side spans [-1, 1] and the
/// longer one sees more of the scene, so the projection's field of view is the shorter side's.
pub fn pixel_center(col: u32, row: u32, width: u32, height: u32) -> (f64, f64) {
    let (w, h) = (f64::from(width), f64::from(height));
    let s = w.min(h);
    let x = (2.0 * f64::from(col) + 1.0 - w) / s;
    let y = (2.0 * (h - 1.0 - f64::from(row)) + 1.0 - h) / s;
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The screen-space camera maps every point to itself, bit for bit (what lets SoftRas's
    /// already-projected `face_vertices` go through the ordinary face setup).
    #[test]
    fn the_screen_space_camera_is_the_identity_exactly() {
        let camera = Camera::screen_space();
        assert_eq!(
            look_at(camera.eye, camera.at, camera.up),
            [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        );
        for p in [
            [0.1, -0.7, 2.5],
            [-1e-7, 3.3e5, -4.0],
            [0.3333333333, 0.0, 1e-30],
        ] {
            assert_eq!(camera.to_screen(DVec3::from(p)), p);
        }
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn pixel_centers_of_small_images() {
        assert_eq!(pixel_center(0, 0, 1, 1), (0.0, 0.0));
        // 3 wide, 2 high: S = 2.
        let xs: Vec<f64> = (0..3).map(|c| pixel_center(c, 0, 3, 2).0).collect();
        assert_eq!(xs, vec![-1.0, 0.0, 1.0]);
        assert_eq!(pixel_center(0, 0, 3, 2).1, 0.5);
        assert_eq!(pixel_center(0, 1, 3, 2).1, -0.5);
        // 2 wide, 3 high: S = 2.
        assert_eq!(pixel_center(0, 0, 2, 3), (-0.5, 1.0));
        assert_eq!(pixel_center(1, 1, 2, 3), (0.5, 0.0));
        assert_eq!(pixel_center(1, 2, 2, 3), (0.5, -1.0));
    }

    #[test]
    fn pixel_centers_match_softras_for_square_images() {
        let n = 8;
        for row in 0..n {
            for col in 0..n {
                // SoftRas: yi = is - 1 - row, yp = (2 yi + 1 - is) / is.
                let yi = f64::from(n - 1 - row);
                let expected = (
                    (2.0 * f64::from(col) + 1.0 - f64::from(n)) / f64::from(n),
                    (2.0 * yi + 1.0 - f64::from(n)) / f64::from(n),
                );
                assert_eq!(pixel_center(col, row, n, n), expected);
            }
        }
    }

    #[test]
    fn look_at_rows_are_orthonormal_and_right_handed() {
        let eye = DVec3::new(1.3, -0.7, 2.1);
        let at = DVec3::new(0.2, 0.1, -0.3);
        let r = look_at(eye, at, DVec3::Y).map(DVec3::from);
        for i in 0..3 {
            for j in 0..3 {
                let expected = if i == j { 1.0 } else { 0.0 };
                assert!(close(r[i].dot(r[j]), expected));
            }
        }
        assert!(close(r[0].cross(r[1]).dot(r[2]), 1.0));
        // z points from the eye to the target.
        assert!(close(r[2].dot((at - eye).normalize()), 1.0));
    }

    #[test]
    fn eye_maps_to_the_origin_and_target_to_the_z_axis() {
        let cam = Camera {
            eye: DVec3::new(0.5, 1.5, -2.0),
            at: DVec3::new(0.1, 0.2, 0.3),
            up: DVec3::Y,
            projection: Projection::default(),
        };
        assert!(cam.to_camera(cam.eye).length() < 1e-15);
        let t = cam.to_camera(cam.at);
        assert!(t.x.abs() < 1e-12 && t.y.abs() < 1e-12);
        assert!(close(t.z, (cam.at - cam.eye).length()));
    }

    #[test]
    fn eye_from_angles_matches_softras() {
        let e = eye_from_angles(2.732, 0.0, 0.0);
        assert!(close(e.x, 0.0) && close(e.y, 0.0) && close(e.z, -2.732));
        let e = eye_from_angles(2.0, 90.0, 0.0);
        assert!(close(e.y, 2.0) && e.x.abs() < 1e-12 && e.z.abs() < 1e-12);
        let e = eye_from_angles(2.0, 0.0, 90.0);
        assert!(close(e.x, 2.0) && e.z.abs() < 1e-12);
    }

    #[test]
    fn default_camera_sees_world_axes_as_screen_axes() {
        // Eye on -z looking at +z with +y up: world x is screen right, world y screen up.
        let cam = Camera::default();
        let s = cam.to_screen(DVec3::new(0.3, 0.2, 0.0));
        let k = 1.0 / (2.732 * 30f64.to_radians().tan());
        assert!(close(s[0], 0.3 * k) && close(s[1], 0.2 * k) && close(s[2], 2.732));
    }

    #[test]
    fn orthographic_scales_camera_xy() {
        let cam = Camera {
            projection: Projection::Orthographic { scale: 0.5 },
            ..Camera::default()
        };
        let s = cam.to_screen(DVec3::new(0.4, -0.6, 1.0));
        assert!(close(s[0], 0.2) && close(s[1], -0.3) && close(s[2], 3.732));
    }

    #[test]
    fn matrix_projection_without_distortion_is_pinhole_to_ndc() {
        // K = [[f, 0, c], [0, f, c], [0, 0, 1]], identity extrinsics, image 512 wide.
        let (f, c) = (400.0, 256.0);
        let p = [[f, 0.0, c, 0.0], [0.0, f, c, 0.0], [0.0, 0.0, 1.0, 0.0]];
        let cam = Camera {
            projection: Projection::Matrix {
                p,
                dist_coeffs: [0.0; 5],
                orig_size: 512.0,
            },
            ..Camera::default()
        };
        let w = DVec3::new(0.5, -0.25, 2.0);
        let s = cam.to_screen(w);
        let px = (f * w.x + c * w.z) / (w.z + 1e-5);
        let py = (f * w.y + c * w.z) / (w.z + 1e-5);
        assert!(close(s[0], (px - 256.0) / 256.0) && close(s[1], (py - 256.0) / 256.0));
        assert!(close(s[2], 2.0));
    }

    #[test]
    fn matrix_projection_applies_brown_distortion() {
        let p = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ];
        let (k1, k2, p1, p2, k3) = (0.1, 0.01, 0.002, 0.003, 0.001);
        let proj = Projection::Matrix {
            p,
            dist_coeffs: [k1, k2, p1, p2, k3],
            orig_size: 4.0,
        };
        let cam = Camera {
            projection: proj,
            ..Camera::default()
        };
        let s = cam.to_screen(DVec3::new(0.6, 0.8, 1.0 - 1e-5));
        // x' = 0.6, y' = 0.8, r² = 1.
        let radial = 1.0 + k1 + k2 + k3;
        let x2 = 0.6 * radial + 2.0 * p1 * 0.48 + p2 * (1.0 + 2.0 * 0.36);
        let y2 = 0.8 * radial + p1 * (1.0 + 2.0 * 0.64) + 2.0 * p2 * 0.48;
        assert!((s[0] - (x2 - 2.0) / 2.0).abs() < 1e-9);
        assert!((s[1] - (y2 - 2.0) / 2.0).abs() < 1e-9);
    }
}
