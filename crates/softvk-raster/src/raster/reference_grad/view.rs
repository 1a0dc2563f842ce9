//! Step 3 of the f64 backward, per view and face: the pixels' contributions summed per face
//! ([`backward_view`]), then chained through the projection to world space
//! ([`face_screen_to_world_grad`]), with each face's share of the camera's gradient
//! ([`camera_grad`], [`look_at_grad`]).

use glam::DVec3;

use super::pixel::{ColorSampleGrad, PixelUpstream, pixel_face_grad};
use super::{CameraGrad, ViewForward, add3, color_slots, normalize_eps_grad};
use crate::camera::{Camera, Projection, pixel_center};
use crate::raster::reference::FaceColors;
use crate::raster::settings::{ColorMode, RasterSettings};

/// `look_at` normalizes with this eps (SoftRas's).
const LOOK_AT_EPS: f64 = 1e-5;

/// One view's pixel contributions summed per face.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceScreenGrads {
    /// Per face, dL/d(screen vertex `(x_s, y_s, z)`) of each corner.
    pub screen: Vec<[[f64; 3]; 3]>,
    /// Per face, [`color_slots`] dL/d(lit colour)s: its R² texels or its 3 corners.
    pub colors: Vec<[f64; 3]>,
}

/// The backward of one view's fine pass: every rendered pixel (row-major), every face in
/// order, summed per face. `d_rendered` is dL/d(rendered RGBA) ([`upsample_grad_2x2`] of the
/// output's with anti-aliasing).
///
/// [`upsample_grad_2x2`]: super::upsample_grad_2x2
pub fn backward_view(
    fwd: &ViewForward,
    colors: &FaceColors,
    d_rendered: &[[f64; 4]],
    s: &RasterSettings,
) -> FaceScreenGrads {
    let nf = fwd.faces.len();
    let slots = match colors {
        FaceColors::Surface { res, .. } => color_slots(ColorMode::Surface, *res),
        FaceColors::Vertex { .. } => color_slots(ColorMode::Vertex, 1),
    };
    let mut out = FaceScreenGrads {
        screen: vec![[[0.0; 3]; 3]; nf],
        colors: vec![[0.0; 3]; slots * nf],
    };
    for row in 0..fwd.height {
        for col in 0..fwd.width {
            let i = (row * fwd.width + col) as usize;
            let up = PixelUpstream::new(
                pixel_center(col, row, fwd.width, fwd.height),
                fwd.image[i],
                fwd.aux[i],
                d_rendered[i],
                nf,
            );
            if up.is_zero() {
                continue;
            }
            for (j, face) in fwd.faces.iter().enumerate() {
                let Some(g) = pixel_face_grad(face, j, colors, &up, s) else {
                    continue;
                };
                for (acc, gk) in out.screen[j].iter_mut().zip(g.screen) {
                    add3(acc, gk);
                }
                match g.color {
                    Some(ColorSampleGrad::Texel { texel, rgb }) => {
                        add3(&mut out.colors[j * slots + texel], rgb);
                    }
                    Some(ColorSampleGrad::Corners(c)) => {
                        for (k, ck) in c.into_iter().enumerate() {
                            add3(&mut out.colors[j * 3 + k], ck);
                        }
                    }
                    None => {}
                }
            }
        }
    }
    out
}

/// One face's screen-space gradient in world space, for one view.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FaceWorldGrad {
    /// dL/d(world position) of each corner, through this view's projection.
    pub corners: [[f64; 3]; 3],
    /// This face's share of dL/d(R), R the look-at rotation (rows x, y, z); zero for a matrix
    /// projection, which does not use the look-at.
    pub rotation: [[f64; 3]; 3],
}

/// Chains a face's dL/d(screen vertices) through the projection and `p_c = R (p − eye)` to
/// world space; `rotation` is the view's `look_at(eye, at, up)`.
pub fn face_screen_to_world_grad(
    camera: &Camera,
    rotation: &[[f64; 3]; 3],
    corners: [DVec3; 3],
    screen: &[[f64; 3]; 3],
) -> FaceWorldGrad {
    let mut out = FaceWorldGrad::default();
    let r = rotation.map(DVec3::from);
    for (k, &p) in corners.iter().enumerate() {
        let g = screen[k];
        // Also keeps a vertex on a perspective camera's plane (a face the forward skips as
        // not finite) from turning 0 · ∞ into NaN.
        if g == [0.0; 3] {
            continue;
        }
        let rel = p - camera.eye;
        let pc = DVec3::new(r[0].dot(rel), r[1].dot(rel), r[2].dot(rel));
        let d_cam = match &camera.projection {
            Projection::Perspective { viewing_angle_deg } => {
                let width = viewing_angle_deg.to_radians().tan();
                let k_xy = 1.0 / (pc.z * width);
                DVec3::new(
                    g[0] * k_xy,
                    g[1] * k_xy,
                    g[2] - (g[0] * pc.x + g[1] * pc.y) * k_xy / pc.z,
                )
            }
            Projection::Orthographic { scale } => DVec3::new(g[0] * scale, g[1] * scale, g[2]),
            Projection::Matrix {
                p: m,
                dist_coeffs,
                orig_size,
            } => {
                out.corners[k] = matrix_projection_grad(m, dist_coeffs, *orig_size, p, g);
                continue;
            }
        };
        out.corners[k] = (r[0] * d_cam.x + r[1] * d_cam.y + r[2] * d_cam.z).to_array();
        for (i, di) in d_cam.to_array().into_iter().enumerate() {
            for c in 0..3 {
                out.rotation[i][c] += di * rel[c];
            }
        }
    }
    out
}

