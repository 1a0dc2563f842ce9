//! Both reconstruction trainers in a [`Session`](crate::fit::session::Session), like every fit:
//! their log row ([`TrainRow`]), their state (the settings, the parameters and Adam's moments)
//! and what a resumed run must match ([`fingerprint`], [`check_resume`]).
//!
//! A checkpoint is the one format of [`crate::fit::checkpoint`], kind
//! [`FitKind::ReconMesh`] or [`FitKind::ReconField`]; its fingerprint names the network's
//! shape, and its state starts with the run's [`SETTINGS`] settings, which a resume compares
//! with its own: the same, except that the learning rate's step may differ where it has not
//! acted yet.

use super::field::{FieldReconTraining, FieldTrainOptions};
use super::model::SETTINGS;
use super::train::{NetShape, ReconTraining, TrainOptions, TrainedParams};
use crate::error::{Error, Result};
use crate::field::MlpLayout;
use crate::fit::checkpoint::{Fingerprint, FitKind, Reader, Writer, read_adam};
use crate::fit::log::Columns;
use crate::fit::session::{LogRow, Resume, Trainee};
use crate::gpu::Context;

/// One logged iteration of either trainer: its losses (a conditioned field has only the
/// silhouette loss: the others are 0 and its total is it).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrainRow {
    /// The iteration (from 1).
    pub iteration: u32,
    /// The silhouette loss.
    pub silhouette: f64,
    /// The colour loss.
    pub color: f64,
    /// The Laplacian loss.
    pub laplacian: f64,
    /// The flatten loss.
    pub flatten: f64,
    /// The weighted total.
    pub total: f64,
}

impl LogRow for TrainRow {
    fn iteration(&self) -> u32 {
        self.iteration
    }
    fn loss(&self) -> f64 {
        self.total
    }
    fn columns(&mut self, c: &mut dyn Columns) {
        c.u32("iteration", &mut self.iteration);
        c.f64("silhouette", &mut self.silhouette);
        c.f64("color", &mut self.color);
        c.f64("laplacian", &mut self.laplacian);
        c.f64("flatten", &mut self.flatten);
        c.f64("total", &mut self.total);
    }
}

impl TrainOptions {
    /// The settings a checkpoint carries: `[seed, batch, lr, β1, β2, λ_lap, λ_flat, λ_col, σ,
    /// the lr step's iteration (0: none), its factor, the recipe's code]`.
    pub fn settings(&self) -> [f64; SETTINGS] {
        let step = self
            .lr_step
            .map_or([0.0, 1.0], |s| [f64::from(s.at), s.factor]);
        [
            self.seed as f64,
            f64::from(self.batch),
            self.adam.lr,
            self.adam.betas.0,
            self.adam.betas.1,
            f64::from(self.laplacian),
            f64::from(self.flatten),
            f64::from(self.color),
            self.sigma,
            step[0],
            step[1],
            self.recipe.code(),
        ]
    }
}

impl FieldTrainOptions {
    /// The settings a checkpoint carries: as [`TrainOptions::settings`], with the rays per
    /// view, the anchors, τ and the tile size where the mesh's hold its λs and σ, and recipe 0.
    pub fn settings(&self) -> [f64; SETTINGS] {
        let step = self
            .lr_step
            .map_or([0.0, 1.0], |s| [f64::from(s.at), s.factor]);
        let p = &self.probe;
        [
            self.seed as f64,
            f64::from(self.batch),
            self.adam.lr,
            self.adam.betas.0,
            self.adam.betas.1,
            f64::from(p.rays_per_view),
            f64::from(p.anchors),
            p.tau,
            f64::from(p.tile_size),
            step[0],
            step[1],
            0.0,
        ]
    }
}

/// The fingerprint a trainer's checkpoint carries: the encoder's shape and, for a conditioned
/// field, the MLP's.
pub fn fingerprint(net: &NetShape, field: Option<MlpLayout>) -> u64 {
    let mut f = Fingerprint::default();
    f.add(format!("{net:?} {field:?}").as_bytes());
    f.value()
}

/// The settings a checkpoint's state starts with.
pub fn checkpoint_settings(resume: &Resume<TrainRow>) -> Result<[f64; SETTINGS]> {
    let mut r = Reader::new(&resume.state);
    let mut s = [0.0; SETTINGS];
    for x in &mut s {
        *x = r.f64()?;
    }
    Ok(s)
}

