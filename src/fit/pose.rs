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
//!    t at another); [`SceneLight`]: the mesh lit again with its turned normals (SoftRas
//!    lights in world space before projection).
//! 2. The guarded tiled forward (face setup, count, the gate's check against the capacity,
//!    then gated: sort, fine pass), [`ImageMse`] (loss and dL/d(image)), the tiled backward.
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

use std::time::Instant;

use glam::{DMat3, DQuat, DVec3};

use bytemuck::{Pod, Zeroable};

use super::ImageMse;
use super::adam::{Adam, AdamOptions};
use super::checkpoint::{
    Checkpoint, Fingerprint, FitKind, Reader, Writer, check_resume, check_state, read_log,
    write_log,
};
use super::driver::{self, Fit, Fitter};
use super::max_entry_capacity;
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::GradOut;
use crate::gpu::gate::IterationGate;
use crate::gpu::groups;
use crate::gpu::{Buffer, Context, Kernel, MemoryKind, Recorder, specs};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::backward::GradBuffers;
use crate::raster::gpu::{GpuScene, Method, Renderer};
use crate::raster::light::SceneLight;
use crate::raster::settings::{ColorMode, RasterSettings};

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

/// Everything settable about a pose fit.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseFitOptions {
    /// Iterations.
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
        crate::raster::fine::check_tile_size(self.tile)?;
        self.settings.validate()?;
        Ok(())
    }

    /// σ and γ of iteration `it` (0-based).
    pub fn sigma_gamma(&self, it: u32) -> (f64, f64) {
        let sharp = (self.settings.sigma, self.settings.gamma);
        match &self.schedule {
            Some(s) => s.at(it, self.iterations, sharp),
            None => sharp,
        }
    }

    /// The learning-rate factor of iteration `it` (0-based): `lr_final^(it / (N − 1))`.
    pub fn lr_factor(&self, it: u32) -> f64 {
        if self.iterations <= 1 {
            return 1.0;
        }
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

/// One evaluation of the loss and its gradient at a pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Evaluation {
    /// The image MSE (GPU, f32).
    pub loss: f64,
    /// dL/d(ω, t).
    pub gradient: [f64; 6],
}

/// One mesh, one camera and one target on the GPU, ready to evaluate the loss and its pose
/// gradient at any pose and σ/γ (see the [module docs](self) for the stages).
pub struct PoseProblem {
    renderer: Renderer,
    scene: GpuScene,
    mse: ImageMse,
    target: Buffer,
    /// Host-visible staging of the posed positions, then the lit colours (copied into the
    /// scene's buffers by the first submission of each evaluation).
    staging: Buffer,
    /// Bytes of positions at the start of `staging`, and of colours after them.
    position_bytes: u64,
    color_bytes: u64,
    grads: Option<GradBuffers>,
    rest: Vec<DVec3>,
    centre: DVec3,
    tile: u32,
}

impl PoseProblem {
    /// Uploads `mesh` (at rest), `camera`, `lighting` and `target` (RGBA per pixel, row 0 at
    /// the top, `settings.width × settings.height`).
    pub fn new(
        ctx: &Context,
        mesh: &Mesh,
        camera: &Camera,
        lighting: &Lighting,
        target: &[[f32; 4]],
        settings: &RasterSettings,
        tile: u32,
    ) -> Result<Self> {
        crate::raster::fine::check_tile_size(tile)?;
        mesh.validate()?;
        settings.validate()?;
        check_target(target, settings)?;
        let renderer = Renderer::new(ctx)?;
        let scene =
            renderer.prepare(ctx, mesh, std::slice::from_ref(camera), lighting, settings)?;
        let rest = scene.host_meshes()[0].positions.clone();
        let position_bytes = 12 * rest.len() as u64;
        // As `GpuScene::colors` holds them: 4 floats per colour.
        let color_bytes = 16
            * match settings.color_mode {
                ColorMode::Surface => mesh.textures.len() as u64,
                ColorMode::Vertex => rest.len() as u64,
            };
        let staging = ctx.create_buffer(
            "pose staging",
            position_bytes + color_bytes,
            MemoryKind::Upload,
        )?;
        Ok(Self {
            mse: ImageMse::new(ctx, 1, settings.width, settings.height)?,
            target: ctx.upload_buffer("pose target", target)?,
            staging,
            position_bytes,
            color_bytes,
            renderer,
            scene,
            grads: None,
            centre: centroid(&rest),
            rest,
            tile,
        })
    }

    /// Replaces the target (same size, finite).
    pub fn set_target(&mut self, ctx: &Context, target: &[[f32; 4]]) -> Result<()> {
        check_target(target, self.scene.settings())?;
        ctx.write_buffer(&self.target, 0, target)
    }

    /// The point rotations turn about (the rest mesh's vertex centroid).
    pub fn centre(&self) -> DVec3 {
        self.centre
    }

