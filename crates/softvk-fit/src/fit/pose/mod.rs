//! Rigid pose estimation from one RGB(A) image: the rotation and translation of a
//! textured mesh that make its render match a target image, by Adam on the image MSE, with a
//! σ/γ schedule from blurry to sharp (the talk's smoother energy landscape).
//!
//! # Parameters
//!
//! A pose is an axis-angle vector ω (radians; direction the axis, length the angle) and a
//! translation t. It moves every rest vertex p about the rest mesh's vertex centroid c (the mean
//! of its vertex positions, so that a rotation does not swing the mesh out of view):
//!
//! ```text
//! p' = R(ω) (p − c) + c + t,     R(ω) = exp([ω]×) (Rodrigues)
//! ```
//!
//! # One iteration
//!
//! [`PoseFitter`] records every iteration into one command buffer with no read-back, and
//! [`fit_pose`] runs [`PoseFitOptions::log_every`] of them per submission (ending one early
//! where the σ/γ stage changes, to swap a per-stage target): the mesh and field fits' loop
//! shape. On the GPU, in f32:
//!
//! 1. `pose_apply.comp`: the posed positions p' from the parameters (ω at one bindable range,
//!    t at another); [`SceneLight`](crate::raster::light::SceneLight): the mesh lit again with its turned normals (SoftRas
//!    lights in world space before projection).
//! 2. The guarded tiled forward (face setup, count, the gate's check against the capacity,
//!    then gated: sort, fine pass), [`ImageMse`](crate::fit::ImageMse) (loss and dL/d(image)), the tiled backward.
//! 3. The lighting's backward (dL/d(lit colour) to dL/dp' through the normals, added to the
//!    geometric share), `pose_grad.comp` (the chain below, one workgroup in a fixed order; it
//!    also logs the iteration's loss and pose), and two Adam steps (rotation and translation,
//!    each with its learning rate of the iteration).
//!
//! ```text
//! dL/dt = Σ_i g_i,     dL/dω = J_l(ω)ᵀ Σ_i (q_i × g_i),     q_i = R(ω)(p_i − c),  g_i = dL/dp'_i
//! J_l(ω) = I + (1 − cos θ)/θ² [ω]× + (θ − sin θ)/θ³ [ω]×²,  θ = |ω|
//! ```
//!
//! (`exp([ω + δ]×) ≈ exp([J_l δ]×) exp([ω]×)`, so a small change δ of ω turns q_i by J_l δ.)
//!
//! [`PoseProblem`] evaluates the loss and gradient at any pose with the chain on the host in
//! f64 (two submissions and a read-back: landscapes and studies), and [`cpu`] is the f64 twin
//! of both; tests check the GPU chain against it (5e-6 of the largest component on the test
//! scenes) and k iterations per submission against one, bit for bit.
//!
//! # The σ/γ schedule
//!
//! [`Schedule`]: the iterations are split into `stages` equal stages; stage k of S renders with
//! `σ_k = σ_0 (σ_1/σ_0)^{k/(S−1)}` and likewise γ (geometric interpolation), from blurry
//! (σ_0, γ_0) to sharp (σ_1, γ_1); the last stage is sharp. Without a schedule every iteration is
//! sharp. Adam's learning rates decay geometrically over the iterations to `lr_final` times
//! their start, with or without the schedule, so that a comparison isolates the schedule.
//!
//! The f64 twin of one iteration's loss and gradient is [`cpu::loss_and_gradient`] (render,
//! MSE and backward of the reference rasterizer, then the same chain); tests check it against
//! central finite differences, and [`PoseProblem::evaluate`] and [`PoseFitter`] against it.

use glam::{DMat3, DQuat, DVec3};

use super::adam::AdamOptions;
use super::checkpoint::{Fingerprint, FitKind, Reader, Writer, read_f64_state, write_f64_state};
use super::driver;
use super::posed::Stages;
use super::session::{LogRow, Session, StopRule, Trainee};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::fit::log::Columns;
use crate::gpu::Context;
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::settings::RasterSettings;

