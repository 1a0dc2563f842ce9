//! What the rigid pose fit ([`super::pose`]) and the articulated fit ([`super::articulated`])
//! share: one view of a lit mesh whose positions a kernel of the fit writes every iteration,
//! rendered through guarded bins against one target image, and differentiated back to those
//! positions through the lighting. Each fit adds its parameters, the kernels that pose the mesh
//! from them and take the gradient back to them, its image loss and its optimizer.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::gate::IterationGate;
use crate::gpu::{Buffer, BufferRange, Context, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::backward::{GradBuffers, GradIo};
use crate::raster::gpu::{GpuScene, GuardedBins, Renderer};
use crate::raster::light::SceneLight;
use crate::raster::settings::RasterSettings;

use super::driver::{Fit, Fitter, max_entry_capacity, reserve_guarded, with_headroom};

/// The posed mesh's view: the scene with its guarded bins and the backward's buffers, the
/// lighting and the target.
pub struct PosedView {
    pub(crate) renderer: Renderer,
    pub(crate) scene: GpuScene,
    pub(crate) light: SceneLight,
    pub(crate) target: Buffer,
    pub(crate) grads: GradBuffers,
    /// The guarded forward's bins, beside the scene.
    bins: GuardedBins,
    /// dL/d(unlit colour), which the fits do not need (the lighting's backward writes it).
    d_base: Buffer,
    tile: u32,
    capacity: u64,
    max_capacity: u64,
    /// The fit's binning, for [`Error::DeviceLimit`].
    what: &'static str,
}

impl PosedView {
    /// `mesh` seen from `camera` with `settings`, against `target`; its bins hold one entry
    /// until [`PosedView::fit_capacity`] counts the first pose's. `what` names the fit's binning
    /// in the device-limit error ("a pose fit's binning ...").
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        ctx: &Context,
        mesh: &Mesh,
        camera: &Camera,
        lighting: &Lighting,
        target: &[[f32; 4]],
        settings: &RasterSettings,
        tile: u32,
        what: &'static str,
    ) -> Result<Self> {
        check_target(target, settings)?;
        let renderer = Renderer::new(ctx)?;
        let scene =
            renderer.prepare(ctx, mesh, std::slice::from_ref(camera), lighting, settings)?;
        let (bins, grads) = reserve_guarded(ctx, &renderer, &scene, tile, 1, false)?;
        let light = SceneLight::new(ctx, &scene)?;
        Ok(Self {
            target: ctx.upload_buffer("posed target", target)?,
            bins,
            grads,
            d_base: ctx.create_buffer(
                "posed unlit colour gradients",
                12 * light.color_count().max(1),
                MemoryKind::Device,
            )?,
            tile,
            capacity: 1,
            max_capacity: max_entry_capacity(ctx, &renderer, &scene),
            what,
            renderer,
            scene,
            light,
        })
    }

    /// Records the lighting of the positions the fit wrote into the scene.
    pub(crate) fn record_light(&self, rec: &mut Recorder<'_>) -> Result<()> {
        rec.pass("lighting", |rec| {
            self.light.record_forward(
                rec,
                self.scene.positions().whole(),
                self.scene.position_layout(),
                self.scene.colors().whole(),
            )
        })
    }

    /// Sizes the guarded bins for the pose the fit recorded last (positions and lighting, at
    /// the σ and γ set): one counting submission, then the count with the headroom. The fits do
    /// it at the start of every σ/γ stage (a blurry stage bins several times the entries of a
    /// sharp one, and the backward's texel partials, cleared over the whole capacity every
    /// iteration, are the larger cost at these image sizes); it changes no result.
    pub(crate) fn fit_capacity(&mut self, ctx: &Context) -> Result<()> {
        let total = self.renderer.count_entries(ctx, &self.scene, self.tile)?;
        self.resize(ctx, total)
    }

    /// Sizes the bins and the backward's buffers for `total` entries with the headroom.
    pub(crate) fn resize(&mut self, ctx: &Context, total: u64) -> Result<()> {
        let capacity = with_headroom(
            ctx,
            self.what,
            total,
            self.max_capacity,
            "use larger tiles or a smaller σ",
        )?;
        (self.bins, self.grads) =
            reserve_guarded(ctx, &self.renderer, &self.scene, self.tile, capacity, false)?;
        self.capacity = capacity;
        Ok(())
    }

    /// Entries the bins and the backward's partials hold now.
    pub(crate) fn capacity(&self) -> u64 {
        self.capacity
    }

    /// Replaces the target (same size, finite).
    pub(crate) fn set_target(&self, ctx: &Context, target: &[[f32; 4]]) -> Result<()> {
        check_target(target, self.scene.settings())?;
        ctx.write_buffer(&self.target, 0, target)
    }

    /// Records iteration `it` after the pose: the guarded forward, then gated on its count the
    /// image loss (`loss`: the render and the target to dL/d(image) into the given range), the
    /// backward, the lighting's backward (dL/d(lit colour) to dL/d(positions), added to the
    /// geometric share), and `step` (the gradient to the parameters and the optimizer).
    pub(crate) fn record_guarded(
        &self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        loss: impl FnOnce(
            &mut Recorder<'_>,
            BufferRange<'_>,
            BufferRange<'_>,
            BufferRange<'_>,
        ) -> Result<()>,
        step: impl FnOnce(&mut Recorder<'_>, &GradIo<'_>) -> Result<()>,
    ) -> Result<()> {
        let Self {
            renderer,
            scene,
            light,
            target,
            grads,
            bins,
            d_base,
            ..
        } = self;
        renderer.record_forward_guarded(rec, scene, bins, gate, it, |rec, binned| {
            let scene = binned.scene();
            let io = grads.io();
            rec.pass("image loss", |rec| {
                loss(rec, scene.output().whole(), target.whole(), io.upstream)
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
            step(rec, &io)
        })
    }

    /// An evaluation's guarded forward (iteration 0) with the image loss only.
    pub(crate) fn record_evaluation(
        &self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        loss: impl FnOnce(&mut Recorder<'_>, BufferRange<'_>, BufferRange<'_>) -> Result<()>,
    ) -> Result<()> {
        let (renderer, target) = (&self.renderer, &self.target);
        renderer.record_forward_guarded(rec, &self.scene, &self.bins, gate, 0, |rec, binned| {
            loss(rec, binned.scene().output().whole(), target.whole())
        })
    }

    /// The last render, read back (RGBA per pixel).
    pub(crate) fn read_render(&self, ctx: &Context) -> Result<Vec<[f32; 4]>> {
        let s = self.scene.settings();
        ctx.read_buffer(self.scene.output(), 0, (s.width * s.height) as usize)
    }
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

/// The σ/γ stages of a posed fit's loop: at a new σ and γ, the target of the stage (a
/// [`PoseTarget::PerStage`]) and the capacity are set before its first submission.
pub(crate) struct Stages<'t, 'a> {
    target: &'t mut PoseTarget<'a>,
    sigma_gamma: (f64, f64),
}

impl<'t, 'a> Stages<'t, 'a> {
    /// The stages from the first σ and γ, and the target there.
    pub(crate) fn new(
        target: &'t mut PoseTarget<'a>,
        sigma_gamma: (f64, f64),
    ) -> Result<(Self, Vec<[f32; 4]>)> {
        let first = match target {
            PoseTarget::Fixed(t) => t.to_vec(),
            PoseTarget::PerStage(f) => f(sigma_gamma.0, sigma_gamma.1)?,
        };
        Ok((
            Self {
                target,
                sigma_gamma,
            },
            first,
        ))
    }

    /// Before a submission at σ and γ: a new stage's target and capacity.
    pub(crate) fn enter(
        &mut self,
        fit: &mut PosedFit<'_, impl PoseModel>,
        sigma_gamma: (f64, f64),
    ) -> Result<()> {
        if sigma_gamma != self.sigma_gamma {
            self.set_target(fit, sigma_gamma)?;
            fit.fit_capacity(sigma_gamma.0, sigma_gamma.1)?;
            self.sigma_gamma = sigma_gamma;
        }
        Ok(())
    }

    /// After the loop: the target of the sharp σ and γ the fit is evaluated at.
    pub(crate) fn finish(
        mut self,
        fit: &mut PosedFit<'_, impl PoseModel>,
        sharp: (f64, f64),
    ) -> Result<()> {
        if sharp != self.sigma_gamma {
            self.set_target(fit, sharp)?;
        }
        Ok(())
    }

    fn set_target(
        &mut self,
        fit: &mut PosedFit<'_, impl PoseModel>,
        (sigma, gamma): (f64, f64),
    ) -> Result<()> {
        match self.target {
            PoseTarget::Fixed(_) => Ok(()),
            PoseTarget::PerStage(f) => fit.set_target(&f(sigma, gamma)?),
        }
    }
}

/// What a posed fit adds to its [`PosedView`]: its parameters, the kernels that pose the mesh
/// from them and take the gradient back to them, its image loss and its optimizer.
///
/// Public only to be named in [`PosedFit`]'s bounds; this module is private to the crate.
pub trait PoseModel {
    /// The fit's name in messages.
    const NAME: &'static str;
    /// The last iteration the fit runs ([`Fit::last_iteration`]).
    fn last_iteration(&self) -> u32;
    /// Sets iteration `it`'s optimizer options; its σ and γ.
    fn set_iteration(&mut self, it: u32) -> Result<(f64, f64)>;
    /// Records the posed positions (packed xyz) into `positions`.
    fn record_positions(&self, rec: &mut Recorder<'_>, positions: BufferRange<'_>) -> Result<()>;
    /// Records iteration `it`'s step after the pose: [`PosedView::record_guarded`] with the
    /// fit's image loss, its gradient to the parameters and the optimizer.
    fn record_step(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        view: &PosedView,
    ) -> Result<()>;
    /// Records the image loss of an evaluation (no gradient) of the render against the target,
    /// of images blurred by `blur` pixels where the fit's loss blurs.
    fn record_loss(
        &self,
        rec: &mut Recorder<'_>,
        images: BufferRange<'_>,
        target: BufferRange<'_>,
        blur: f64,
    ) -> Result<()>;
    /// The loss [`PoseModel::record_loss`] left.
    fn read_loss(&self, ctx: &Context) -> Result<f32>;
}

/// A fit of a posed view: the scene with its guarded bins, the lighting, the target and the
/// backward's buffers, and the fit's model of the pose ([`super::pose::Rigid`],
/// [`super::articulated::Skinned`]), run by a [`Fitter`] ([`super::pose::PoseFit`],
/// [`super::articulated::ArticulatedFit`]).
pub struct PosedFit<'c, M> {
    pub(crate) ctx: &'c Context,
    pub(crate) view: PosedView,
    pub(crate) model: M,
}

impl<'c, M: PoseModel> PosedFit<'c, M> {
    /// `model` on `view`, its bins sized for the pose it records at the first iteration's σ and
    /// γ.
    pub(crate) fn new(
        ctx: &'c Context,
        view: PosedView,
        model: M,
        (sigma, gamma): (f64, f64),
    ) -> Result<Self> {
        let mut fit = Self { ctx, view, model };
        fit.fit_capacity(sigma, gamma)?;
        Ok(fit)
    }

    /// Replaces the target (same size, finite).
    pub(crate) fn set_target(&mut self, target: &[[f32; 4]]) -> Result<()> {
        self.view.set_target(self.ctx, target)
    }

    /// Sizes the guarded bins for the pose now at σ and γ ([`PosedView::fit_capacity`]).
    pub(crate) fn fit_capacity(&mut self, sigma: f64, gamma: f64) -> Result<()> {
        self.view.scene.set_blur(sigma, gamma)?;
        self.ctx.submit_and_wait(|rec| self.record_pose(rec))?;
        self.view.fit_capacity(self.ctx)
    }

    /// Records the posed positions and their lit colours into the scene.
    fn record_pose(&self, rec: &mut Recorder<'_>) -> Result<()> {
        self.model
            .record_positions(rec, self.view.scene.positions().whole())?;
        self.view.record_light(rec)
    }
}

impl<M> PosedFit<'_, M> {
    /// Entries the bins and the backward's partials hold now.
    pub fn capacity(&self) -> u64 {
        self.view.capacity()
    }
}

impl<M: PoseModel> Fit for PosedFit<'_, M> {
    const NAME: &'static str = M::NAME;

    fn last_iteration(&self) -> u32 {
        self.model.last_iteration()
    }

    fn record_iteration(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        _row: u32,
    ) -> Result<()> {
        let (sigma, gamma) = self.model.set_iteration(it)?;
        self.view.scene.set_blur(sigma, gamma)?;
        self.record_pose(rec)?;
        self.model.record_step(rec, gate, it, &self.view)
    }

    fn capacity(&self) -> u64 {
        self.view.capacity()
    }

    fn grow(&mut self, ctx: &Context, total: u64) -> Result<()> {
        self.view.resize(ctx, total)
    }
}

/// The loss (of images blurred by `blur` pixels, where the fit blurs) and the render of
/// `fitter`'s pose now with σ and γ (no step), re-run until the entries fit.
pub(crate) fn evaluate<M: PoseModel>(
    fitter: &mut Fitter<'_, PosedFit<'_, M>>,
    sigma: f64,
    gamma: f64,
    blur: f64,
) -> Result<(f64, Vec<[f32; 4]>)> {
    fitter.view.scene.set_blur(sigma, gamma)?;
    fitter.submit_guarded(|fit, rec, gate| {
        fit.record_pose(rec)?;
        fit.view
            .record_evaluation(rec, gate, |rec, images, target| {
                fit.model.record_loss(rec, images, target, blur)
            })
    })?;
    let ctx = fitter.ctx;
    Ok((
        f64::from(fitter.model.read_loss(ctx)?),
        fitter.view.read_render(ctx)?,
    ))
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