    /// Renders the mesh at `pose` with σ and γ, and returns the MSE against the target and
    /// dL/d(ω, t). The image stays on the GPU for [`PoseProblem::read_image`].
    pub fn evaluate(
        &mut self,
        ctx: &Context,
        pose: &Pose,
        sigma: f64,
        gamma: f64,
    ) -> Result<Evaluation> {
        if !pose.is_finite() {
            return Err(Error::Input(format!("the pose {pose:?} is not finite")));
        }
        self.set_pose(pose)?;
        let scene = &mut self.scene;
        scene.set_blur(sigma, gamma)?;
        let (renderer, tile) = (&self.renderer, self.tile);
        let (staging, split, colors) = (&self.staging, self.position_bytes, self.color_bytes);
        ctx.submit_and_wait(|rec| {
            rec.copy(staging, 0, scene.positions(), 0, split);
            rec.copy(staging, split, scene.colors(), 0, colors);
            Ok(())
        })?;
        // The exact-sized tiled forward (its count is read back: the host round trip of this
        // loop is the pose chain's anyway).
        let binned = renderer.run(ctx, scene, Method::Tiled { tile })?;
        let scene = binned.scene();
        let entries = scene.binned_entries();
        if self
            .grads
            .as_ref()
            .is_none_or(|g| g.entry_capacity() < entries)
        {
            // Drop the old buffers before making the larger ones.
            self.grads = None;
            self.grads = Some(GradBuffers::new(ctx, scene, Method::Tiled { tile })?);
        }
        let gb = self.grads.as_ref().expect("made above");
        let io = gb.io();
        let kernels = renderer.grad_kernels();
        ctx.submit_and_wait(|rec| {
            self.mse.record(
                rec,
                scene.output().whole(),
                self.target.whole(),
                Some(GradOut::write(io.upstream)),
            )?;
            kernels.record(rec, &binned, gb, &io)
        })?;
        let loss = f64::from(self.mse.read_loss(ctx)?);
        let g = kernels.finish(ctx, scene, gb, &io, false)?;
        Ok(Evaluation {
            loss,
            gradient: pose_gradient(&self.rest, self.centre, pose, &g.positions),
        })
    }

    /// The last evaluation's image: RGBA per pixel, row 0 at the top.
    pub fn read_image(&self, ctx: &Context) -> Result<Vec<[f32; 4]>> {
        let s = self.scene.settings();
        ctx.read_buffer(self.scene.output(), 0, (s.width * s.height) as usize)
    }

    /// Uploads the posed positions and the colours lit with the posed normals, and keeps the
    /// f64 mesh the backward's host share reads in step with what the GPU renders.
    fn set_pose(&mut self, pose: &Pose) -> Result<()> {
        let posed: Vec<[f32; 3]> = pose
            .apply(&self.rest, self.centre)
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect();
        let colors = self.scene.relight(0, &posed)?;
        let (split, color_bytes) = (self.position_bytes as usize, self.color_bytes as usize);
        let bytes = self
            .staging
            .mapped_mut()
            .ok_or_else(|| Error::Limit("upload memory is not host-mapped".into()))?;
        let (p, c) = (
            bytemuck::cast_slice::<_, u8>(&posed),
            bytemuck::cast_slice::<_, u8>(&colors),
        );
        if p.len() != split || c.len() != color_bytes {
            return Err(Error::Input(format!(
                "pose staging: {} position and {} colour bytes, expected {split} and \
                 {color_bytes}",
                p.len(),
                c.len(),
            )));
        }
        bytes[..split].copy_from_slice(p);
        bytes[split..split + c.len()].copy_from_slice(c);
        Ok(())
    }
}

impl Fit for PoseFit<'_> {
    const NAME: &'static str = "pose fit";

    fn last_iteration(&self) -> u32 {
        self.opts.iterations
    }

    /// The pose and its lighting, then the guarded forward with the rest gated on the count:
    /// the MSE, the backward, the lighting's backward, the pose gradient (and the log row) and
    /// the two Adam steps.
    fn record_iteration(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        _row: u32,
    ) -> Result<()> {
        let o = &self.opts;
        let (sigma, gamma) = o.sigma_gamma(it - 1);
        self.scene.set_blur(sigma, gamma)?;
        let rot = o.adam(it - 1);
        self.adam_rotation.set_options(rot)?;
        self.adam_translation.set_options(AdamOptions {
            lr: o.lr_translation * o.lr_factor(it - 1),
            ..rot
        })?;
        self.record_pose(rec)?;
        let ti = 4 * u64::from(self.push.translation_at);
        let push = PosePush {
            log_index: it - 1,
            ..self.push
        };
        let Self {
            scene,
            renderer,
            mse,
            target,
            grads,
            light,
            grad,
            params,
            d_params,
            d_base,
            rest,
            log,
            adam_rotation,
            adam_translation,
            ..
        } = self;
        renderer.record_forward_guarded(rec, scene, gate, it, |rec, binned| {
            let scene = binned.scene();
            let io = grads.io();
            rec.pass("image loss", |rec| {
                mse.record(
                    rec,
                    scene.output().whole(),
                    target.whole(),
                    Some(GradOut::write(io.upstream)),
                )
            })?;
            renderer.grad_kernels().record(rec, &binned, grads, &io)?;
            rec.pass("lighting backward", |rec| {
                light.record_backward(
                    rec,
                    scene.positions().whole(),
                    scene.position_layout(),
                    io.colors,
                    d_base.whole(),
                    io.positions,
                )
            })?;
            rec.pass("pose gradient", |rec| {
                rec.dispatch(
                    grad,
                    &specs::PoseGradBindings {
                        params: params.whole(),
                        rest: rest.whole(),
                        d_posed: io.positions,
                        d_params: d_params.whole(),
                        loss: mse.loss_buffer().whole(),
                        log: log.whole(),
                    }
                    .for_kernel(grad)?,
                    &push,
                    1,
                )
            })?;
            rec.pass("adam", |rec| {
                adam_rotation.record_step(rec, params.range(0, 12), d_params.range(0, 12), it)?;
                adam_translation.record_step(rec, params.range(ti, 12), d_params.range(ti, 12), it)
            })
        })
    }

    fn capacity(&self) -> u64 {
        self.capacity
    }

    fn grow(&mut self, _: &Context, total: u64) -> Result<()> {
        self.resize(total)
    }
}

