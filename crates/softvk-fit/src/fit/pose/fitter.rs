//! The pose fit on the GPU: every iteration recorded with no read-back, as many per submission
//! as asked ([`PoseFitter`]).

use std::sync::Arc;

use glam::DVec3;

use bytemuck::{Pod, Zeroable};

use super::{Pose, PoseFitOptions, PoseLog, centroid};
use crate::fit::posed::{self, PoseModel, PosedFit, PosedView, check_target};

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::fit::ImageMse;
use crate::fit::adam::{Adam, AdamOptions};
use crate::fit::driver::Fitter;
use crate::gpu::GradOut;
use crate::gpu::gate::IterationGate;
use crate::gpu::groups;
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::specs;

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

/// A pose fit's GPU state: the scene with its guarded bins and the lighting, and the rigid
/// model. Every iteration is recorded with no read-back (see the
/// [module docs](super)), as many per submission as asked ([`PoseFitter`] runs them).
pub type PoseFit<'c> = PosedFit<'c, Rigid>;

/// What a pose fit adds to its view: the loss, the pose's parameters, the kernels that apply
/// them and take the gradient back to them, and their two Adam optimizers.
pub struct Rigid {
    opts: PoseFitOptions,
    mse: ImageMse,
    apply: Arc<Kernel>,
    grad: Arc<Kernel>,
    /// The rest positions, packed xyz.
    rest: Buffer,
    /// ω at floats [0, 3), t at [`PosePush::translation_at`, + 3): two bindable ranges.
    params: Buffer,
    d_params: Buffer,
    adam_rotation: Adam,
    adam_translation: Adam,
    /// Two vec4 per iteration of the fit: the loss and ω, then t.
    log: Buffer,
    push: PosePush,
}

/// A pose fit ready to run iterations ([`Fitter::run`]).
pub type PoseFitter<'c> = Fitter<'c, PoseFit<'c>>;

impl<'c> Fitter<'c, PoseFit<'c>> {
    /// The fit of `mesh`'s pose seen from `camera` to `target` from `init` (see
    /// [`fit_pose`](super::fit_pose)): uploads everything, counts the entries of the first pose once and sizes
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
        // Sized for real once the first pose's entries are counted (below).
        let view = PosedView::new(
            ctx,
            mesh,
            camera,
            lighting,
            target,
            &opts.settings,
            opts.tile,
            "a pose fit's binning (with the backward's partials)",
        )?;
        let rest_f64 = &view.scene.host_meshes()[0].positions;
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
        let model = Rigid {
            mse: ImageMse::new(ctx, 1, opts.settings.width, opts.settings.height)?,
            apply: ctx.kernel(&specs::POSE_APPLY, &[])?,
            grad: ctx.kernel(&specs::POSE_GRAD, &[])?,
            rest: ctx.upload_buffer("pose rest positions", &rest)?,
            params: ctx.upload_buffer("pose parameters", &p0)?,
            d_params: ctx.upload_buffer("pose gradient", &vec![0f32; param_floats])?,
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
                32 * u64::from(opts.last_iteration()),
                MemoryKind::Device,
            )?,
            push,
            opts: opts.clone(),
        };
        let fit = PosedFit::new(ctx, view, model, opts.sigma_gamma(0))?;
        Fitter::from_fit(ctx, fit)
    }

    /// The MSE and the render at the current pose with σ and γ (no step), re-run until the
    /// entries fit.
    pub fn evaluate(&mut self, sigma: f64, gamma: f64) -> Result<(f64, Vec<[f32; 4]>)> {
        posed::evaluate(self, sigma, gamma, 0.0)
    }
}

