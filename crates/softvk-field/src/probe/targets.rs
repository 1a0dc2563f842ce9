//! What sphere probing fits: the target silhouettes and the views they were taken from, on the
//! host ([`Targets`], which the CPU twins read) and on the GPU ([`GpuTargets`]).
//!
//! A view is a [`ProbeView`]: the camera as a projective map to screen space (SPEC §1) plus, for
//! every screen point, the line of world points that project to it. Both come from the camera in
//! f64 and are rounded once to f32; the kernels and the twins then use the same f32 numbers.

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use crate::camera::{Camera, Projection, look_at};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context};
use crate::io::Silhouettes;

/// One view as the probing kernels read it. Twin of `ProbeView` in `kernels/softvk/include/probe.glsl`;
/// std430, 160 bytes, every member a `vec4`.
///
/// Screen position of a world point p: `(a0·(p, 1) / a2·(p, 1), a1·(p, 1) / a2·(p, 1))`, which is
/// `Camera::to_screen` rewritten as one projective map; depth `depth·(p, 1)`. The points that
/// project to screen point s form the line `o0 + s.x ox + s.y oy + t (d0 + s.x dx + s.y dy)`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ProbeView {
    /// Numerator row of x_s.
    pub a0: [f32; 4],
    /// Numerator row of y_s.
    pub a1: [f32; 4],
    /// Denominator row of both (positive in front of the camera).
    pub a2: [f32; 4],
    /// The depth row (camera z; P's third row for a matrix projection).
    pub depth: [f32; 4],
    /// Ray origin, constant part (w unused).
    pub o0: [f32; 4],
    /// Ray origin, per unit of x_s.
    pub ox: [f32; 4],
    /// Ray origin, per unit of y_s.
    pub oy: [f32; 4],
    /// Ray direction (unnormalized), constant part.
    pub d0: [f32; 4],
    /// Ray direction, per unit of x_s.
    pub dx: [f32; 4],
    /// Ray direction, per unit of y_s.
    pub dy: [f32; 4],
}

type Row = [f64; 4];

fn affine(a: &Row, p: DVec3) -> f64 {
    a[0] * p.x + a[1] * p.y + a[2] * p.z + a[3]
}

fn xyz(a: &Row) -> DVec3 {
    DVec3::new(a[0], a[1], a[2])
}

fn det3(m: [DVec3; 3]) -> f64 {
    m[0].dot(m[1].cross(m[2]))
}

/// Solves `[r0; r1; r2] x = b` by Cramer's rule (the caller checked the determinant).
fn solve3(m: [DVec3; 3], b: DVec3) -> DVec3 {
    let d = det3(m);
    let cols = [
        DVec3::new(m[0].x, m[1].x, m[2].x),
        DVec3::new(m[0].y, m[1].y, m[2].y),
        DVec3::new(m[0].z, m[1].z, m[2].z),
    ];
    let det_cols = |c: [DVec3; 3]| c[0].dot(c[1].cross(c[2]));
    DVec3::new(
        det_cols([b, cols[1], cols[2]]) / d,
        det_cols([cols[0], b, cols[2]]) / d,
        det_cols([cols[0], cols[1], b]) / d,
    )
}

/// The projective form of a camera, in f64: rows `a0, a1, a2` and `depth` (see [`ProbeView`]).
pub(crate) fn projective_rows(camera: &Camera) -> Result<[Row; 4]> {
    let eye = camera.eye;
    let look = |r: &[[f64; 3]; 3], k: usize, s: f64| {
        let v = DVec3::from(r[k]);
        [s * v.x, s * v.y, s * v.z, -s * v.dot(eye)]
    };
    let rows = match camera.projection {
        Projection::Perspective { viewing_angle_deg } => {
            if !(viewing_angle_deg > 0.0 && viewing_angle_deg < 90.0) {
                return Err(Error::Input(format!(
                    "sphere probing: a perspective viewing angle of {viewing_angle_deg}° (it \
                     must lie strictly between 0 and 90)"
                )));
            }
            let r = look_at(eye, camera.at, camera.up);
            let tan = viewing_angle_deg.to_radians().tan();
            [
                look(&r, 0, 1.0),
                look(&r, 1, 1.0),
                look(&r, 2, tan),
                look(&r, 2, 1.0),
            ]
        }
        Projection::Orthographic { scale } => {
            if !(scale > 0.0 && scale.is_finite()) {
                return Err(Error::Input(format!(
                    "sphere probing: an orthographic scale of {scale} (it must be positive)"
                )));
            }
            let r = look_at(eye, camera.at, camera.up);
            [
                look(&r, 0, scale),
                look(&r, 1, scale),
                [0.0, 0.0, 0.0, 1.0],
                look(&r, 2, 1.0),
            ]
        }
        Projection::Matrix {
            p,
            dist_coeffs,
            orig_size,
        } => {
            if dist_coeffs.iter().any(|&c| c != 0.0) {
                return Err(Error::Input(format!(
                    "sphere probing: the matrix projection's Brown distortion {dist_coeffs:?} is \
                     not supported (its rays are not straight lines in screen space); undistort \
                     the silhouettes and pass zero coefficients"
                )));
            }
            if !(orig_size > 0.0 && orig_size.is_finite()) {
                return Err(Error::Input(format!(
                    "sphere probing: matrix projection with orig_size {orig_size}"
                )));
            }
            // x_s = (x / (z + 1e-5) − h) / h with h = orig_size / 2, as `Camera::to_screen`.
            let h = orig_size / 2.0;
            let z = [p[2][0], p[2][1], p[2][2], p[2][3] + 1e-5];
            let num = |r: [f64; 4]| [0, 1, 2, 3].map(|i| r[i] - h * z[i]);
            [num(p[0]), num(p[1]), z.map(|c| h * c), p[2]]
        }
    };
    if !rows.iter().flatten().all(|c| c.is_finite()) {
        return Err(Error::Input(format!(
            "sphere probing: camera at {eye} looking at {} is not finite",
            camera.at
        )));
    }
    Ok(rows)
}