/// Push constants of `pose_apply.comp` and `pose_grad.comp`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct PosePush {
    centre: [f32; 3],
    vertex_count: u32,
    translation_at: u32,
    log_index: u32,
    pad: [u32; 2],
}

/// A pose fit's GPU state: the scene with its guarded bins, the lighting, the loss, the pose's
/// parameters and their two Adam optimizers. Every iteration is recorded with no read-back (see
/// the [module docs](self)), as many per submission as asked ([`PoseFitter`] runs them).
pub struct PoseFit<'c> {
    ctx: &'c Context,
    opts: PoseFitOptions,
    renderer: Renderer,
    scene: GpuScene,
    light: SceneLight,
    mse: ImageMse,
    target: Buffer,
    grads: GradBuffers,
    apply: Kernel,
    grad: Kernel,
    /// The rest positions, packed xyz.
    rest: Buffer,
    /// ω at floats [0, 3), t at [`PosePush::translation_at`, + 3): two bindable ranges.
    params: Buffer,
    d_params: Buffer,
    /// dL/d(unlit colour), which the pose does not need (the lighting's backward writes it).
    d_base: Buffer,
    adam_rotation: Adam,
    adam_translation: Adam,
    /// Two vec4 per iteration of the fit: the loss and ω, then t.
    log: Buffer,
    push: PosePush,
    capacity: u64,
    max_capacity: u64,
}

/// A pose fit ready to run iterations ([`Fitter::run`]).
pub type PoseFitter<'c> = Fitter<'c, PoseFit<'c>>;

impl<'c> Fitter<'c, PoseFit<'c>> {
    /// The fit of `mesh`'s pose seen from `camera` to `target` from `init` (see
    /// [`fit_pose`]): uploads everything, counts the entries of the first pose once and sizes
    /// the guarded bins with the mesh fit's headroom.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        ctx: &'c Context,
        mesh: &Mesh,
        camera: &Camera,
        lighting: &Lighting,
        target: &[[f32; 4]],
        init: &Pose,
        opts: &PoseFitOptions,
    ) -> Result<Self> {
        opts.validate()?;
        mesh.validate()?;
        check_target(target, &opts.settings)?;
        if !init.is_finite() {
            return Err(Error::Input(format!(
                "the initial pose {init:?} is not finite"
            )));
        }
        let renderer = Renderer::new(ctx)?;
        let mut scene = renderer.prepare(
            ctx,
            mesh,
            std::slice::from_ref(camera),
            lighting,
            &opts.settings,
        )?;
        // Sized for real once the first pose's entries are counted (below).
        renderer.reserve_guarded(ctx, &mut scene, opts.tile, 1)?;
        let light = SceneLight::new(ctx, &scene)?;
        let rest_f64 = &scene.host_meshes()[0].positions;
        let centre = centroid(rest_f64);
        let rest: Vec<f32> = mesh.positions.as_flattened().to_vec();
        let translation_at = (ctx.info().buffer_alignment() / 4).max(4);
        let push = PosePush {
            centre: centre.to_array().map(|c| c as f32),
            vertex_count: mesh.vertex_count() as u32,
            translation_at: translation_at as u32,
            log_index: 0,
            pad: [0; 2],
        };
        let param_floats = (translation_at + 3) as usize;
        let mut p0 = vec![0f32; param_floats];
        let a = init.to_array();
        for k in 0..3 {
            p0[k] = a[k] as f32;
            p0[translation_at as usize + k] = a[3 + k] as f32;
        }
        let first = opts.adam(0);
        let max_capacity = max_entry_capacity(ctx, &renderer, &scene);
        let mut fit = PoseFit {
            ctx,
            mse: ImageMse::new(ctx, 1, opts.settings.width, opts.settings.height)?,
            target: ctx.upload_buffer("pose target", target)?,
            grads: GradBuffers::with_entry_capacity(
                ctx,
                &scene,
                Method::Tiled { tile: opts.tile },
                1,
            )?,
            apply: Kernel::new(ctx, &specs::POSE_APPLY)?,
            grad: Kernel::new(ctx, &specs::POSE_GRAD)?,
            rest: ctx.upload_buffer("pose rest positions", &rest)?,
            params: ctx.upload_buffer("pose parameters", &p0)?,
            d_params: ctx.upload_buffer("pose gradient", &vec![0f32; param_floats])?,
            d_base: ctx.create_buffer(
                "pose unlit colour gradients",
                12 * light.color_count().max(1),
                MemoryKind::Device,
            )?,
            adam_rotation: Adam::new(ctx, 3, first)?,
            adam_translation: Adam::new(
                ctx,
                3,
                AdamOptions {
                    lr: opts.lr_translation * opts.lr_factor(0),
                    ..first
                },
            )?,
            log: ctx.create_buffer(
                "pose log",
                32 * u64::from(opts.iterations),
                MemoryKind::Device,
            )?,
            push,
            capacity: 1,
            max_capacity,
            light,
            opts: opts.clone(),
            renderer,
            scene,
        };
        let (sigma, gamma) = opts.sigma_gamma(0);
        fit.fit_capacity(sigma, gamma)?;
        Fitter::from_fit(ctx, fit)
    }

    /// The MSE and the render at the current pose with σ and γ (no step), re-run until the
    /// entries fit.
    pub fn evaluate(&mut self, sigma: f64, gamma: f64) -> Result<(f64, Vec<[f32; 4]>)> {
        self.scene.set_blur(sigma, gamma)?;
        self.submit_guarded(|fit, rec, gate| {
            fit.record_pose(rec)?;
            let PoseFit {
                scene,
                renderer,
                mse,
                target,
                ..
            } = fit;
            renderer.record_forward_guarded(rec, scene, gate, 0, |rec, binned| {
                let scene = binned.scene();
                mse.record(rec, scene.output().whole(), target.whole(), None)
            })
        })?;
        let s = &self.opts.settings;
        Ok((
            f64::from(self.mse.read_loss(self.ctx)?),
            self.ctx
                .read_buffer(self.scene.output(), 0, (s.width * s.height) as usize)?,
        ))
    }
}

