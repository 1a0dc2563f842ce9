//! Non-rigid pose estimation: the joint angles of a skinned articulated mesh
//! ([`Rig`]) that make its render match a target RGBA image, by Adam on the image MSE with the
//! pose fit's σ/γ schedule ([`Schedule`]) — the talk's non-rigid pose estimation.
//!
//! # One iteration
//!
//! [`ArticulatedFitter`] records every iteration into one command buffer with no read-back, as
//! the rigid [`PoseFitter`](super::pose::PoseFitter) does, and [`fit_articulated`] runs
//! [`ArticulatedFitOptions::log_every`] of them per submission (ending one early where the σ/γ
//! stage changes). On the GPU, in f32:
//!
//! 1. `skin_fk.comp`: every bone's transform from the angles (one invocation walking the joint
//!    tree); `skin_apply.comp`: the skinned positions (linear blend skinning, one invocation
//!    per vertex); [`SceneLight`](crate::raster::light::SceneLight): the mesh lit again with its posed normals.
//! 2. The guarded tiled forward, [`BlurredMse`] (loss and dL/d(image) of
//!    render and target blurred alike), the tiled backward.
//! 3. The lighting's backward (dL/dp' through the normals, added to the geometric share),
//!    `skin_grad.comp` (dL/dθ, one workgroup per joint in a fixed order, which also logs the
//!    iteration's loss and angles) and one Adam step.
//!
//! The chain from dL/dp' to dL/dθ is [`Rig::angle_gradient`] (see [`super::rig`]); [`cpu`] is
//! the f64 twin of a whole evaluation, which tests check against central differences and the
//! GPU iteration against.
//!
//! Not here (yet): checkpoints (the rigid pose fit has them), several starts, a root pose
//! fitted with the joints (give the camera instead).

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::adam::{Adam, AdamOptions};
use super::blur::{BlurredMse, MAX_BLUR_STD};
use super::checkpoint::{Fingerprint, FitKind, Reader, Writer, restore_adam, save_adam};
use super::driver::{self, Fitter};
use super::log::Columns;
use super::pose::{PoseTarget, Schedule};
use super::posed::{self, PoseModel, PosedFit, PosedView, Stages};
use super::rig::{Rig, bone_of};
use super::session::{LogRow, Session, Trainee};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::gate::IterationGate;
use crate::gpu::groups;
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::raster::settings::RasterSettings;
use crate::specs;

/// Everything settable about an articulated fit.
#[derive(Clone, Debug, PartialEq)]
pub struct ArticulatedFitOptions {
    /// Iterations.
    pub iterations: u32,
    /// Adam's learning rate of the angles (radians per step, about).
    pub lr: f64,
    /// Adam's β1, β2.
    pub betas: (f64, f64),
    /// The learning rate decays geometrically to this factor of its start at the last step.
    pub lr_final: f64,
    /// The σ/γ schedule; `None`: every iteration at the settings' (sharp) σ and γ.
    pub schedule: Option<Schedule>,
    /// The blur of the image loss from wide to none ([`BlurSchedule`]); `None`: the plain MSE.
    pub blur: Option<BlurSchedule>,
    /// Rasterization: size, the sharp σ and γ (the schedule's end), colours...
    pub settings: RasterSettings,
    /// Tile edge of the tiled passes.
    pub tile: u32,
    /// Iterations per submission (the fit reads its log and calls back after each). A
    /// submission also ends where the σ/γ stage changes.
    pub log_every: u32,
}

/// The blur of the image loss ([`BlurredMse`]): `stages` equal stages from `start` pixels
/// down to none, linearly (stage k of S blurs `start (S − 1 − k)/(S − 1)`; the last is sharp).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlurSchedule {
    /// The first stage's standard deviation, in pixels.
    pub start: f64,
    /// Stages, at least 1 (1: every iteration at `start`).
    pub stages: u32,
}