mod fitter;
mod multistart;
mod problem;

pub mod cpu;

pub use super::posed::PoseTarget;
pub use fitter::{PoseFit, PoseFitter, Rigid};
pub use multistart::{
    MultiStartResult, StartOutcome, fit_pose_multistart, screened_starts, spread_rotations,
    spread_starts,
};
pub use problem::{Evaluation, PoseProblem};

/// A rigid pose: `p' = R(rotation) (p − c) + c + translation` (see the [module docs](self)).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose {
    /// Axis-angle vector, radians: its direction is the axis, its length the angle.
    pub rotation: DVec3,
    /// Translation, world units.
    pub translation: DVec3,
}

impl Pose {
    /// The rotation as a 3×3 matrix (Rodrigues).
    pub fn matrix(&self) -> DMat3 {
        rotation_matrix(self.rotation)
    }

    /// The rotation as a unit quaternion.
    pub fn quaternion(&self) -> DQuat {
        DQuat::from_scaled_axis(self.rotation)
    }

    /// The six parameters `(ω, t)`.
    pub fn to_array(&self) -> [f64; 6] {
        let (r, t) = (self.rotation, self.translation);
        [r.x, r.y, r.z, t.x, t.y, t.z]
    }

    /// From the six parameters `(ω, t)`.
    pub fn from_array(a: [f64; 6]) -> Pose {
        Pose {
            rotation: DVec3::new(a[0], a[1], a[2]),
            translation: DVec3::new(a[3], a[4], a[5]),
        }
    }

    /// The posed positions of `rest` about `centre`.
    pub fn apply(&self, rest: &[DVec3], centre: DVec3) -> Vec<DVec3> {
        let r = self.matrix();
        rest.iter()
            .map(|&p| r * (p - centre) + centre + self.translation)
            .collect()
    }

    /// Whether every parameter is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.is_finite() && self.translation.is_finite()
    }
}