impl PoseFit<'_> {
    /// Sizes the guarded bins for the pose now at σ and γ: one counting submission, then the
    /// count with the headroom. The fit does it at the start of every σ/γ stage (a blurry
    /// stage bins several times the entries of a sharp one, and the backward's texel
    /// partials, cleared over the whole capacity every iteration, are the larger cost at
    /// these image sizes); it changes no result.
    pub fn fit_capacity(&mut self, sigma: f64, gamma: f64) -> Result<()> {
        self.scene.set_blur(sigma, gamma)?;
        self.ctx.submit_and_wait(|rec| self.record_pose(rec))?;
        let total = self
            .renderer
            .count_entries(self.ctx, &mut self.scene, self.opts.tile)?;
        self.resize(total)
    }

    /// Records the posed positions and their lit colours into the scene.
    fn record_pose(&self, rec: &mut Recorder<'_>) -> Result<()> {
        let nv = u64::from(self.push.vertex_count);
        rec.pass("pose", |rec| {
            rec.dispatch(
                &self.apply,
                &specs::PoseApplyBindings {
                    params: self.params.whole(),
                    rest: self.rest.whole(),
                    posed: self.scene.positions().whole(),
                }
                .for_kernel(&self.apply)?,
                &self.push,
                groups(nv, 64)?,
            )
        })?;
        rec.pass("lighting", |rec| {
            self.light.record_forward(
                rec,
                self.scene.positions().whole(),
                self.scene.position_layout(),
                self.scene.colors().whole(),
            )
        })
    }

    /// Sizes the bins and the backward's buffers for `total` entries with the headroom.
    fn resize(&mut self, total: u64) -> Result<()> {
        let capacity = super::with_headroom(
            self.ctx,
            "a pose fit's binning (with the backward's partials)",
            total,
            self.max_capacity,
            "use larger tiles or a smaller σ",
        )?;
        self.grads = super::reserve_guarded(
            self.ctx,
            &self.renderer,
            &mut self.scene,
            self.opts.tile,
            capacity,
            false,
        )?;
        self.capacity = capacity;
        Ok(())
    }

    /// The log of iterations `first ..= last` (their losses and poses), read back.
    fn read_log(&self, first: u32, last: u32, seconds: f64) -> Result<Vec<PoseLog>> {
        let rows: Vec<[f32; 4]> = self.ctx.read_buffer(
            &self.log,
            32 * u64::from(first - 1),
            2 * (last - first + 1) as usize,
        )?;
        Ok(rows
            .chunks_exact(2)
            .zip(first..=last)
            .map(|(r, it)| {
                let (sigma, gamma) = self.opts.sigma_gamma(it - 1);
                PoseLog {
                    iteration: it,
                    loss: f64::from(r[0][0]),
                    sigma,
                    gamma,
                    pose: Pose::from_array(
                        [r[0][1], r[0][2], r[0][3], r[1][0], r[1][1], r[1][2]].map(f64::from),
                    ),
                    seconds,
                }
            })
            .collect())
    }

    /// The parameters and Adam's moments now (each `[rotation; translation]`).
    fn read_state(&self) -> Result<[[f64; 6]; 3]> {
        let ti = 4 * u64::from(self.push.translation_at);
        let read = |b: &Buffer, at: u64| -> Result<Vec<f32>> { self.ctx.read_buffer(b, at, 3) };
        let (mr, vr) = self.adam_rotation.moments();
        let (mt, vt) = self.adam_translation.moments();
        let join = |a: Vec<f32>, b: Vec<f32>| -> [f64; 6] {
            std::array::from_fn(|k| f64::from(if k < 3 { a[k] } else { b[k - 3] }))
        };
        Ok([
            join(read(&self.params, 0)?, read(&self.params, ti)?),
            join(read(mr, 0)?, read(mt, 0)?),
            join(read(vr, 0)?, read(vt, 0)?),
        ])
    }

    /// Sets the parameters and Adam's moments (each `[rotation; translation]`).
    fn write_state(&self, state: [&[f64; 6]; 3]) -> Result<()> {
        let ti = 4 * u64::from(self.push.translation_at);
        let f = |a: &[f64; 6], k: usize| -> [f32; 3] { std::array::from_fn(|i| a[k + i] as f32) };
        let (mr, vr) = self.adam_rotation.moments();
        let (mt, vt) = self.adam_translation.moments();
        self.ctx.write_buffer(&self.params, 0, &f(state[0], 0))?;
        self.ctx.write_buffer(&self.params, ti, &f(state[0], 3))?;
        self.ctx.write_buffer(mr, 0, &f(state[1], 0))?;
        self.ctx.write_buffer(mt, 0, &f(state[1], 3))?;
        self.ctx.write_buffer(vr, 0, &f(state[2], 0))?;
        self.ctx.write_buffer(vt, 0, &f(state[2], 3))
    }

    /// Replaces the target (same size, finite).
    pub fn set_target(&mut self, target: &[[f32; 4]]) -> Result<()> {
        check_target(target, &self.opts.settings)?;
        self.ctx.write_buffer(&self.target, 0, target)
    }

    /// dL/d(ω, t) of the last iteration that ran (the gradient its Adam steps took).
    pub fn gradient(&self) -> Result<[f64; 6]> {
        let ti = 4 * u64::from(self.push.translation_at);
        let r: Vec<f32> = self.ctx.read_buffer(&self.d_params, 0, 3)?;
        let t: Vec<f32> = self.ctx.read_buffer(&self.d_params, ti, 3)?;
        Ok(std::array::from_fn(|k| {
            f64::from(if k < 3 { r[k] } else { t[k - 3] })
        }))
    }

    /// The log of iterations `first ..= last` that ran: each one's loss, σ, γ and the pose it
    /// evaluated (`seconds` as given).
    pub fn log(&self, first: u32, last: u32, seconds: f64) -> Result<Vec<PoseLog>> {
        if first == 0 || first > last || last > self.opts.iterations {
            return Err(Error::Misuse(format!(
                "pose fit: the log of {first}..={last} of 1..={}",
                self.opts.iterations
            )));
        }
        self.read_log(first, last, seconds)
    }

    /// The pose now.
    pub fn pose(&self) -> Result<Pose> {
        Ok(Pose::from_array(self.read_state()?[0]))
    }

    /// Entries the bins and the backward's partials hold now.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// The point rotations turn about.
    pub fn centre(&self) -> DVec3 {
        DVec3::from(self.push.centre.map(f64::from))
    }
}