impl Default for BlurSchedule {
    /// Chosen by `examples/articulated_study.rs` (RESULTS.md, "Non-rigid pose").
    fn default() -> Self {
        Self {
            start: 2.0,
            stages: 4,
        }
    }
}

impl BlurSchedule {
    /// The blur of iteration `it` (0-based) of `iterations`, in pixels.
    pub fn at(&self, it: u32, iterations: u32) -> f64 {
        let stages = self.stages.max(1);
        if stages == 1 {
            return self.start;
        }
        let stage = (u64::from(it) * u64::from(stages) / u64::from(iterations.max(1)))
            .min(u64::from(stages - 1));
        self.start * f64::from(stages - 1 - stage as u32) / f64::from(stages - 1)
    }

    /// [`Error::Input`] unless the start is in [0, [`MAX_BLUR_STD`]] and stages ≥ 1.
    pub fn validate(&self) -> Result<()> {
        if !(self.start.is_finite() && (0.0..=MAX_BLUR_STD).contains(&self.start))
            || self.stages == 0
        {
            return Err(Error::Input(format!(
                "blur schedule {self:?}: the start must be in [0, {MAX_BLUR_STD}] pixels, \
                 stages ≥ 1"
            )));
        }
        Ok(())
    }
}

impl Default for ArticulatedFitOptions {
    /// The defaults for a fixed target image ([`PoseTarget::Fixed`]), chosen by
    /// `examples/articulated_study.rs` on [`Rig::figure`] (RESULTS.md, "Non-rigid pose"); see
    /// [`ArticulatedFitOptions::for_rendered_target`] for a target rendered per stage.
    fn default() -> Self {
        Self {
            iterations: 240,
            lr: 0.05,
            betas: (0.9, 0.999),
            lr_final: 0.1,
            schedule: Some(Schedule {
                sigma_start: 1e-4,
                gamma_start: 1e-4,
                stages: 4,
            }),
            blur: Some(BlurSchedule::default()),
            settings: RasterSettings {
                width: 64,
                height: 64,
                ..RasterSettings::default()
            },
            tile: 8,
            log_every: 10,
        }
    }
}

impl ArticulatedFitOptions {
    /// The defaults for a target rendered again at every stage's σ/γ
    /// ([`PoseTarget::PerStage`]: the figure at known angles, as `fit-articulated
    /// --target-angles` does): the schedule starts at σ = γ = 1e-2, a hundred times softer than
    /// [`Default`]'s, which is chosen for a fixed image (a photograph cannot be softened alike,
    /// and against a sharp target a soft start does harm). Chosen by
    /// `examples/articulated_study.rs` (RESULTS.md, "Non-rigid pose").
    pub fn for_rendered_target() -> Self {
        Self {
            schedule: Some(Schedule {
                sigma_start: 1e-2,
                gamma_start: 1e-2,
                stages: 4,
            }),
            ..Self::default()
        }
    }

    /// [`Error::Input`] for an out-of-domain option.
    pub fn validate(&self) -> Result<()> {
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if self.iterations == 0 || self.log_every == 0 {
            return Err(Error::Input(
                "an articulated fit needs at least 1 iteration, and log_every at least 1".into(),
            ));
        }
        if !(pos(self.lr) && pos(self.lr_final)) {
            return Err(Error::Input(format!(
                "the learning rate and its final factor must be finite and > 0 ({}, {})",
                self.lr, self.lr_final
            )));
        }
        self.adam(0).validate()?;
        if let Some(s) = &self.schedule {
            s.validate()?;
        }
        if let Some(b) = &self.blur {
            b.validate()?;
        }
        crate::raster::gpu::Method::check_tile(self.tile)?;
        self.settings.validate()?;
        Ok(())
    }

    /// The blur of iteration `it` (0-based), in pixels.
    pub fn blur_at(&self, it: u32) -> f64 {
        self.blur
            .as_ref()
            .map_or(0.0, |b| b.at(it, self.iterations))
    }