/// dL/d(world point) through SoftRas's `projection` (3×4 matrix, Brown distortion, `orig_size`;
/// see `Projection::Matrix`), given dL/d(screen point).
fn matrix_projection_grad(
    m: &[[f64; 4]; 3],
    dist: &[f64; 5],
    orig_size: f64,
    p: DVec3,
    g: [f64; 3],
) -> [f64; 3] {
    let row = |r: &[f64; 4]| r[0] * p.x + r[1] * p.y + r[2] * p.z + r[3];
    let (x, y, z) = (row(&m[0]), row(&m[1]), row(&m[2]));
    let zs = z + 1e-5;
    let (x1, y1) = (x / zs, y / zs);
    let [k1, k2, p1, p2, k3] = *dist;
    let r2 = x1 * x1 + y1 * y1;
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
    let d_radial = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r2 * r2;
    let half = orig_size / 2.0;
    let (g_x2, g_y2) = (g[0] / half, g[1] / half);
    let dx2_dx1 = radial + 2.0 * x1 * x1 * d_radial + 2.0 * p1 * y1 + 6.0 * p2 * x1;
    let dx2_dy1 = 2.0 * x1 * y1 * d_radial + 2.0 * p1 * x1 + 2.0 * p2 * y1;
    let dy2_dx1 = 2.0 * x1 * y1 * d_radial + 2.0 * p1 * x1 + 2.0 * p2 * y1;
    let dy2_dy1 = radial + 2.0 * y1 * y1 * d_radial + 6.0 * p1 * y1 + 2.0 * p2 * x1;
    let g_x1 = g_x2 * dx2_dx1 + g_y2 * dy2_dx1;
    let g_y1 = g_x2 * dx2_dy1 + g_y2 * dy2_dy1;
    let g_row = [g_x1 / zs, g_y1 / zs, g[2] - (g_x1 * x1 + g_y1 * y1) / zs];
    std::array::from_fn(|c| g_row[0] * m[0][c] + g_row[1] * m[1][c] + g_row[2] * m[2][c])
}

/// dL/d(eye, at, up) of `R = look_at(eye, at, up)` given dL/dR (rows x, y, z), through
/// `z = N(at − eye)`, `x = N(up × z)`, `y = N(z × x)`, `N` SoftRas's eps-normalization.
pub fn look_at_grad(eye: DVec3, at: DVec3, up: DVec3, d_rotation: [[f64; 3]; 3]) -> CameraGrad {
    let vz = at - eye;
    let z = vz / vz.length().max(LOOK_AT_EPS);
    let vx = up.cross(z);
    let x = vx / vx.length().max(LOOK_AT_EPS);
    let vy = z.cross(x);
    let [mut g_x, g_y, mut g_z] = d_rotation.map(DVec3::from);
    let g_vy = normalize_eps_grad(vy, LOOK_AT_EPS, g_y);
    g_z += x.cross(g_vy);
    g_x += g_vy.cross(z);
    let g_vx = normalize_eps_grad(vx, LOOK_AT_EPS, g_x);
    let g_up = z.cross(g_vx);
    g_z += g_vx.cross(up);
    let g_vz = normalize_eps_grad(vz, LOOK_AT_EPS, g_z);
    CameraGrad {
        eye: (-g_vz).to_array(),
        at: g_vz.to_array(),
        up: g_up.to_array(),
    }
}

/// A view's camera gradient from its faces' summed [`FaceWorldGrad`]s: `d_rotation`
/// (Σ rotation) and `d_world_sum` (Σ corners; `p − eye` makes the eye's direct share its
/// negative). Zero for a matrix projection.
pub fn camera_grad(
    camera: &Camera,
    d_rotation: [[f64; 3]; 3],
    d_world_sum: [f64; 3],
) -> CameraGrad {
    if matches!(camera.projection, Projection::Matrix { .. }) {
        return CameraGrad::default();
    }
    let mut g = look_at_grad(camera.eye, camera.at, camera.up, d_rotation);
    for (e, d) in g.eye.iter_mut().zip(d_world_sum) {
        *e -= d;
    }
    g
}