/// [`Error::Input`] unless `target` has one finite RGBA value per pixel of `settings`.
pub(crate) fn check_target(target: &[[f32; 4]], settings: &RasterSettings) -> Result<()> {
    let px = settings.width as usize * settings.height as usize;
    if target.len() != px {
        return Err(Error::Input(format!(
            "the target has {} pixels; {}x{} needs {px}",
            target.len(),
            settings.width,
            settings.height
        )));
    }
    if let Some(i) = target.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::Input(format!(
            "the target is not finite at pixel ({}, {})",
            i % settings.width as usize,
            i / settings.width as usize
        )));
    }
    Ok(())
}

/// What the render is compared with.
pub enum PoseTarget<'a> {
    /// One image for every iteration: a photograph, or any given render (`softvk fit-pose`).
    Fixed(&'a [[f32; 4]]),
    /// An image per (σ, γ), asked for whenever the schedule changes them and for the final
    /// sharp evaluation: for synthetic studies, where the target pose is known and the target
    /// can be rendered with the same σ and γ as the fit (the loss landscape of the talk).
    PerStage(&'a mut dyn FnMut(f64, f64) -> Result<Vec<[f32; 4]>>),
}

/// One logged iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
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
    /// Wall time of the iterations (without the final evaluation).
    pub seconds: f64,
}

/// Fits the pose of `mesh` seen from `camera` to `target` (RGBA per pixel, row 0 at the top,
/// the settings' size), from `init`. `progress` is called after every submission of
/// iterations (every [`PoseFitOptions::log_every`], and at the end of each σ/γ stage) with
/// its last iteration, and may return `false` to stop early; the result's log holds every
/// iteration. The result's loss is against the target of the sharp σ/γ.
// The scene (mesh, camera, lighting), the target, the start and the options are each a
// caller's choice; bundling them would only move the count into a struct.
#[allow(clippy::too_many_arguments)]
pub fn fit_pose(
    ctx: &Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    target: PoseTarget<'_>,
    init: &Pose,
    opts: &PoseFitOptions,
    mut progress: impl FnMut(&PoseLog) -> bool,
) -> Result<PoseFitResult> {
    fit_pose_resumable(
        ctx,
        mesh,
        camera,
        lighting,
        target,
        init,
        opts,
        None,
        |l, _| Ok(progress(l)),
    )
}