impl ProbeView {
    /// The view of `camera` (perspective, orthographic, or a matrix projection without
    /// distortion; [`Error::Input`] otherwise).
    pub fn new(camera: &Camera) -> Result<ProbeView> {
        let [a0, a1, a2, depth] = projective_rows(camera)?;
        let (m0, m1, m2) = (xyz(&a0), xyz(&a1), xyz(&a2));
        // The line of screen point s is the intersection of the planes (a0 − s.x a2)·(p, 1) = 0
        // and (a1 − s.y a2)·(p, 1) = 0; its direction (m0 − s.x m2) × (m1 − s.y m2) is affine in
        // s because m2 × m2 = 0.
        let (d0, dx, dy) = (m0.cross(m1), m1.cross(m2), m2.cross(m0));
        // A determinant far below the product of its rows' lengths: (numerically) singular.
        let degenerate = |m: [DVec3; 3]| {
            let scale = m[0].length() * m[1].length() * m[2].length();
            det3(m).abs() <= 1e-12 * scale || !det3(m).is_finite()
        };
        let (o0, ox, oy) = if m2 == DVec3::ZERO {
            // An affine camera: a0·(p, 1) = s.x and a1·(p, 1) = s.y; take the point of the line
            // on the depth-0 plane.
            let n = [m0, m1, xyz(&depth)];
            if degenerate(n) {
                return Err(Error::Input(
                    "sphere probing: a degenerate orthographic camera".into(),
                ));
            }
            (
                solve3(n, DVec3::new(-a0[3], -a1[3], -depth[3])),
                solve3(n, DVec3::X),
                solve3(n, DVec3::Y),
            )
        } else {
            // A central camera: every line passes through its centre, where all rows vanish.
            let m = [m0, m1, m2];
            if degenerate(m) {
                return Err(Error::Input(
                    "sphere probing: a projection matrix whose 3×3 part is singular".into(),
                ));
            }
            (
                solve3(m, DVec3::new(-a0[3], -a1[3], -a2[3])),
                DVec3::ZERO,
                DVec3::ZERO,
            )
        };
        // Only the direction's line matters: scale it to unit length at the image centre.
        let unit = 1.0 / d0.length();
        let f4 = |r: &Row| r.map(|c| c as f32);
        let v4 = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32, 0.0];
        let view = ProbeView {
            a0: f4(&a0),
            a1: f4(&a1),
            a2: f4(&a2),
            depth: f4(&depth),
            o0: v4(o0),
            ox: v4(ox),
            oy: v4(oy),
            d0: v4(d0 * unit),
            dx: v4(dx * unit),
            dy: v4(dy * unit),
        };
        let all = bytemuck::cast_slice::<ProbeView, f32>(std::slice::from_ref(&view));
        if !all.iter().all(|c| c.is_finite()) {
            return Err(Error::Input(format!(
                "sphere probing: camera at {} does not give a finite view in f32",
                camera.eye
            )));
        }
        Ok(view)
    }

    /// Screen position and depth of a world point, in f64 from the f32 rows.
    pub fn project(&self, p: DVec3) -> [f64; 3] {
        let r = |a: &[f32; 4]| a.map(f64::from);
        let den = affine(&r(&self.a2), p);
        [
            affine(&r(&self.a0), p) / den,
            affine(&r(&self.a1), p) / den,
            affine(&r(&self.depth), p),
        ]
    }

    /// The denominator `a2·(p, 1)` (positive in front of the camera), in f64.
    pub fn denominator(&self, p: DVec3) -> f64 {
        affine(&self.a2.map(f64::from), p)
    }
}