impl PoseFit<'_> {
    /// The log of iterations `first ..= last` (their losses and poses), read back.
    pub(super) fn read_log(&self, first: u32, last: u32, seconds: f64) -> Result<Vec<PoseLog>> {
        let rows: Vec<[f32; 4]> = self.ctx.read_buffer(
            &self.model.log,
            32 * u64::from(first - 1),
            2 * (last - first + 1) as usize,
        )?;
        Ok(rows
            .chunks_exact(2)
            .zip(first..=last)
            .map(|(r, it)| {
                let (sigma, gamma) = self.model.opts.sigma_gamma(it - 1);
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
    pub(super) fn read_state(&self) -> Result<[[f64; 6]; 3]> {
        let ti = 4 * u64::from(self.model.push.translation_at);
        let read = |b: &Buffer, at: u64| -> Result<Vec<f32>> { self.ctx.read_buffer(b, at, 3) };
        let (mr, vr) = self.model.adam_rotation.moments();
        let (mt, vt) = self.model.adam_translation.moments();
        let join = |a: Vec<f32>, b: Vec<f32>| -> [f64; 6] {
            std::array::from_fn(|k| f64::from(if k < 3 { a[k] } else { b[k - 3] }))
        };
        Ok([
            join(read(&self.model.params, 0)?, read(&self.model.params, ti)?),
            join(read(mr, 0)?, read(mt, 0)?),
            join(read(vr, 0)?, read(vt, 0)?),
        ])
    }

    /// Sets the parameters and Adam's moments (each `[rotation; translation]`).
    pub(super) fn write_state(&self, state: [&[f64; 6]; 3]) -> Result<()> {
        let ti = 4 * u64::from(self.model.push.translation_at);
        let f = |a: &[f64; 6], k: usize| -> [f32; 3] { std::array::from_fn(|i| a[k + i] as f32) };
        let (mr, vr) = self.model.adam_rotation.moments();
        let (mt, vt) = self.model.adam_translation.moments();
        self.ctx
            .write_buffer(&self.model.params, 0, &f(state[0], 0))?;
        self.ctx
            .write_buffer(&self.model.params, ti, &f(state[0], 3))?;
        self.ctx.write_buffer(mr, 0, &f(state[1], 0))?;
        self.ctx.write_buffer(mt, 0, &f(state[1], 3))?;
        self.ctx.write_buffer(vr, 0, &f(state[2], 0))?;
        self.ctx.write_buffer(vt, 0, &f(state[2], 3))
    }

    /// dL/d(ω, t) of the last iteration that ran (the gradient its Adam steps took).
    pub fn gradient(&self) -> Result<[f64; 6]> {
        let ti = 4 * u64::from(self.model.push.translation_at);
        let r: Vec<f32> = self.ctx.read_buffer(&self.model.d_params, 0, 3)?;
        let t: Vec<f32> = self.ctx.read_buffer(&self.model.d_params, ti, 3)?;
        Ok(std::array::from_fn(|k| {
            f64::from(if k < 3 { r[k] } else { t[k - 3] })
        }))
    }

    /// The log of iterations `first ..= last` that ran: each one's loss, σ, γ and the pose it
    /// evaluated (`seconds` as given).
    pub fn log(&self, first: u32, last: u32, seconds: f64) -> Result<Vec<PoseLog>> {
        if first == 0 || first > last || last > self.model.opts.last_iteration() {
            return Err(Error::Misuse(format!(
                "pose fit: the log of {first}..={last} of 1..={}",
                self.model.opts.last_iteration()
            )));
        }
        self.read_log(first, last, seconds)
    }

    /// The pose now.
    pub fn pose(&self) -> Result<Pose> {
        Ok(Pose::from_array(self.read_state()?[0]))
    }

    /// The point rotations turn about.
    pub fn centre(&self) -> DVec3 {
        DVec3::from(self.model.push.centre.map(f64::from))
    }
}

impl PoseModel for Rigid {
    const NAME: &'static str = "pose fit";

    fn last_iteration(&self) -> u32 {
        self.opts.last_iteration()
    }

    fn set_iteration(&mut self, it: u32) -> Result<(f64, f64)> {
        let o = &self.opts;
        let rot = o.adam(it - 1);
        self.adam_rotation.set_options(rot)?;
        self.adam_translation.set_options(AdamOptions {
            lr: o.lr_translation * o.lr_factor(it - 1),
            ..rot
        })?;
        Ok(o.sigma_gamma(it - 1))
    }

    /// The guarded forward with the rest gated on the count: the MSE, the backward, the
    /// lighting's backward, the pose gradient (and the log row) and the two Adam steps.
    fn record_step(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        view: &PosedView,
    ) -> Result<()> {
        let ti = 4 * u64::from(self.push.translation_at);
        let push = PosePush {
            log_index: it - 1,
            ..self.push
        };
        let Self {
            mse,
            grad,
            params,
            d_params,
            rest,
            log,
            adam_rotation,
            adam_translation,
            ..
        } = self;
        view.record_guarded(
            rec,
            gate,
            it,
            |rec, images, target, d_image| {
                mse.record(rec, images, target, Some(GradOut::write(d_image)))
            },
            |rec, io| {
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
                    adam_rotation.record_step(
                        rec,
                        params.range(0, 12),
                        d_params.range(0, 12),
                        it,
                    )?;
                    adam_translation.record_step(
                        rec,
                        params.range(ti, 12),
                        d_params.range(ti, 12),
                        it,
                    )
                })
            },
        )
    }

    fn record_positions(&self, rec: &mut Recorder<'_>, positions: BufferRange<'_>) -> Result<()> {
        rec.pass("pose", |rec| {
            rec.dispatch(
                &self.apply,
                &specs::PoseApplyBindings {
                    params: self.params.whole(),
                    rest: self.rest.whole(),
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
        _blur: f64,
    ) -> Result<()> {
        self.mse.record(rec, images, target, None)
    }

    fn read_loss(&self, ctx: &Context) -> Result<f32> {
        self.mse.read_loss(ctx)
    }
}
