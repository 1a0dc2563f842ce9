//! The iteration loop every fit and trainer shares: iterations recorded `k` per submission
//! behind the binning's gate, re-run from a stopped one after the capacity grows, and a callback
//! after each submission (losses, progress, checkpoints, interrupts).
//!
//! A fit is its per-iteration recording plus its parameters ([`Fit`]); [`Fitter`] adds what
//! every loop needs around it: the [`IterationGate`], the submission of a span of iterations,
//! the regrowth when an iteration's entries outgrew the capacity, and [`Fitter::drive`], the
//! loop from a first iteration to a last one. The mesh, field, pose and articulated fits, both
//! reconstruction trainers and the fitting benchmark all run through it, so a stopped
//! iteration is handled in one place and a new fit writes none of it again.
//!
//! A fit sizes its guarded stage with the helpers here ([`with_headroom`] over the count the gate
//! saw, at most [`max_entry_capacity`]; [`reserve_guarded`] for a renderer's bins and backward).
//!
//! Why a stopped iteration changes nothing: the gate ([`crate::gpu::gate`]) stops the stages
//! after the binning's count of the iteration whose count does not fit, and of every later one
//! in the submission, before they write anything; the fit then grows to the count the gate
//! recorded and the loop runs again from that iteration. The binned result does not depend on
//! the capacity, so a fit that regrew is bit for bit the one that never did.

use std::ops::{Deref, DerefMut};

use crate::error::{Error, LimitKind, Result};
use crate::gpu::gate::IterationGate;
use crate::gpu::{Context, Recorder, Timer};
use crate::raster::backward::{GradBuffers, grad_stride};
use crate::raster::gpu::{GpuScene, GuardedBins, Renderer};

/// Entry capacity reserved over a count seen: `count × 3 / 2`.
pub const ENTRY_HEADROOM: (u64, u64) = (3, 2);

/// One fit's iterations, as [`Fitter`] runs them: the recording of an iteration and the guarded
/// stage's capacity. Everything else about the loop is the driver's.
pub trait Fit {
    /// Names the fit in errors ("pose fit").
    const NAME: &'static str;

    /// The last iteration the fit can run (its per-iteration buffers are sized for it); no
    /// bound by default.
    fn last_iteration(&self) -> u32 {
        u32::MAX
    }

    /// Work on the host before iterations `first ..= last` are recorded (a trainer stages its
    /// batches); none by default.
    fn prepare(&mut self, _ctx: &Context, _first: u32, _last: u32) -> Result<()> {
        Ok(())
    }

    /// Records iteration `it`, the `row`-th (from 0) of its submission: its guarded stage
    /// through `gate`, and everything that must not run when the gate stops it gated on it.
    fn record_iteration(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        row: u32,
    ) -> Result<()>;

    /// Entries the guarded stage holds now.
    fn capacity(&self) -> u64;

    /// Grows the guarded stage to hold `total` entries (with the fit's headroom).
    fn grow(&mut self, ctx: &Context, total: u64) -> Result<()>;
}

/// A [`Fit`] with the gate, its regrowths and the loop ([`Fitter::drive`]). Derefs to the fit.
pub struct Fitter<'c, F> {
    ctx: &'c Context,
    fit: F,
    gate: IterationGate,
    regrowths: u32,
    last_entries: u64,
}

impl<'c, F: Fit> Fitter<'c, F> {
    /// `fit` with a gate of its own.
    pub fn from_fit(ctx: &'c Context, fit: F) -> Result<Self> {
        Ok(Self {
            ctx,
            fit,
            gate: IterationGate::new(ctx)?,
            regrowths: 0,
            last_entries: 0,
        })
    }