/// The target silhouettes and their views, on the host.
#[derive(Clone, Debug)]
pub struct Targets {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The cameras, one per view.
    pub cameras: Vec<Camera>,
    /// The views as the kernels read them.
    pub views: Vec<ProbeView>,
    /// `views × height × width` values, view-major then row-major (row 0 at the top); a pixel is
    /// inside when its value is ≥ 0.5.
    pub masks: Vec<f32>,
}

impl Targets {
    /// Targets from cameras and masks (`cameras.len() × height × width` values).
    pub fn new(cameras: &[Camera], width: u32, height: u32, masks: Vec<f32>) -> Result<Self> {
        if cameras.is_empty() || width == 0 || height == 0 {
            return Err(Error::Input(format!(
                "sphere probing: {} views of {width}×{height} pixels; every count must be \
                 positive",
                cameras.len()
            )));
        }
        let pixels = u64::from(width) * u64::from(height);
        if pixels * cameras.len() as u64 >= 1 << 31 {
            return Err(Error::Limit(format!(
                "sphere probing: {} views of {width}×{height} pixels are too many pixels",
                cameras.len()
            )));
        }
        if masks.len() as u64 != pixels * cameras.len() as u64 {
            return Err(Error::Input(format!(
                "sphere probing: {} mask values for {} views of {width}×{height}",
                masks.len(),
                cameras.len()
            )));
        }
        if masks.iter().any(|m| !m.is_finite()) {
            return Err(Error::Input(
                "sphere probing: a silhouette value is not finite".into(),
            ));
        }
        let views = cameras
            .iter()
            .enumerate()
            .map(|(k, c)| {
                ProbeView::new(c).map_err(|e| match e {
                    Error::Input(m) => Error::Input(format!("view {k}: {m}")),
                    other => other,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self {
            width,
            height,
            cameras: cameras.to_vec(),
            views,
            masks,
        })
    }

    /// Targets from loaded silhouettes, one camera per silhouette in order.
    pub fn from_silhouettes(cameras: &[Camera], silhouettes: &Silhouettes) -> Result<Self> {
        if cameras.len() != silhouettes.views() {
            return Err(Error::Input(format!(
                "sphere probing: {} cameras for {} silhouettes",
                cameras.len(),
                silhouettes.views()
            )));
        }
        Self::new(
            cameras,
            silhouettes.width,
            silhouettes.height,
            silhouettes.masks.clone(),
        )
    }

    /// Number of views.
    pub fn view_count(&self) -> u32 {
        self.views.len() as u32
    }

    /// Pixels per view.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The mask of `view`, row-major.
    pub fn mask(&self, view: usize) -> &[f32] {
        let n = self.pixels();
        &self.masks[view * n..(view + 1) * n]
    }

    /// Is pixel (`col`, `row`) of `view` inside its silhouette (false outside the image)?
    pub fn inside(&self, view: usize, col: i64, row: i64) -> bool {
        let (w, h) = (i64::from(self.width), i64::from(self.height));
        (0..w).contains(&col)
            && (0..h).contains(&row)
            && self.masks[view * self.pixels() + (row * w + col) as usize] >= 0.5
    }

    /// The pixel (`col`, `row`) whose centre is nearest screen point (`x`, `y`), possibly
    /// outside the image: `c = ⌊(x S + W) / 2⌋`, `r = ⌊(H − y S) / 2⌋` (SPEC §1 inverted).
    pub fn screen_to_pixel(&self, x: f64, y: f64) -> (i64, i64) {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let s = w.min(h);
        let c = ((x * s + w) * 0.5).floor();
        let r = ((h - y * s) * 0.5).floor();
        (c.clamp(-1.0, w) as i64, r.clamp(-1.0, h) as i64)
    }
}

/// The targets of a sphere of `radius` at the origin, computed exactly: a pixel is inside when
/// the line of its centre passes within `radius` of the origin. For tests and demos.
pub fn sphere_silhouettes(
    cameras: &[Camera],
    width: u32,
    height: u32,
    radius: f64,
) -> Result<Targets> {
    let mut masks = Vec::with_capacity(cameras.len() * (width * height) as usize);
    for camera in cameras {
        let view = ProbeView::new(camera)?;
        let f = |a: [f32; 4]| DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]));
        for row in 0..height {
            for col in 0..width {
                let (x, y) = crate::camera::pixel_center(col, row, width, height);
                let o = f(view.o0) + x * f(view.ox) + y * f(view.oy);
                let d = f(view.d0) + x * f(view.dx) + y * f(view.dy);
                let dist = (-o).cross(d).length() / d.length();
                masks.push(if dist < radius { 1.0 } else { 0.0 });
            }
        }
    }
    Targets::new(cameras, width, height, masks)
}