/// A pose fit's complete state after an iteration: the pose, Adam's moments (on the host, in
/// f64), the iterations done and the log. The σ/γ stage follows from the iteration, so a fit
/// resumed from it ([`fit_pose_resumable`]) ends bit for bit as the fit that never stopped.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseFitState {
    /// Iterations done.
    pub iteration: u32,
    /// The pose's parameters (axis-angle, translation).
    pub params: [f64; 6],
    /// Adam's first moments.
    pub adam_m: [f64; 6],
    /// Adam's second moments.
    pub adam_v: [f64; 6],
    /// One entry per iteration so far.
    pub log: Vec<PoseLog>,
    /// Seconds the iterations took so far.
    pub seconds: f64,
}

/// An iteration's view of the running pose fit ([`PoseFitSnapshot::state`]: checkpoints).
pub struct PoseFitSnapshot<'a> {
    fitter: &'a PoseFitter<'a>,
    iteration: u32,
    log: &'a [PoseLog],
    seconds: f64,
}

impl PoseFitSnapshot<'_> {
    /// The fit's complete state now (the parameters and moments read from the GPU).
    pub fn state(&self) -> Result<PoseFitState> {
        let [params, adam_m, adam_v] = self.fitter.read_state()?;
        Ok(PoseFitState {
            iteration: self.iteration,
            params,
            adam_m,
            adam_v,
            log: self.log.to_vec(),
            seconds: self.seconds,
        })
    }
}

impl PoseFitState {
    /// The fingerprint of a fit's inputs that a checkpoint of it must carry: the mesh with its
    /// colours, the camera, the lighting, the target, the start and every option (the
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

    /// As a checkpoint for inputs of `fingerprint`.
    pub fn to_checkpoint(&self, fingerprint: u64) -> Checkpoint {
        let mut w = Writer::default();
        for x in self.params.iter().chain(&self.adam_m).chain(&self.adam_v) {
            w.f64(*x);
        }
        write_log(&mut w, &self.log, |w, l| {
            w.u32(l.iteration);
            for x in [l.loss, l.sigma, l.gamma]
                .into_iter()
                .chain(l.pose.to_array())
                .chain([l.seconds])
            {
                w.f64(x);
            }
        });
        Checkpoint {
            kind: FitKind::Pose,
            fingerprint,
            iteration: self.iteration,
            seconds: self.seconds,
            payload: w.0,
        }
    }

    /// From a checkpoint ([`Checkpoint::read`] checked its kind and inputs).
    pub fn from_checkpoint(c: &Checkpoint) -> Result<Self> {
        let mut r = Reader::new(&c.payload);
        let mut six = || -> Result<[f64; 6]> {
            let mut a = [0.0; 6];
            for x in &mut a {
                *x = r.f64()?;
            }
            Ok(a)
        };
        let (params, adam_m, adam_v) = (six()?, six()?, six()?);
        check_state(&params, &adam_m, &adam_v)?;
        let log = read_log(&mut r, c.iteration, |r| {
            let iteration = r.u32()?;
            let (loss, sigma, gamma) = (r.f64()?, r.f64()?, r.f64()?);
            let mut pose = [0.0; 6];
            for x in &mut pose {
                *x = r.f64()?;
            }
            Ok(PoseLog {
                iteration,
                loss,
                sigma,
                gamma,
                pose: Pose::from_array(pose),
                seconds: r.f64()?,
            })
        })?;
        Ok(Self {
            iteration: c.iteration,
            params,
            adam_m,
            adam_v,
            log,
            seconds: c.seconds,
        })
    }
}