    /// What changes between stages: σ, γ and the blur of iteration `it` (0-based).
    fn stage(&self, it: u32) -> (f64, f64, f64) {
        let (sigma, gamma) = self.sigma_gamma(it);
        (sigma, gamma, self.blur_at(it))
    }

    /// σ and γ of iteration `it` (0-based).
    pub fn sigma_gamma(&self, it: u32) -> (f64, f64) {
        let sharp = (self.settings.sigma, self.settings.gamma);
        self.schedule
            .as_ref()
            .map_or(sharp, |s| s.at(it, self.iterations, sharp))
    }

    /// Adam's options at iteration `it` (0-based): the learning rate decayed by
    /// `lr_final^(it / (N − 1))`.
    fn adam(&self, it: u32) -> AdamOptions {
        let factor = if self.iterations <= 1 {
            1.0
        } else {
            self.lr_final
                .powf(f64::from(it) / f64::from(self.iterations - 1))
        };
        AdamOptions {
            lr: self.lr * factor,
            betas: self.betas,
            eps: 1e-8,
        }
    }
}

/// Push constants of `kernels/fit/skin/*.comp` (`skin.glsl`'s `Push`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct SkinPush {
    vertex_count: u32,
    joint_count: u32,
    log_index: u32,
    pad: u32,
}

/// A joint as `skin.glsl`'s `JointDef` reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct JointDef {
    pivot: [f32; 3],
    parent_bone: u32,
    axis: [f32; 3],
    pad: u32,
}

/// A vertex's bones and weights as `skin.glsl`'s `Skin` reads them.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct SkinDef {
    bones: [u32; 4],
    weights: [f32; 4],
}

/// Bytes of `skin.glsl`'s `Bone`: three rows, the posed axis and pivot.
const BONE_BYTES: u64 = 5 * 16;

/// One logged iteration.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ArticulatedLog {
    /// Iteration, from 1.
    pub iteration: u32,
    /// The MSE at this iteration's angles (before its step), at its σ and γ.
    pub loss: f64,
    /// σ of this iteration.
    pub sigma: f64,
    /// γ of this iteration.
    pub gamma: f64,
    /// The loss's blur of this iteration, in pixels.
    pub blur: f64,
    /// The angles the iteration evaluated (radians).
    pub angles: Vec<f64>,
    /// Seconds since the fit started.
    pub seconds: f64,
}

/// An articulated fit's GPU state: the scene with its guarded bins and the lighting, and the
/// skinned model, ready to run iterations
/// ([`ArticulatedFitter::run`]) with no read-back.
pub type ArticulatedFit<'c> = PosedFit<'c, Skinned>;

/// What an articulated fit adds to its view: the loss, the skeleton and skin, the angles, the
/// kernels that pose the mesh from them and take the gradient back to them, and their Adam
/// optimizer.
pub struct Skinned {
    opts: ArticulatedFitOptions,
    mse: BlurredMse,
    fk: Arc<Kernel>,
    apply: Arc<Kernel>,
    grad: Arc<Kernel>,
    /// The rest positions, packed xyz.
    rest: Buffer,
    joint_defs: Buffer,
    skins: Buffer,
    /// Per bone, the joints that move it (two words of bits).
    below: Buffer,
    /// Per bone, its transform now (`BONE_BYTES` each).
    bones: Buffer,
    /// The angles, one float per joint.
    params: Buffer,
    d_params: Buffer,
    adam: Adam,
    /// `joint_count + 1` floats per iteration: the loss and the angles.
    log: Buffer,
    push: SkinPush,
}

/// An articulated fit ready to run iterations ([`Fitter::run`]).
pub type ArticulatedFitter<'c> = Fitter<'c, ArticulatedFit<'c>>;