/// The targets on the GPU: the views and the masks, read by the sampler and the prober.
pub struct GpuTargets {
    views: Buffer,
    masks: Buffer,
    width: u32,
    height: u32,
    view_count: u32,
}

impl GpuTargets {
    /// Uploads `targets`.
    pub fn new(ctx: &Context, targets: &Targets) -> Result<Self> {
        crate::gpu::check_binding(
            ctx,
            "sphere probing: the silhouettes",
            4 * targets.masks.len() as u64,
        )?;
        Ok(Self {
            views: ctx.upload_buffer("probe views", &targets.views)?,
            masks: ctx.upload_buffer("probe silhouettes", &targets.masks)?,
            width: targets.width,
            height: targets.height,
            view_count: targets.view_count(),
        })
    }

    /// The [`ProbeView`]s.
    pub fn views(&self) -> &Buffer {
        &self.views
    }

    /// The masks (one `f32` per pixel, view-major, row-major).
    pub fn masks(&self) -> &Buffer {
        &self.masks
    }

    /// Image width.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Number of views.
    pub fn view_count(&self) -> u32 {
        self.view_count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    fn check_view_matches_camera(camera: &Camera) {
        let view = ProbeView::new(camera).unwrap();
        let points = [
            DVec3::new(0.1, -0.2, 0.3),
            DVec3::new(-0.5, 0.4, -0.2),
            DVec3::new(0.7, 0.6, 0.1),
        ];
        for p in points {
            let want = camera.to_screen(p);
            let got = view.project(p);
            for k in 0..3 {
                assert!(close(got[k], want[k], 1e-5), "{p}: {got:?} vs {want:?}");
            }
            // p lies on the line of its own screen point.
            let f = |a: [f32; 4]| DVec3::new(f64::from(a[0]), f64::from(a[1]), f64::from(a[2]));
            let o = f(view.o0) + got[0] * f(view.ox) + got[1] * f(view.oy);
            let d = f(view.d0) + got[0] * f(view.dx) + got[1] * f(view.dy);
            let dist = (p - o).cross(d).length() / d.length();
            assert!(dist < 1e-5, "{p}: {dist}");
        }
    }

    #[test]
    fn probe_views_project_as_the_camera_and_their_rays_pass_through_the_points() {
        check_view_matches_camera(&Camera::from_angles(2.732, 30.0, -45.0));
        check_view_matches_camera(&Camera {
            projection: Projection::Orthographic { scale: 0.8 },
            ..Camera::from_angles(3.0, -20.0, 110.0)
        });
        let (f, c) = (300.0, 128.0);
        let camera = Camera {
            projection: Projection::Matrix {
                p: [
                    [f, 0.0, c, 0.1 * c],
                    [0.0, f, c, -0.2 * c],
                    [0.0, 0.0, 1.0, 3.0],
                ],
                dist_coeffs: [0.0; 5],
                orig_size: 256.0,
            },
            ..Camera::default()
        };
        check_view_matches_camera(&camera);
    }

    #[test]
    fn distortion_singular_matrices_and_bad_angles_are_input_errors() {
        let mut camera = Camera {
            projection: Projection::Matrix {
                p: [
                    [1.0, 0.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 2.0],
                ],
                dist_coeffs: [0.1, 0.0, 0.0, 0.0, 0.0],
                orig_size: 2.0,
            },
            ..Camera::default()
        };
        assert!(matches!(ProbeView::new(&camera), Err(Error::Input(_))));
        camera.projection = Projection::Matrix {
            p: [
                [1.0, 0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 2.0],
            ],
            dist_coeffs: [0.0; 5],
            orig_size: 2.0,
        };
        assert!(matches!(ProbeView::new(&camera), Err(Error::Input(_))));
        camera.projection = Projection::Perspective {
            viewing_angle_deg: 90.0,
        };
        assert!(matches!(ProbeView::new(&camera), Err(Error::Input(_))));
    }

    #[test]
    fn screen_to_pixel_inverts_pixel_centres() {
        let t = Targets::new(&[Camera::default()], 7, 4, vec![0.0; 28]).unwrap();
        for row in 0..4 {
            for col in 0..7 {
                let (x, y) = crate::camera::pixel_center(col, row, 7, 4);
                assert_eq!(t.screen_to_pixel(x, y), (i64::from(col), i64::from(row)));
            }
        }
        assert_eq!(t.screen_to_pixel(-10.0, 0.0).0, -1);
    }
}