/// `[v]×`, the cross-product matrix: `[v]× x = v × x`.
fn cross_matrix(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

/// Below this angle the trigonometric coefficients are taken from their Taylor series (their
/// closed forms cancel catastrophically; the next series term is below 1e-16 here).
const SMALL_ANGLE: f64 = 1e-3;

/// `R(ω) = exp([ω]×) = I + sin θ/θ [ω]× + (1 − cos θ)/θ² [ω]×²`, θ = |ω|.
pub fn rotation_matrix(omega: DVec3) -> DMat3 {
    let t2 = omega.length_squared();
    let t = t2.sqrt();
    let (a, b) = if t < SMALL_ANGLE {
        (1.0 - t2 / 6.0, 0.5 - t2 / 24.0)
    } else {
        (t.sin() / t, (1.0 - t.cos()) / t2)
    };
    let k = cross_matrix(omega);
    DMat3::IDENTITY + k * a + k * k * b
}

/// The left Jacobian of SO(3): `exp([ω + δ]×) ≈ exp([J_l(ω) δ]×) exp([ω]×)`;
/// `J_l = I + (1 − cos θ)/θ² [ω]× + (θ − sin θ)/θ³ [ω]×²`.
pub fn left_jacobian(omega: DVec3) -> DMat3 {
    let t2 = omega.length_squared();
    let t = t2.sqrt();
    let (a, b) = if t < SMALL_ANGLE {
        (0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        ((1.0 - t.cos()) / t2, (t - t.sin()) / (t2 * t))
    };
    let k = cross_matrix(omega);
    DMat3::IDENTITY + k * a + k * k * b
}

/// The geodesic angle (radians, in [0, π]) between the rotations of two axis-angle vectors:
/// the angle of `R(a)ᵀ R(b)`, as `2 atan2(|v|, |w|)` of its quaternion (accurate at 0 and π).
pub fn rotation_distance(a: DVec3, b: DVec3) -> f64 {
    let q = DQuat::from_scaled_axis(a).inverse() * DQuat::from_scaled_axis(b);
    2.0 * q.xyz().length().atan2(q.w.abs())
}

/// The mean of the vertex positions: the point rotations turn about.
pub fn centroid(positions: &[DVec3]) -> DVec3 {
    let n = positions.len().max(1) as f64;
    positions.iter().copied().sum::<DVec3>() / n
}

/// dL/d(ω, t) from `d_posed` = dL/dp' per vertex (see the [module docs](self)), in f64.
pub fn pose_gradient(rest: &[DVec3], centre: DVec3, pose: &Pose, d_posed: &[[f64; 3]]) -> [f64; 6] {
    assert_eq!(rest.len(), d_posed.len(), "one gradient per vertex");
    let r = pose.matrix();
    let mut torque = DVec3::ZERO;
    let mut force = DVec3::ZERO;
    for (&p, g) in rest.iter().zip(d_posed) {
        let g = DVec3::from(*g);
        torque += (r * (p - centre)).cross(g);
        force += g;
    }
    let d_omega = left_jacobian(pose.rotation).transpose() * torque;
    [d_omega.x, d_omega.y, d_omega.z, force.x, force.y, force.z]
}

/// The σ/γ schedule from blurry to sharp (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    /// σ of the first stage (blurry).
    pub sigma_start: f64,
    /// γ of the first stage.
    pub gamma_start: f64,
    /// Stages, at least 1 (1: every iteration at the start values).
    pub stages: u32,
}

impl Schedule {
    /// σ and γ of iteration `it` (0-based) of `iterations`, ending at `sharp` = (σ, γ).
    pub fn at(&self, it: u32, iterations: u32, sharp: (f64, f64)) -> (f64, f64) {
        let stages = self.stages.max(1);
        if stages == 1 {
            return (self.sigma_start, self.gamma_start);
        }
        let stage = (u64::from(it) * u64::from(stages) / u64::from(iterations.max(1)))
            .min(u64::from(stages - 1));
        let u = stage as f64 / f64::from(stages - 1);
        let geo = |a: f64, b: f64| a * (b / a).powf(u);
        (
            geo(self.sigma_start, sharp.0),
            geo(self.gamma_start, sharp.1),
        )
    }

    /// [`Error::Input`] unless both start values are finite and positive.
    pub fn validate(&self) -> Result<()> {
        let ok = |x: f64| x.is_finite() && x > 0.0;
        if !(ok(self.sigma_start) && ok(self.gamma_start)) || self.stages == 0 {
            return Err(Error::Input(format!(
                "schedule {self:?}: σ and γ must be finite and > 0, stages ≥ 1"
            )));
        }
        Ok(())
    }
}

impl Default for Schedule {
    /// The defaults chosen by `examples/pose_study.rs` on spot (RESULTS.md, "Pose estimation"):
    /// from σ = γ = 1e-3, which did as well as sharp fits or better in every range studied
    /// against a sharp target (the first choice, 1e-2/1e-1, did worse than sharp).
    fn default() -> Self {
        Schedule {
            sigma_start: 1e-3,
            gamma_start: 1e-3,
            stages: 4,
        }
    }
}

/// Refinement after a pose fit's schedule: up to `iterations` more at the sharp σ/γ and the
/// final learning rates, ended by the session's [`StopRule`] once the loss has not improved by
/// `min_improvement` (relative) for `window` iterations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refine {
    /// At most this many iterations after the schedule's.
    pub iterations: u32,
    /// Iterations without improvement that end the fit.
    pub window: u32,
    /// The relative fall of the loss that counts as an improvement.
    pub min_improvement: f64,
}

impl Default for Refine {
    /// Up to 220 iterations (300 in all after the default schedule's 80), ended after 10
    /// without a 5 % fall of the loss: the default chosen by the pose study (RESULTS.md, "Pose
    /// estimation"), where it brought every one of 20 fits from 100–145° away to within 0.9°
    /// (8 screened starts, the winner refined) in the fewest iterations of the rules measured.
    fn default() -> Self {
        Self {
            iterations: 220,
            window: 10,
            min_improvement: 0.05,
        }
    }
}