impl<'c> Fitter<'c, ArticulatedFit<'c>> {
    /// The fit of `rig`'s angles seen from `camera` to `target` (RGBA per pixel, row 0 at the
    /// top, the settings' size) from `init` (radians, one per joint): uploads everything,
    /// counts the entries of the first pose once and sizes the guarded bins with the mesh fit's
    /// headroom.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        ctx: &'c Context,
        rig: &Rig,
        camera: &Camera,
        lighting: &Lighting,
        target: &[[f32; 4]],
        init: &[f64],
        opts: &ArticulatedFitOptions,
    ) -> Result<Self> {
        opts.validate()?;
        rig.validate()?;
        rig.check_angles(init)?;
        let view = PosedView::new(
            ctx,
            &rig.mesh,
            camera,
            lighting,
            target,
            &opts.settings,
            opts.tile,
            "an articulated fit's binning (with the backward's partials)",
        )?;
        let joints = rig.joint_count();
        let defs: Vec<JointDef> = rig
            .joints
            .iter()
            .map(|j| JointDef {
                pivot: j.pivot.as_vec3().to_array(),
                parent_bone: j.parent.map_or(0, |p| p as u32 + 1),
                axis: j.axis.normalize().as_vec3().to_array(),
                pad: 0,
            })
            .collect();
        let skins: Vec<SkinDef> = rig
            .skin
            .iter()
            .map(|s| SkinDef {
                bones: s.joints.map(bone_of),
                weights: s.weights,
            })
            .collect();
        let angles: Vec<f32> = init.iter().map(|&a| a as f32).collect();
        let model = Skinned {
            mse: BlurredMse::new(ctx, 1, opts.settings.width, opts.settings.height)?,
            fk: ctx.kernel(&specs::SKIN_FK, &[])?,
            apply: ctx.kernel(&specs::SKIN_APPLY, &[])?,
            grad: ctx.kernel(&specs::SKIN_GRAD, &[])?,
            rest: ctx.upload_buffer("rig rest positions", rig.mesh.positions.as_flattened())?,
            joint_defs: ctx.upload_buffer("rig joints", &defs)?,
            skins: ctx.upload_buffer("rig skin", &skins)?,
            below: ctx.upload_buffer("rig joints per bone", &rig.below_masks())?,
            bones: ctx.create_buffer(
                "rig bones",
                BONE_BYTES * (joints as u64 + 1),
                MemoryKind::Device,
            )?,
            params: ctx.upload_buffer("joint angles", &angles)?,
            d_params: ctx.upload_buffer("joint angle gradient", &vec![0f32; joints])?,
            adam: Adam::new(ctx, joints as u64, opts.adam(0))?,
            log: ctx.create_buffer(
                "articulated log",
                4 * (joints as u64 + 1) * u64::from(opts.iterations),
                MemoryKind::Device,
            )?,
            push: SkinPush {
                vertex_count: rig.mesh.vertex_count() as u32,
                joint_count: joints as u32,
                log_index: 0,
                pad: 0,
            },
            opts: opts.clone(),
        };
        let fit = PosedFit::new(ctx, view, model, opts.sigma_gamma(0))?;
        Fitter::from_fit(ctx, fit)
    }

    /// The MSE (of images blurred by `blur` pixels) and the render at the current angles with σ
    /// and γ (no step), re-run until the entries fit.
    pub fn evaluate(&mut self, sigma: f64, gamma: f64, blur: f64) -> Result<(f64, Vec<[f32; 4]>)> {
        posed::evaluate(self, sigma, gamma, blur)
    }
}