    /// The context the fit runs on.
    pub fn ctx(&self) -> &'c Context {
        self.ctx
    }

    /// Runs iterations `first ..= last` (from 1) in one submission (GPU timestamps into
    /// `timer`). `None` when all ran; `Some(i)` when iteration `i` outgrew the capacity: it and
    /// the later ones changed nothing, the capacity has grown to fit it, and they are to be run
    /// again.
    pub fn run(&mut self, first: u32, last: u32, timer: Option<&mut Timer>) -> Result<Option<u32>> {
        if first == 0 || first > last || last > self.fit.last_iteration() {
            return Err(Error::Misuse(format!(
                "{}: iterations {first}..={last} (they count from 1, up to {})",
                F::NAME,
                self.fit.last_iteration()
            )));
        }
        self.fit.prepare(self.ctx, first, last)?;
        let Self { ctx, fit, gate, .. } = self;
        ctx.submit_and_wait_timed(timer, |rec| {
            gate.reset();
            for it in first..=last {
                fit.record_iteration(rec, gate, it, it - first)?;
            }
            Ok(())
        })?;
        let status = self.gate.read(self.ctx)?;
        if let Some((stopped, total)) = status.stopped {
            let capacity = self.fit.capacity();
            if stopped < first || stopped > last || total <= capacity {
                return Err(Error::Limit(format!(
                    "{}: the gate stopped iteration {stopped} of {first}..={last} with {total} \
                     entries for a capacity of {capacity}",
                    F::NAME
                )));
            }
            self.fit.grow(self.ctx, total)?;
            self.regrowths += 1;
            return Ok(Some(stopped));
        }
        self.last_entries = status.last_total;
        Ok(None)
    }

    /// One guarded submission outside the iterations (an evaluation: `record` gets the fit and
    /// the gate, as iteration 0), submitted again after growing until its entries fit.
    pub fn submit_guarded(
        &mut self,
        mut record: impl FnMut(&mut F, &mut Recorder<'_>, &mut IterationGate) -> Result<()>,
    ) -> Result<()> {
        loop {
            let Self { ctx, fit, gate, .. } = self;
            ctx.submit_and_wait(|rec| {
                gate.reset();
                record(fit, rec, gate)
            })?;
            match self.gate.read(self.ctx)?.stopped {
                None => return Ok(()),
                Some((_, total)) => {
                    self.fit.grow(self.ctx, total)?;
                    self.regrowths += 1;
                }
            }
        }
    }

    /// The loop: iterations `first ..= last`, each submission ending where `span` says (given
    /// the fitter and the submission's first iteration, it returns the submission's last and may
    /// prepare the fit for it: a new stage's target), a submission the gate stopped run again
    /// from the stopped iteration, and `done(fitter, first, last)` after each submission that
    /// ran (read the losses, report, checkpoint); `false` from it stops the loop. Returns the
    /// last iteration that ran (`first − 1` when none did).
    pub fn drive(
        &mut self,
        first: u32,
        last: u32,
        mut span: impl FnMut(&mut Self, u32) -> Result<u32>,
        mut done: impl FnMut(&mut Self, u32, u32) -> Result<bool>,
    ) -> Result<u32> {
        let mut ran = first.saturating_sub(1);
        let mut it = first;
        while it <= last {
            let end = span(self, it)?.min(last);
            if let Some(stopped) = self.run(it, end, None)? {
                it = stopped;
                continue;
            }
            ran = end;
            if !done(self, it, end)? {
                break;
            }
            it = end + 1;
        }
        Ok(ran)
    }

    /// Submissions the gate stopped (each grew the capacity and ran again).
    pub fn regrowths(&self) -> u32 {
        self.regrowths
    }

    /// The entry count of the last iteration that ran.
    pub fn last_entries(&self) -> u64 {
        self.last_entries
    }

    /// The fit.
    pub fn into_fit(self) -> F {
        self.fit
    }
}

impl<F> Deref for Fitter<'_, F> {
    type Target = F;
    fn deref(&self) -> &F {
        &self.fit
    }
}

impl<F> DerefMut for Fitter<'_, F> {
    fn deref_mut(&mut self) -> &mut F {
        &mut self.fit
    }
}

/// `last` cut where the stage (`stage` of the 0-based iteration) changes after `it`'s: a
/// submission within one stage.
pub fn to_stage_end<S: PartialEq>(it: u32, last: u32, stage: impl Fn(u32) -> S) -> u32 {
    let here = stage(it - 1);
    (it..=last)
        .find(|&i| stage(i - 1) != here)
        .map_or(last, |end| end - 1)
}

/// The submission plan most loops use: from iteration `it`, up to the next multiple of `every`
/// (the next logged iteration).
pub fn to_next_log(it: u32, every: u32) -> u32 {
    ((it - 1) / every + 1).saturating_mul(every)
}

/// The entry capacity of a fit's guarded binning for a count of `total`: with
/// [`ENTRY_HEADROOM`], at most `max` (what the device holds); [`Error::DeviceLimit`]
/// naming `what` and `hint` when even `total` is over it. Every fit of softvk shares it.
pub fn with_headroom(
    ctx: &Context,
    what: &str,
    total: u64,
    max: u64,
    hint: &'static str,
) -> Result<u64> {
    if total > max {
        return Err(Error::DeviceLimit {
            kind: LimitKind::BinEntries,
            what: what.to_string(),
            need: total,
            max,
            device: ctx.info().name.clone(),
            hint,
        });
    }
    let (num, den) = ENTRY_HEADROOM;
    Ok((total * num / den).clamp(total.max(1), max))
}

/// The most (face, tile) entries a fit's guarded binning of `scene` may reserve: what one
/// binning holds, and what one binding of the backward's partials holds.
pub fn max_entry_capacity(ctx: &Context, renderer: &Renderer, scene: &GpuScene) -> u64 {
    let s = scene.settings();
    let stride = grad_stride(s.color_mode, scene.texture_res());
    renderer
        .max_entries(ctx)
        .min(u64::from(ctx.info().limits.max_storage_buffer_range) / (4 * u64::from(stride)))
        .min(u64::from(u32::MAX))
}

/// The guarded fits' sizing step: bins for `scene` with `capacity` entries on `tile`-pixel
/// tiles ([`Renderer::reserve_guarded`]) and the backward's buffers for them, differentiating
/// alpha only when `alpha_only` ([`GradBuffers::set_alpha_only`]).
///
/// [`Renderer::reserve_guarded`]: Renderer::reserve_guarded
/// [`GradBuffers::set_alpha_only`]: GradBuffers::set_alpha_only
pub fn reserve_guarded(
    ctx: &Context,
    renderer: &Renderer,
    scene: &GpuScene,
    tile: u32,
    capacity: u64,
    alpha_only: bool,
) -> Result<(GuardedBins, GradBuffers)> {
    let bins = renderer.reserve_guarded(ctx, scene, tile, capacity)?;
    let mut grads = GradBuffers::guarded(ctx, scene, &bins)?;
    grads.set_alpha_only(alpha_only);
    Ok((bins, grads))
}