/// Everything settable about a pose fit.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseFitOptions {
    /// Iterations of the schedule (σ/γ stages and the learning rates' decay spread over them);
    /// [`PoseFitOptions::refine`] may run more.
    pub iterations: u32,
    /// Adam's learning rate of the rotation (radians per step, about).
    pub lr_rotation: f64,
    /// Adam's learning rate of the translation (world units per step, about).
    pub lr_translation: f64,
    /// Adam's β1, β2.
    pub betas: (f64, f64),
    /// The learning rates decay geometrically to this factor of their start at the last step.
    pub lr_final: f64,
    /// The σ/γ schedule; `None`: every iteration at the settings' (sharp) σ and γ.
    pub schedule: Option<Schedule>,
    /// Rasterization: size, the sharp σ and γ (the schedule's end), colours...
    pub settings: RasterSettings,
    /// Tile edge of the tiled passes.
    pub tile: u32,
    /// Iterations per submission (the fit reads its log and calls back after each; also a
    /// checkpoint's granularity). A submission also ends where the σ/γ stage changes.
    pub log_every: u32,
    /// Iterations after the schedule's, until the loss stops improving; `None`: the schedule's
    /// iterations only.
    pub refine: Option<Refine>,
}

impl Default for PoseFitOptions {
    fn default() -> Self {
        Self {
            iterations: 80,
            lr_rotation: 0.1,
            lr_translation: 0.005,
            betas: (0.9, 0.999),
            lr_final: 0.1,
            schedule: Some(Schedule::default()),
            settings: RasterSettings {
                width: 48,
                height: 48,
                ..RasterSettings::default()
            },
            tile: 8,
            log_every: 10,
            refine: Some(Refine::default()),
        }
    }
}

impl PoseFitOptions {
    /// [`Error::Input`] for an out-of-domain option.
    pub fn validate(&self) -> Result<()> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if self.iterations == 0 || self.log_every == 0 {
            return Err(Error::Input(
                "a pose fit needs at least 1 iteration, and log_every at least 1".into(),
            ));
        }
        if !(pos(self.lr_rotation) && pos(self.lr_translation) && pos(self.lr_final)) {
            return Err(Error::Input(format!(
                "learning rates must be finite and > 0 (rotation {}, translation {}, final \
                 factor {})",
                self.lr_rotation, self.lr_translation, self.lr_final
            )));
        }
        self.adam(0).validate()?;
        if let Some(s) = &self.schedule {
            s.validate()?;
        }
        crate::raster::gpu::Method::check_tile(self.tile)?;
        self.settings.validate()?;
        if let Some(r) = self.refine {
            if r.window == 0 || !(0.0..1.0).contains(&r.min_improvement) {
                return Err(Error::Input(format!(
                    "refinement: a window of at least 1 iteration and an improvement in [0, 1) \
                     (window {}, improvement {})",
                    r.window, r.min_improvement
                )));
            }
            if self.iterations.checked_add(r.iterations).is_none() {
                return Err(Error::Input("refinement: too many iterations".into()));
            }
        }
        Ok(())
    }

    /// The last iteration the fit may run: the schedule's, and the refinement's at most.
    pub fn last_iteration(&self) -> u32 {
        self.iterations + self.refine.map_or(0, |r| r.iterations)
    }

    /// The rule that ends the refinement ([`PoseFitOptions::refine`]): it counts the rows from
    /// the schedule's last iteration on.
    pub fn stop_rule(&self) -> Option<StopRule> {
        self.refine.map(|r| StopRule {
            from: self.iterations,
            window: r.window,
            min_improvement: r.min_improvement,
        })
    }

    /// σ and γ of iteration `it` (0-based).
    pub fn sigma_gamma(&self, it: u32) -> (f64, f64) {
        let sharp = (self.settings.sigma, self.settings.gamma);
        match &self.schedule {
            Some(s) => s.at(it, self.iterations, sharp),
            None => sharp,
        }
    }

    /// The learning-rate factor of iteration `it` (0-based): `lr_final^(it / (N − 1))` over
    /// the schedule's N iterations, `lr_final` after them.
    pub fn lr_factor(&self, it: u32) -> f64 {
        if self.iterations <= 1 {
            return 1.0;
        }
        let it = it.min(self.iterations - 1);
        self.lr_final
            .powf(f64::from(it) / f64::from(self.iterations - 1))
    }

    /// Adam's options for the rotation at iteration `it` (the translation scales alike).
    fn adam(&self, it: u32) -> AdamOptions {
        AdamOptions {
            lr: self.lr_rotation * self.lr_factor(it),
            betas: self.betas,
            eps: 1e-8,
        }
    }
}