impl ArticulatedFit<'_> {
    /// The log of iterations `first ..= last` that ran: each one's loss, σ, γ and the angles
    /// it evaluated (`seconds` as given).
    pub fn log(&self, first: u32, last: u32, seconds: f64) -> Result<Vec<ArticulatedLog>> {
        if first == 0 || first > last || last > self.model.opts.iterations {
            return Err(Error::Misuse(format!(
                "articulated fit: the log of {first}..={last} of 1..={}",
                self.model.opts.iterations
            )));
        }
        let row = self.model.push.joint_count as usize + 1;
        let floats: Vec<f32> = self.ctx.read_buffer(
            &self.model.log,
            4 * (row as u64) * u64::from(first - 1),
            row * (last - first + 1) as usize,
        )?;
        Ok(floats
            .chunks_exact(row)
            .zip(first..=last)
            .map(|(r, it)| {
                let (sigma, gamma, blur) = self.model.opts.stage(it - 1);
                ArticulatedLog {
                    iteration: it,
                    loss: f64::from(r[0]),
                    sigma,
                    gamma,
                    blur,
                    angles: r[1..].iter().map(|&a| f64::from(a)).collect(),
                    seconds,
                }
            })
            .collect())
    }

    /// dL/dθ of the last iteration that ran (the gradient its Adam step took).
    pub fn gradient(&self) -> Result<Vec<f64>> {
        let g: Vec<f32> = self.ctx.read_buffer(
            &self.model.d_params,
            0,
            self.model.push.joint_count as usize,
        )?;
        Ok(g.into_iter().map(f64::from).collect())
    }

    /// The angles now (radians).
    pub fn angles(&self) -> Result<Vec<f64>> {
        let a: Vec<f32> =
            self.ctx
                .read_buffer(&self.model.params, 0, self.model.push.joint_count as usize)?;
        Ok(a.into_iter().map(f64::from).collect())
    }

    /// The skinned positions the last pose recorded (packed xyz), read back.
    pub fn posed_positions(&self) -> Result<Vec<[f32; 3]>> {
        self.ctx.read_buffer(
            self.view.scene.positions(),
            0,
            self.model.push.vertex_count as usize,
        )
    }
}

impl PoseModel for Skinned {
    const NAME: &'static str = "articulated fit";

    fn last_iteration(&self) -> u32 {
        self.opts.iterations
    }

    fn set_iteration(&mut self, it: u32) -> Result<(f64, f64)> {
        self.adam.set_options(self.opts.adam(it - 1))?;
        Ok(self.opts.sigma_gamma(it - 1))
    }

    /// The guarded forward with the rest gated on the count: the MSE of the images blurred
    /// as the iteration's stage says, the backward, the lighting's backward, the angle
    /// gradient (and the log row) and the Adam step.
    fn record_step(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        view: &PosedView,
    ) -> Result<()> {
        let blur = self.opts.blur_at(it - 1);
        let push = SkinPush {
            log_index: it - 1,
            ..self.push
        };
        let Self {
            mse,
            grad,
            params,
            d_params,
            rest,
            skins,
            below,
            bones,
            log,
            adam,
            ..
        } = self;
        view.record_guarded(
            rec,
            gate,
            it,
            |rec, images, target, d_image| mse.record(rec, images, target, Some(d_image), blur),
            |rec, io| {
                rec.pass("angle gradient", |rec| {
                    rec.dispatch(
                        grad,
                        &specs::SkinGradBindings {
                            params: params.whole(),
                            bones: bones.whole(),
                            rest: rest.whole(),
                            skins: skins.whole(),
                            below: below.whole(),
                            d_posed: io.positions,
                            d_params: d_params.whole(),
                            loss: mse.loss_buffer().whole(),
                            log: log.whole(),
                        }
                        .for_kernel(grad)?,
                        &push,
                        push.joint_count,
                    )
                })?;
                rec.pass("adam", |rec| {
                    adam.record_step(rec, params.whole(), d_params.whole(), it)
                })
            },
        )
    }

    /// Records the bones, then the skinned positions.
    fn record_positions(&self, rec: &mut Recorder<'_>, positions: BufferRange<'_>) -> Result<()> {
        rec.pass("kinematics", |rec| {
            rec.dispatch(
                &self.fk,
                &specs::SkinFkBindings {
                    params: self.params.whole(),
                    joints: self.joint_defs.whole(),
                    bones: self.bones.whole(),
                }
                .for_kernel(&self.fk)?,
                &self.push,
                1,
            )
        })?;
        rec.pass("skinning", |rec| {
            rec.dispatch(
                &self.apply,
                &specs::SkinApplyBindings {
                    bones: self.bones.whole(),
                    rest: self.rest.whole(),
                    skins: self.skins.whole(),
                    posed: positions,
                }
                .for_kernel(&self.apply)?,
                &self.push,
                groups(u64::from(self.push.vertex_count), 64)?,
            )
        })
    }