/// Whether a run with `now`'s settings would have run a checkpoint's first `done` iterations
/// as `then`'s did: the same settings, except that the learning rate's step may differ where
/// it has not acted yet (both steps later than `done`, or none).
pub fn same_past(then: &[f64; SETTINGS], now: &[f64; SETTINGS], done: u32) -> bool {
    let unacted = |s: &[f64; SETTINGS]| s[9] == 0.0 || s[9] > f64::from(done);
    then[..9] == now[..9]
        && then[11] == now[11]
        && (then[9..11] == now[9..11] || (unacted(then) && unacted(now)))
}

/// [`Error::Input`] (naming `path`) unless a run of `now`'s settings may go on from `resume`
/// ([`same_past`]).
pub fn check_resume(
    path: &std::path::Path,
    resume: &Resume<TrainRow>,
    net: &NetShape,
    field: Option<MlpLayout>,
    now: &[f64; SETTINGS],
) -> Result<()> {
    let then = checkpoint_settings(resume)?;
    if !same_past(&then, now, resume.iteration) {
        return Err(Error::Input(format!(
            "{}: written by a run with other options (network {net:?}, field {field:?}, \
             settings {then:?})",
            path.display()
        )));
    }
    Ok(())
}

/// Writes a trainer's state: its settings, then its parameters and Adam's moments.
fn save(
    ctx: &Context,
    settings: &[f64; SETTINGS],
    t: &TrainedParams,
    w: &mut Writer,
) -> Result<()> {
    for &x in settings {
        w.f64(x);
    }
    let (m, v) = t.read_moments(ctx)?;
    w.f32s(&t.read_params(ctx)?);
    w.f32s(&m);
    w.f32s(&v);
    Ok(())
}

/// Reads what [`save`] wrote (the settings were checked by [`check_resume`]) and puts the
/// parameters and moments back.
fn restore(ctx: &Context, t: &TrainedParams, r: &mut Reader<'_>) -> Result<()> {
    for _ in 0..SETTINGS {
        r.f64()?;
    }
    let n = t.read_params(ctx)?.len();
    let [p, m, v] = read_adam(r, n, "the network")?;
    t.write_params(ctx, &p)?;
    t.write_moments(ctx, &m, &v)
}

/// A mesh network's training: a row per submission (its last iteration's losses, read back).
/// A row whose total is not finite ends the run with an error: training diverged.
impl Trainee for ReconTraining<'_> {
    type Row = TrainRow;
    const KIND: FitKind = FitKind::ReconMesh;

    fn rows(
        &mut self,
        _ctx: &Context,
        _first: u32,
        last: u32,
        _entries: u64,
        _seconds: f64,
    ) -> Result<Vec<TrainRow>> {
        let l = self.read_log(last)?;
        diverged(TrainRow {
            iteration: last,
            silhouette: f64::from(l.silhouette),
            color: f64::from(l.color),
            laplacian: f64::from(l.laplacian),
            flatten: f64::from(l.flatten),
            total: f64::from(l.total),
        })
    }

    fn save_state(&self, ctx: &Context, w: &mut Writer) -> Result<()> {
        save(ctx, &self.options().settings(), self.trained(), w)
    }

    fn restore_state(&mut self, ctx: &Context, r: &mut Reader<'_>) -> Result<()> {
        restore(ctx, self.trained(), r)
    }
}

/// A conditioned field's training: a row per submission, as the mesh network's.
impl Trainee for FieldReconTraining<'_> {
    type Row = TrainRow;
    const KIND: FitKind = FitKind::ReconField;

    fn rows(
        &mut self,
        _ctx: &Context,
        _first: u32,
        last: u32,
        _entries: u64,
        _seconds: f64,
    ) -> Result<Vec<TrainRow>> {
        let l = f64::from(self.read_log(last)?.silhouette);
        diverged(TrainRow {
            iteration: last,
            silhouette: l,
            color: 0.0,
            laplacian: 0.0,
            flatten: 0.0,
            total: l,
        })
    }

    fn save_state(&self, ctx: &Context, w: &mut Writer) -> Result<()> {
        save(ctx, &self.options().settings(), self.trained(), w)
    }

    fn restore_state(&mut self, ctx: &Context, r: &mut Reader<'_>) -> Result<()> {
        restore(ctx, self.trained(), r)
    }
}

/// `row`, or the error of a run whose loss is not finite.
fn diverged(row: TrainRow) -> Result<Vec<TrainRow>> {
    if !row.total.is_finite() {
        return Err(Error::Input(format!(
            "training diverged at iteration {} (loss {}); try a smaller --lr",
            row.iteration, row.total
        )));
    }
    Ok(vec![row])
}