/// One logged iteration.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoseLog {
    /// Iteration, from 1.
    pub iteration: u32,
    /// The MSE at this iteration's pose (before its step), at its σ and γ.
    pub loss: f64,
    /// σ of this iteration.
    pub sigma: f64,
    /// γ of this iteration.
    pub gamma: f64,
    /// The pose the iteration evaluated.
    pub pose: Pose,
    /// Seconds since the fit started.
    pub seconds: f64,
}

/// A finished pose fit.
#[derive(Clone, Debug)]
pub struct PoseFitResult {
    /// The pose after the last step.
    pub pose: Pose,
    /// The MSE at that pose, at the sharp σ and γ.
    pub loss: f64,
    /// The render at that pose (sharp), RGBA per pixel, row 0 at the top.
    pub image: Vec<[f32; 4]>,
    /// The point rotations turn about.
    pub centre: DVec3,
    /// One entry per iteration.
    pub log: Vec<PoseLog>,
    /// Iterations run.
    pub iterations: u32,
    /// The first iteration this run ran (after a resume, the checkpoint's + 1).
    pub first_iteration: u32,
    /// Wall time of the iterations (without the final evaluation).
    pub seconds: f64,
}

/// Fits the pose of `mesh` seen from `camera` to `target` (RGBA per pixel, row 0 at the top,
/// the settings' size), from `init`, in `session`: its hooks see the fit after every
/// submission of iterations (every [`PoseFitOptions::log_every`], and at the end of each σ/γ
/// stage); the result's log holds every iteration. The result's loss is against the target of
/// the sharp σ/γ.
// The scene (mesh, camera, lighting), the target, the start and the options are each a
// caller's choice; bundling them would only move the count into a struct.
#[allow(clippy::too_many_arguments)]
pub fn fit_pose<'c>(
    ctx: &'c Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    mut target: PoseTarget<'_>,
    init: &Pose,
    opts: &PoseFitOptions,
    session: Session<'_, PoseFit<'c>>,
) -> Result<PoseFitResult> {
    // Before the schedule is read (PoseFitter::new checks the rest).
    opts.validate()?;
    let (mut stages, first_target) = Stages::new(&mut target, opts.sigma_gamma(0))?;
    let mut fitter = PoseFitter::new(ctx, mesh, camera, lighting, &first_target, init, opts)?;
    let every = opts.log_every;
    let last = opts.last_iteration();
    // The refinement's rule, unless the caller's session has one.
    let stop = session.stop.or(opts.stop_rule());
    let end = session
        .stop(stop)
        .run(&mut fitter, (last, every), |fitter, it| {
            let end = driver::to_next_log(it, every).min(last);
            stages.enter(&mut **fitter, opts.sigma_gamma(it - 1))?;
            Ok(driver::to_stage_end(it, end, |i| opts.sigma_gamma(i)))
        })?;
    let s = &opts.settings;
    stages.finish(&mut *fitter, (s.sigma, s.gamma))?;
    let (loss, image) = fitter.evaluate(s.sigma, s.gamma)?;
    Ok(PoseFitResult {
        pose: fitter.pose()?,
        loss,
        image,
        centre: fitter.centre(),
        log: end.log,
        iterations: end.last,
        first_iteration: end.first,
        seconds: end.seconds,
    })
}