    fn record_loss(
        &self,
        rec: &mut Recorder<'_>,
        images: BufferRange<'_>,
        target: BufferRange<'_>,
        blur: f64,
    ) -> Result<()> {
        self.mse.record(rec, images, target, None, blur)
    }

    fn read_loss(&self, ctx: &Context) -> Result<f32> {
        self.mse.read_loss(ctx)
    }
}

/// A finished articulated fit.
#[derive(Clone, Debug)]
pub struct ArticulatedFitResult {
    /// The angles after the last step (radians).
    pub angles: Vec<f64>,
    /// The MSE at those angles, at the sharp σ and γ.
    pub loss: f64,
    /// The render at those angles (sharp), RGBA per pixel, row 0 at the top.
    pub image: Vec<[f32; 4]>,
    /// One entry per iteration.
    pub log: Vec<ArticulatedLog>,
    /// Iterations run.
    pub iterations: u32,
    /// The first iteration this run ran (after a resume, the checkpoint's + 1).
    pub first_iteration: u32,
    /// Wall time of the iterations (without the final evaluation).
    pub seconds: f64,
}

/// Fits the joint angles of `rig` seen from `camera` to `target` (RGBA per pixel, row 0 at the
/// top, the settings' size) from `init` (radians, one per joint), in `session`: its hooks see
/// the fit after every submission of iterations (every [`ArticulatedFitOptions::log_every`],
/// and at the end of each σ/γ stage); the result's log holds every iteration. The result's
/// loss is against the target of the sharp σ/γ.
#[allow(clippy::too_many_arguments)]
pub fn fit_articulated<'c>(
    ctx: &'c Context,
    rig: &Rig,
    camera: &Camera,
    lighting: &Lighting,
    mut target: PoseTarget<'_>,
    init: &[f64],
    opts: &ArticulatedFitOptions,
    session: Session<'_, ArticulatedFit<'c>>,
) -> Result<ArticulatedFitResult> {
    opts.validate()?;
    let (mut stages, first_target) = Stages::new(&mut target, opts.sigma_gamma(0))?;
    let mut fitter = ArticulatedFitter::new(ctx, rig, camera, lighting, &first_target, init, opts)?;
    let every = opts.log_every;
    let end = session.run(&mut fitter, (opts.iterations, every), |fitter, it| {
        let last = driver::to_next_log(it, every).min(opts.iterations);
        stages.enter(&mut **fitter, opts.sigma_gamma(it - 1))?;
        Ok(driver::to_stage_end(it, last, |i| opts.stage(i)))
    })?;
    let s = &opts.settings;
    stages.finish(&mut *fitter, (s.sigma, s.gamma))?;
    let (loss, image) = fitter.evaluate(s.sigma, s.gamma, 0.0)?;
    Ok(ArticulatedFitResult {
        angles: fitter.angles()?,
        loss,
        image,
        log: end.log,
        iterations: end.last,
        first_iteration: end.first,
        seconds: end.seconds,
    })
}

impl LogRow for ArticulatedLog {
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
        c.f64("blur", &mut self.blur);
        c.f64s("angle", &mut self.angles);
        c.f64("seconds", &mut self.seconds);
    }
}

