//! A shaded preview of φ = 0.5: per pixel a ray from the camera (the same pixel centres and
//! projection as the renderer), marched through the field's cube at a fixed step, refined by
//! bisection to φ = 0.5, and shaded Lambertian with the normal `−∇φ / |∇φ|` from central
//! differences. The rays, bisection and shading run on the host; φ is evaluated in batches, on
//! the GPU by [`render_preview`] (through [`Field::eval`]) or by any evaluator (the twin) with
//! [`render_preview_with`]. A PNG is then one `fit::report::write_png` away (feature `plots`).
//!
//! The march samples `t₀ + iΔ` with `Δ = 2√3 h / steps` (`steps` samples along the cube's
//! diagonal) from where the ray enters the cube; the first sample with φ > 0.5 is a hit, so a
//! surface thinner than Δ along the ray can be missed. A ray that starts inside (φ > 0.5 where it
//! enters the cube) hits at the entry point.

use glam::DVec3;
use image::{Rgba, RgbaImage};

use super::{Cube, EVAL_BATCH, Field};
use crate::camera::{Camera, Projection, look_at, pixel_center};
use crate::error::{Error, Result};
use crate::gpu::Context;

/// How to render a preview.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewOptions {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// March samples along the cube's diagonal (the step is `2√3 h / steps`).
    pub steps: u32,
    /// Bisection iterations after a hit (each halves the depth interval).
    pub bisections: u32,
    /// Central-difference step of the normal, as a fraction of the cube's half-size.
    pub normal_step: f64,
    /// Direction towards the light (world); `None`: a headlight, towards the camera.
    pub light: Option<[f64; 3]>,
    /// Ambient term.
    pub ambient: f64,
    /// Diffuse (Lambertian) term.
    pub diffuse: f64,
    /// Surface colour (linear, 0..1).
    pub color: [f64; 3],
}

impl Default for PreviewOptions {
    /// 256², 256 steps, 12 bisections, normal step 0.01 h, headlight, 0.25 ambient + 0.75
    /// diffuse, light grey.
    fn default() -> Self {
        Self {
            width: 256,
            height: 256,
            steps: 256,
            bisections: 12,
            normal_step: 0.01,
            light: None,
            ambient: 0.25,
            diffuse: 0.75,
            color: [0.85, 0.85, 0.85],
        }
    }
}

impl PreviewOptions {
    fn validate(&self) -> Result<()> {
        let finite = |x: f64| x.is_finite() && x >= 0.0;
        if self.width == 0
            || self.height == 0
            || self.steps == 0
            || !(finite(self.normal_step) && self.normal_step > 0.0)
            || !finite(self.ambient)
            || !finite(self.diffuse)
            || !self.color.iter().all(|&c| finite(c))
            || self
                .light
                .is_some_and(|l| !l.iter().all(|c| c.is_finite()) || DVec3::from(l).length() == 0.0)
        {
            return Err(Error::Input(format!(
                "preview options {self:?}: need a non-empty image, steps > 0, a normal step > 0, \
                 non-negative finite shading terms and a non-zero finite light direction"
            )));
        }
        Ok(())
    }
}

/// A φ evaluator: points (xyz, w ignored) → φ.
pub type Evaluator<'a> = dyn FnMut(&[[f32; 4]]) -> Result<Vec<f32>> + 'a;

/// One pixel's ray: origin and unit direction (world).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub origin: DVec3,
    /// Unit direction.
    pub dir: DVec3,
}

/// The ray through the centre of pixel (`col`, `row`): for a perspective camera from the eye
/// through camera point `(x_p tan a, y_p tan a, 1)`, for an orthographic one from
/// `eye + Rᵀ(x_p / s, y_p / s, 0)` along the view axis, so that the ray's points project to
/// `(x_p, y_p)` with [`Camera::to_screen`]. A projection-matrix camera is [`Error::Input`].
pub fn pixel_ray(camera: &Camera, col: u32, row: u32, width: u32, height: u32) -> Result<Ray> {
    let (xp, yp) = pixel_center(col, row, width, height);
    let r = look_at(camera.eye, camera.at, camera.up).map(DVec3::from);
    let to_world = |c: DVec3| r[0] * c.x + r[1] * c.y + r[2] * c.z;
    match camera.projection {
        Projection::Perspective { viewing_angle_deg } => {
            let t = viewing_angle_deg.to_radians().tan();
            Ok(Ray {
                origin: camera.eye,
                dir: to_world(DVec3::new(xp * t, yp * t, 1.0)).normalize(),
            })
        }
        Projection::Orthographic { scale } => Ok(Ray {
            origin: camera.eye + to_world(DVec3::new(xp / scale, yp / scale, 0.0)),
            dir: r[2].normalize(),
        }),
        Projection::Matrix { .. } => Err(Error::Input(
            "preview: cameras with a projection matrix are not supported".into(),
        )),
    }
}

/// `[t_enter, t_exit]` of the ray in the cube (`t ≥ 0`), or `None` when it misses.
fn cube_span(cube: &Cube, ray: &Ray) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for k in 0..3 {
        let (o, d) = (ray.origin[k], ray.dir[k]);
        let (lo, hi) = (cube.center[k] - cube.half, cube.center[k] + cube.half);
        if d == 0.0 {
            if o < lo || o > hi {
                return None;
            }
            continue;
        }
        let (a, b) = ((lo - o) / d, (hi - o) / d);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    (t0 <= t1).then_some((t0, t1))
}

/// Evaluates φ at many points, in batches of at most [`EVAL_BATCH`].
fn eval_all(eval: &mut Evaluator<'_>, points: &[DVec3]) -> Result<Vec<f32>> {
    let mut out = Vec::with_capacity(points.len());
    for chunk in points.chunks(EVAL_BATCH as usize) {
        let pts: Vec<[f32; 4]> = chunk
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32, 1.0])
            .collect();
        out.extend(eval(&pts)?);
    }
    Ok(out)
}