/// [`fit_pose`], optionally from a state a previous fit of the same inputs reached (`resume`:
/// it goes on with iteration `resume.iteration + 1`), with a progress callback that also gets
/// a [`PoseFitSnapshot`] (to checkpoint) and may fail. Resumed, the fit ends bit for bit as the
/// fit that never stopped.
#[allow(clippy::too_many_arguments)]
pub fn fit_pose_resumable(
    ctx: &Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    mut target: PoseTarget<'_>,
    init: &Pose,
    opts: &PoseFitOptions,
    resume: Option<&PoseFitState>,
    mut progress: impl FnMut(&PoseLog, &PoseFitSnapshot<'_>) -> Result<bool>,
) -> Result<PoseFitResult> {
    // Before the schedule is read (PoseFitter::new checks the rest).
    opts.validate()?;
    let mut stage = opts.sigma_gamma(0);
    let first_target = match &mut target {
        PoseTarget::Fixed(t) => t.to_vec(),
        PoseTarget::PerStage(f) => f(stage.0, stage.1)?,
    };
    let mut fitter = PoseFitter::new(ctx, mesh, camera, lighting, &first_target, init, opts)?;
    let mut log = Vec::with_capacity(opts.iterations as usize);
    let start = Instant::now();
    let mut done = 0;
    let mut earlier = 0.0;
    if let Some(state) = resume {
        check_resume(state.iteration, opts.iterations)?;
        fitter.write_state([&state.params, &state.adam_m, &state.adam_v])?;
        log = state.log.clone();
        done = state.iteration;
        earlier = state.seconds;
    }
    let every = opts.log_every;
    let done = fitter.drive(
        done + 1,
        opts.iterations,
        |fitter, it| {
            // Up to the next logged iteration, within one σ/γ stage, in one submission.
            let here = opts.sigma_gamma(it - 1);
            let last = driver::to_next_log(it, every).min(opts.iterations);
            let last = (it..=last)
                .find(|&i| opts.sigma_gamma(i - 1) != here)
                .map_or(last, |end| end - 1);
            if here != stage {
                if let PoseTarget::PerStage(f) = &mut target {
                    fitter.set_target(&f(here.0, here.1)?)?;
                }
                fitter.fit_capacity(here.0, here.1)?;
            }
            stage = here;
            Ok(last)
        },
        |fitter, first, last| {
            let seconds = earlier + start.elapsed().as_secs_f64();
            log.extend(fitter.read_log(first, last, seconds)?);
            let snapshot = PoseFitSnapshot {
                fitter,
                iteration: last,
                log: &log,
                seconds,
            };
            progress(&log[log.len() - 1], &snapshot)
        },
    )?;
    let seconds = earlier + start.elapsed().as_secs_f64();
    let s = &opts.settings;
    if let PoseTarget::PerStage(f) = &mut target
        && (s.sigma, s.gamma) != stage
    {
        fitter.set_target(&f(s.sigma, s.gamma)?)?;
    }
    let (loss, image) = fitter.evaluate(s.sigma, s.gamma)?;
    Ok(PoseFitResult {
        pose: fitter.pose()?,
        loss,
        image,
        centre: fitter.centre(),
        log,
        iterations: done,
        seconds,
    })
}

/// `k` unit quaternions spread evenly over all rotations: the super-Fibonacci spiral (Alexa,
/// "Super-Fibonacci Spirals", CVPR 2022), turned so that its first point is the identity. Written
/// here (a dozen lines) rather than taken from a crate: no maintained Rust crate offers it.
pub fn spread_rotations(k: u32) -> Vec<DQuat> {
    // ψ: the real root of ψ⁴ = ψ + 4 (the paper's second irrational).
    const PSI: f64 = 1.533_751_168_755_204_3;
    let n = f64::from(k);
    let points: Vec<DQuat> = (0..k)
        .map(|i| {
            let s = f64::from(i) + 0.5;
            let (r, big_r) = ((s / n).sqrt(), (1.0 - s / n).sqrt());
            let alpha = std::f64::consts::TAU * s / std::f64::consts::SQRT_2;
            let beta = std::f64::consts::TAU * s / PSI;
            DQuat::from_xyzw(
                r * alpha.sin(),
                r * alpha.cos(),
                big_r * beta.sin(),
                big_r * beta.cos(),
            )
            .normalize()
        })
        .collect();
    let Some(first) = points.first().copied() else {
        return Vec::new();
    };
    // Right-multiplying every point by one rotation moves them rigidly on the sphere.
    points
        .iter()
        .map(|&q| (q * first.inverse()).normalize())
        .collect()
}

/// `k` starting poses: `init`'s rotation composed with [`spread_rotations`] (the first start is
/// `init` itself), each with `init`'s translation.
pub fn spread_starts(init: &Pose, k: u32) -> Vec<Pose> {
    let q = init.quaternion();
    spread_rotations(k)
        .into_iter()
        .enumerate()
        .map(|(i, s)| Pose {
            rotation: if i == 0 {
                init.rotation
            } else {
                (q * s).to_scaled_axis()
            },
            translation: init.translation,
        })
        .collect()
}

/// `k` starts for a multi-start fit chosen by the loss: `candidates` rotations spread over all
/// rotations ([`spread_rotations`], composed with `init`'s; `init`'s translation) are rendered
/// against `target` at the options' sharp σ/γ, and the `k` lowest losses are kept, best first,
/// skipping any candidate within `separation` (radians) of one already kept, so that the starts
/// lie in different basins. With `candidates ≤ k` it is [`spread_starts`].
#[allow(clippy::too_many_arguments)]
pub fn screened_starts(
    ctx: &Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    target: &[[f32; 4]],
    init: &Pose,
    k: u32,
    candidates: u32,
    separation: f64,
    opts: &PoseFitOptions,
) -> Result<Vec<Pose>> {
    if candidates <= k {
        return Ok(spread_starts(init, k));
    }
    let s = &opts.settings;
    let mut problem = PoseProblem::new(ctx, mesh, camera, lighting, target, s, opts.tile)?;
    let mut scored = Vec::with_capacity(candidates as usize);
    for pose in spread_starts(init, candidates) {
        let loss = problem.evaluate(ctx, &pose, s.sigma, s.gamma)?.loss;
        scored.push((loss, pose));
    }
    // Lowest loss first; ties in the spiral's order; NaN last.
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut kept: Vec<Pose> = Vec::with_capacity(k as usize);
    for (_, pose) in &scored {
        if kept.len() == k as usize {
            break;
        }
        if kept
            .iter()
            .all(|p| rotation_distance(p.rotation, pose.rotation) >= separation)
        {
            kept.push(*pose);
        }
    }
    // Fewer than k far enough apart: fill with the next best.
    for (_, pose) in &scored {
        if kept.len() == k as usize {
            break;
        }
        if !kept.contains(pose) {
            kept.push(*pose);
        }
    }
    Ok(kept)
}

/// How one start of a multi-start fit ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartOutcome {
    /// Where it started.
    pub init: Pose,
    /// Where it ended.
    pub pose: Pose,
    /// Its final loss (sharp σ/γ).
    pub loss: f64,
    /// Its wall time.
    pub seconds: f64,
}