/// An articulated fit in a session: a row per iteration, its state the angles and Adam's
/// moments. The σ/γ and blur stage follows from the iteration, so a fit resumed from it ends
/// bit for bit as the fit that never stopped.
impl Trainee for ArticulatedFit<'_> {
    type Row = ArticulatedLog;
    const KIND: FitKind = FitKind::Articulated;

    fn rows(
        &mut self,
        _ctx: &Context,
        first: u32,
        last: u32,
        _entries: u64,
        seconds: f64,
    ) -> Result<Vec<ArticulatedLog>> {
        self.log(first, last, seconds)
    }

    fn save_state(&self, ctx: &Context, w: &mut Writer) -> Result<()> {
        let n = self.model.push.joint_count as usize;
        save_adam(ctx, &self.model.params, &self.model.adam, n, w)
    }

    fn restore_state(&mut self, ctx: &Context, r: &mut Reader<'_>) -> Result<()> {
        let n = self.model.push.joint_count as usize;
        restore_adam(ctx, &self.model.params, &self.model.adam, n, r, "the rig")
    }
}

impl ArticulatedFit<'_> {
    /// The fingerprint of a fit's inputs that a checkpoint of it must carry: the rig, the
    /// camera, the lighting, the (first) target, the start and every option (the iteration
    /// count among them: it spreads the schedules).
    pub fn fingerprint(
        rig: &Rig,
        camera: &Camera,
        lighting: &Lighting,
        target: &[[f32; 4]],
        init: &[f64],
        opts: &ArticulatedFitOptions,
    ) -> u64 {
        let mut f = Fingerprint::default();
        f.add(format!("{rig:?}").as_bytes());
        f.add_pod(target).add_pod(init);
        f.add(format!("{camera:?} {lighting:?} {opts:?}").as_bytes());
        f.value()
    }
}

/// The f64 twin of one evaluation: the render at some angles, its MSE against a target, and
/// dL/dθ through the reference rasterizer's backward and [`Rig::angle_gradient`].
pub mod cpu {
    use super::Rig;
    use crate::camera::Camera;
    use crate::error::Result;
    use crate::fit::blur::cpu::blurred_mse;
    use crate::lighting::Lighting;
    use crate::raster::reference::{MeshF64, render_f64};
    use crate::raster::reference_grad::grad_f64;
    use crate::raster::settings::RasterSettings;

    /// The rig's mesh posed at `angles`, in f64.
    pub fn posed(rig: &Rig, angles: &[f64]) -> MeshF64 {
        MeshF64 {
            positions: rig.skin(angles),
            ..MeshF64::from_mesh(&rig.mesh)
        }
    }

    /// The f64 render at `angles`.
    pub fn render(
        rig: &Rig,
        camera: &Camera,
        lighting: &Lighting,
        settings: &RasterSettings,
        angles: &[f64],
    ) -> Result<Vec<[f64; 4]>> {
        rig.check_angles(angles)?;
        Ok(render_f64(&posed(rig, angles), camera, lighting, settings)?)
    }

    /// The image MSE at `angles` against `target`, both blurred by `blur` pixels.
    pub fn loss(
        rig: &Rig,
        camera: &Camera,
        lighting: &Lighting,
        settings: &RasterSettings,
        target: &[[f64; 4]],
        angles: &[f64],
        blur: f64,
    ) -> Result<f64> {
        let image = render(rig, camera, lighting, settings, angles)?;
        Ok(blurred_mse(&image, target, settings.width, settings.height, blur).0)
    }

    /// The MSE (blurred by `blur` pixels) and dL/dθ at `angles`.
    pub fn loss_and_gradient(
        rig: &Rig,
        camera: &Camera,
        lighting: &Lighting,
        settings: &RasterSettings,
        target: &[[f64; 4]],
        angles: &[f64],
        blur: f64,
    ) -> Result<(f64, Vec<f64>)> {
        rig.check_angles(angles)?;
        let moved = posed(rig, angles);
        let image = render_f64(&moved, camera, lighting, settings)?;
        let (loss, d_image) = blurred_mse(&image, target, settings.width, settings.height, blur);
        let g = grad_f64(
            &moved,
            std::slice::from_ref(camera),
            lighting,
            settings,
            &d_image,
        )?;
        Ok((loss, rig.angle_gradient(angles, &g.positions)))
    }
}