/// The preview of `field` from `camera`, φ evaluated on the GPU.
pub fn render_preview(
    ctx: &Context,
    field: &Field,
    camera: &Camera,
    options: &PreviewOptions,
) -> Result<RgbaImage> {
    render_preview_with(
        &mut |pts: &[[f32; 4]]| field.eval(ctx, pts),
        field.cube(),
        camera,
        options,
    )
}

/// The preview of the field that `eval` evaluates (points → φ) in `cube`. Pixels without a hit
/// are transparent black; hits are opaque.
pub fn render_preview_with(
    eval: &mut Evaluator<'_>,
    cube: &Cube,
    camera: &Camera,
    options: &PreviewOptions,
) -> Result<RgbaImage> {
    options.validate()?;
    cube.validate()?;
    let (w, h) = (options.width, options.height);
    let step = 2.0 * 3f64.sqrt() * cube.half / f64::from(options.steps);
    // Per pixel: its ray and the cube span.
    let mut rays = Vec::new();
    for row in 0..h {
        for col in 0..w {
            let ray = pixel_ray(camera, col, row, w, h)?;
            if let Some((t0, t1)) = cube_span(cube, &ray) {
                rays.push((row * w + col, ray, t0, t1));
            }
        }
    }
    // March, in groups of rays whose samples fit one eval batch.
    let samples = |t0: f64, t1: f64| ((t1 - t0) / step).ceil() as usize + 1;
    // (pixel, ray, t_outside, t_inside)
    let mut hits: Vec<(u32, Ray, f64, f64)> = Vec::new();
    let mut start = 0;
    while start < rays.len() {
        let mut end = start;
        let mut total = 0;
        while end < rays.len()
            && (end == start || total + samples(rays[end].2, rays[end].3) <= EVAL_BATCH as usize)
        {
            total += samples(rays[end].2, rays[end].3);
            end += 1;
        }
        let mut points = Vec::with_capacity(total);
        for &(_, ray, t0, t1) in &rays[start..end] {
            for i in 0..samples(t0, t1) {
                points.push(ray.origin + ray.dir * (t0 + i as f64 * step).min(t1));
            }
        }
        let phi = eval_all(eval, &points)?;
        let mut at = 0;
        for &(pixel, ray, t0, t1) in &rays[start..end] {
            let n = samples(t0, t1);
            if let Some(i) = phi[at..at + n].iter().position(|&f| f > 0.5) {
                let t_in = (t0 + i as f64 * step).min(t1);
                let t_out = if i == 0 {
                    t_in
                } else {
                    t0 + (i - 1) as f64 * step
                };
                hits.push((pixel, ray, t_out, t_in));
            }
            at += n;
        }
        start = end;
    }
    // Bisection, all hits at once per iteration.
    for _ in 0..options.bisections {
        let mids: Vec<DVec3> = hits
            .iter()
            .map(|&(_, ray, lo, hi)| ray.origin + ray.dir * (0.5 * (lo + hi)))
            .collect();
        let phi = eval_all(eval, &mids)?;
        for (hit, &f) in hits.iter_mut().zip(&phi) {
            let mid = 0.5 * (hit.2 + hit.3);
            if f > 0.5 {
                hit.3 = mid;
            } else {
                hit.2 = mid;
            }
        }
    }
    // Normals by central differences.
    let delta = options.normal_step * cube.half;
    let axes = [DVec3::X, DVec3::Y, DVec3::Z];
    let mut probes = Vec::with_capacity(6 * hits.len());
    for &(_, ray, lo, hi) in &hits {
        let p = ray.origin + ray.dir * (0.5 * (lo + hi));
        for a in axes {
            probes.push(p + a * delta);
            probes.push(p - a * delta);
        }
    }
    let phi = eval_all(eval, &probes)?;
    let mut image = RgbaImage::from_pixel(w, h, Rgba([0, 0, 0, 0]));
    for (k, &(pixel, ray, _, _)) in hits.iter().enumerate() {
        let d = |a: usize| f64::from(phi[6 * k + 2 * a]) - f64::from(phi[6 * k + 2 * a + 1]);
        let grad = DVec3::new(d(0), d(1), d(2));
        let n = if grad.length() > 0.0 {
            -grad.normalize()
        } else {
            -ray.dir
        };
        let l = options
            .light
            .map_or(-ray.dir, |l| DVec3::from(l).normalize());
        let shade = options.ambient + options.diffuse * n.dot(l).max(0.0);
        let c = options
            .color
            .map(|c| ((c * shade).clamp(0.0, 1.0) * 255.0).round() as u8);
        image.put_pixel(pixel % w, pixel / w, Rgba([c[0], c[1], c[2], 255]));
    }
    Ok(image)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_rays_project_back_to_their_pixel_centres() {
        let cams = [
            Camera::from_angles(2.732, 30.0, 45.0),
            Camera {
                projection: Projection::Orthographic { scale: 0.7 },
                ..Camera::from_angles(3.0, -20.0, 200.0)
            },
        ];
        for cam in cams {
            for (c, r) in [(0, 0), (3, 5), (7, 2)] {
                let ray = pixel_ray(&cam, c, r, 8, 6).unwrap();
                let (xp, yp) = pixel_center(c, r, 8, 6);
                for t in [0.5, 2.0, 4.0] {
                    let s = cam.to_screen(ray.origin + ray.dir * t);
                    assert!(
                        (s[0] - xp).abs() < 1e-12 && (s[1] - yp).abs() < 1e-12,
                        "{s:?}"
                    );
                }
            }
        }
    }
}