impl LogRow for PoseLog {
    fn iteration(&self) -> u32 {
        self.iteration
    }
    fn loss(&self) -> f64 {
        self.loss
    }
    fn columns(&mut self, c: &mut dyn Columns) {
        c.u32("iteration", &mut self.iteration);
        c.f64("loss", &mut self.loss);
        c.f64("sigma", &mut self.sigma);
        c.f64("gamma", &mut self.gamma);
        let (r, t) = (&mut self.pose.rotation, &mut self.pose.translation);
        c.f64("rotation_x", &mut r.x);
        c.f64("rotation_y", &mut r.y);
        c.f64("rotation_z", &mut r.z);
        c.f64("translation_x", &mut t.x);
        c.f64("translation_y", &mut t.y);
        c.f64("translation_z", &mut t.z);
        c.f64("seconds", &mut self.seconds);
    }
}

/// A pose fit in a session: a row per iteration, its state the pose and Adam's moments (in
/// f64). The σ/γ stage follows from the iteration, so a fit resumed from it ends bit for bit
/// as the fit that never stopped.
impl Trainee for PoseFit<'_> {
    type Row = PoseLog;
    const KIND: FitKind = FitKind::Pose;

    fn rows(
        &mut self,
        _ctx: &Context,
        first: u32,
        last: u32,
        _entries: u64,
        seconds: f64,
    ) -> Result<Vec<PoseLog>> {
        self.log(first, last, seconds)
    }

    fn save_state(&self, _ctx: &Context, w: &mut Writer) -> Result<()> {
        write_f64_state(w, &self.read_state()?);
        Ok(())
    }

    fn restore_state(&mut self, _ctx: &Context, r: &mut Reader<'_>) -> Result<()> {
        let [params, m, v] = read_f64_state(r)?;
        self.write_state([&params, &m, &v])
    }
}