/// A finished multi-start fit.
#[derive(Clone, Debug)]
pub struct MultiStartResult {
    /// The fit of the start that ended with the lowest loss.
    pub best: PoseFitResult,
    /// Its index in the starts.
    pub best_start: usize,
    /// Every start that ran, in order.
    pub starts: Vec<StartOutcome>,
}

/// Fits the pose from each of `starts` in turn ([`fit_pose`] with the same options, target and
/// schedule) and keeps the fit that ends with the lowest loss (the first of equals; a
/// non-finite loss never wins). The landscape of a rotation has basins: one start from far
/// away lands in a wrong one, while one of several starts spread over the rotations
/// ([`spread_starts`]) usually begins inside the right one. `progress(start, log)` is
/// [`fit_pose`]'s, with the start's index; `false` stops the start it is in and every later one.
#[allow(clippy::too_many_arguments)]
pub fn fit_pose_multistart(
    ctx: &Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    mut target: PoseTarget<'_>,
    starts: &[Pose],
    opts: &PoseFitOptions,
    mut progress: impl FnMut(usize, &PoseLog) -> bool,
) -> Result<MultiStartResult> {
    if starts.is_empty() {
        return Err(Error::Input("a multi-start pose fit needs a start".into()));
    }
    let mut outcomes = Vec::with_capacity(starts.len());
    let mut best: Option<(usize, PoseFitResult)> = None;
    for (k, init) in starts.iter().enumerate() {
        let here = match &mut target {
            PoseTarget::Fixed(t) => PoseTarget::Fixed(t),
            PoseTarget::PerStage(f) => PoseTarget::PerStage(&mut **f),
        };
        let mut stopped = false;
        let result = fit_pose(ctx, mesh, camera, lighting, here, init, opts, |l| {
            let go_on = progress(k, l);
            stopped |= !go_on;
            go_on
        })?;
        outcomes.push(StartOutcome {
            init: *init,
            pose: result.pose,
            loss: result.loss,
            seconds: result.seconds,
        });
        let better = match &best {
            None => true,
            Some((_, b)) => result.loss < b.loss || !b.loss.is_finite() && result.loss.is_finite(),
        };
        if better {
            best = Some((k, result));
        }
        if stopped {
            break;
        }
    }
    let (best_start, best) = best.expect("at least one start ran");
    Ok(MultiStartResult {
        best,
        best_start,
        starts: outcomes,
    })
}

/// The f64 twin of [`PoseProblem::evaluate`].
pub mod cpu {
    use glam::DVec3;

    use super::{Pose, pose_gradient};
    use crate::camera::Camera;
    use crate::error::Result;
    use crate::fit::silhouette;
    use crate::lighting::Lighting;
    use crate::raster::reference::{MeshF64, render_f64};
    use crate::raster::reference_grad::grad_f64;
    use crate::raster::settings::RasterSettings;

    /// `mesh` (at rest) moved to `pose` about `centre`.
    pub fn posed(mesh: &MeshF64, centre: DVec3, pose: &Pose) -> MeshF64 {
        MeshF64 {
            positions: pose.apply(&mesh.positions, centre),
            ..mesh.clone()
        }
    }

    /// The image MSE of the f64 render at `pose` against `target` (RGBA per pixel).
    pub fn loss(
        mesh: &MeshF64,
        centre: DVec3,
        camera: &Camera,
        lighting: &Lighting,
        settings: &RasterSettings,
        target: &[[f64; 4]],
        pose: &Pose,
    ) -> Result<f64> {
        let image = render_f64(&posed(mesh, centre, pose), camera, lighting, settings)?;
        Ok(silhouette::cpu::mse(&image, target).0)
    }

    /// The MSE and dL/d(ω, t): f64 render, MSE, f64 backward to the posed positions, and the
    /// chain [`pose_gradient`].
    pub fn loss_and_gradient(
        mesh: &MeshF64,
        centre: DVec3,
        camera: &Camera,
        lighting: &Lighting,
        settings: &RasterSettings,
        target: &[[f64; 4]],
        pose: &Pose,
    ) -> Result<(f64, [f64; 6])> {
        let moved = posed(mesh, centre, pose);
        let image = render_f64(&moved, camera, lighting, settings)?;
        let (loss, d_image) = silhouette::cpu::mse(&image, target);
        let g = grad_f64(
            &moved,
            std::slice::from_ref(camera),
            lighting,
            settings,
            &d_image,
        )?;
        Ok((
            loss,
            pose_gradient(&mesh.positions, centre, pose, &g.positions),
        ))
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