impl PoseFit<'_> {
    /// The fingerprint of a fit's inputs that a checkpoint of it must carry: the mesh with its
    /// colours, the camera, the lighting, the (first) target, the start and every option (the
    /// iteration count among them: it spreads the σ/γ schedule).
    pub fn fingerprint(
        mesh: &Mesh,
        camera: &Camera,
        lighting: &Lighting,
        target: &[[f32; 4]],
        init: &Pose,
        opts: &PoseFitOptions,
    ) -> u64 {
        let mut f = Fingerprint::default();
        f.add_pod(&mesh.positions).add_pod(&mesh.faces);
        f.add_pod(&[mesh.texture_res]).add_pod(&mesh.textures);
        if let Some(c) = &mesh.vertex_colors {
            f.add_pod(c);
        }
        f.add_pod(target);
        f.add(format!("{camera:?} {lighting:?} {init:?} {opts:?}").as_bytes());
        f.value()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::{Lcg, assert_grad_matches_fd};

    fn random_vec(rng: &mut Lcg, scale: f64) -> DVec3 {
        DVec3::new(
            rng.range(-scale, scale),
            rng.range(-scale, scale),
            rng.range(-scale, scale),
        )
    }

    #[test]
    fn rodrigues_matches_glam_quaternions_and_is_a_rotation() {
        let mut rng = Lcg(3);
        for scale in [1e-9, 1e-4, 0.5, 3.0] {
            for _ in 0..20 {
                let w = random_vec(&mut rng, scale);
                let r = rotation_matrix(w);
                let q = DMat3::from_quat(DQuat::from_scaled_axis(w));
                assert!(r.abs_diff_eq(q, 1e-14), "{w}");
                assert!((r.transpose() * r).abs_diff_eq(DMat3::IDENTITY, 1e-14));
                assert!((r.determinant() - 1.0).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn left_jacobian_is_the_derivative_of_the_exponential() {
        // exp([ω + h e_k]×) exp([ω]×)ᵀ ≈ I + h [J_l e_k]×, by central differences.
        let mut rng = Lcg(5);
        for scale in [1e-5, 0.3, 2.5] {
            let w = random_vec(&mut rng, scale);
            let j = left_jacobian(w);
            let h = 1e-6;
            for k in 0..3 {
                let e = DVec3::AXES[k] * h;
                let d = (rotation_matrix(w + e) - rotation_matrix(w - e))
                    * rotation_matrix(w).transpose()
                    * (0.5 / h);
                // d is skew: [a]× with a = J_l e_k.
                let a = DVec3::new(d.y_axis.z, d.z_axis.x, d.x_axis.y);
                assert!(a.abs_diff_eq(j.col(k), 1e-8), "ω {w}: {a} vs {}", j.col(k));
            }
        }
    }

    #[test]
    fn pose_gradient_is_the_gradient_of_a_linear_function_of_the_posed_points() {
        // L = Σ_i a_i · p'_i: dL/dp'_i = a_i, and dL/d(ω, t) by central differences.
        let mut rng = Lcg(9);
        let rest: Vec<DVec3> = (0..7).map(|_| random_vec(&mut rng, 1.0)).collect();
        let a: Vec<[f64; 3]> = (0..7)
            .map(|_| random_vec(&mut rng, 1.0).to_array())
            .collect();
        let centre = centroid(&rest);
        for scale in [1e-6, 0.7, 2.9] {
            let pose = Pose {
                rotation: random_vec(&mut rng, scale),
                translation: random_vec(&mut rng, 0.3),
            };
            let analytic = pose_gradient(&rest, centre, &pose, &a);
            assert_grad_matches_fd(&pose.to_array(), &analytic, 1e-8, |x| {
                let moved = Pose::from_array(x.try_into().unwrap()).apply(&rest, centre);
                moved
                    .iter()
                    .zip(&a)
                    .map(|(p, g)| p.dot(DVec3::from(*g)))
                    .sum()
            });
        }
    }

    #[test]
    fn rotation_distance_is_the_geodesic_angle() {
        let a = DVec3::new(0.3, -0.2, 0.5);
        let axis = DVec3::new(1.0, 2.0, -0.5).normalize();
        for angle in [0.0, 1e-7, 0.4, 2.0, std::f64::consts::PI] {
            // b = a followed (on the right) by a turn of `angle`.
            let qb = DQuat::from_scaled_axis(a) * DQuat::from_axis_angle(axis, angle);
            let b = qb.to_scaled_axis();
            let d = rotation_distance(a, b);
            assert!((d - angle).abs() < 1e-12, "{angle}: {d}");
            assert!((rotation_distance(b, a) - angle).abs() < 1e-12);
        }
    }

    #[test]
    fn schedule_is_geometric_in_stages_and_ends_sharp() {
        let s = Schedule {
            sigma_start: 1e-2,
            gamma_start: 1e-1,
            stages: 3,
        };
        let sharp = (1e-5, 1e-4);
        let close = |a: (f64, f64), b: (f64, f64)| {
            (a.0 / b.0 - 1.0).abs() < 1e-12 && (a.1 / b.1 - 1.0).abs() < 1e-12
        };
        assert!(close(s.at(0, 9, sharp), (1e-2, 1e-1)));
        assert!(close(s.at(2, 9, sharp), (1e-2, 1e-1)));
        assert!(close(
            s.at(3, 9, sharp),
            (10f64.powf(-3.5), 10f64.powf(-2.5))
        ));
        assert!(close(s.at(6, 9, sharp), sharp));
        assert!(close(s.at(8, 9, sharp), sharp));
        let one = Schedule { stages: 1, ..s };
        assert!(close(one.at(8, 9, sharp), (1e-2, 1e-1)));
        let opts = PoseFitOptions {
            iterations: 5,
            lr_final: 0.01,
            schedule: None,
            ..PoseFitOptions::default()
        };
        assert!(close(opts.sigma_gamma(0), (1e-5, 1e-4)));
        assert!((opts.lr_factor(0) - 1.0).abs() < 1e-15);
        assert!((opts.lr_factor(2) - 0.1).abs() < 1e-15);
        assert!((opts.lr_factor(4) - 0.01).abs() < 1e-15);
    }
}
