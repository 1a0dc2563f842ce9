//! One resumable session around every fit's and trainer's loop: the schedule of submissions,
//! the log, checkpoints and resume, the hooks a caller watches through (progress, interrupt),
//! and the stopping rule.
//!
//! A fit says only what is its own: its iterations ([`Fit`], run by [`Fitter`]), its log row's
//! columns ([`LogRow`], [`super::log`]), and the state a resumed fit needs ([`Trainee::save_state`] /
//! [`Trainee::restore_state`]: parameters and Adam's moments). [`Session::run`] does the rest:
//!
//! - **Submissions**: from the first iteration to the last, each ending where the fit's plan
//!   says (by default the next logged iteration, [`driver::to_next_log`]), through
//!   [`Fitter::drive`] (which re-runs an iteration whose binning outgrew its capacity).
//! - **The log**: after each submission, the fit's rows for its iterations
//!   ([`Trainee::rows`]), stamped with the session's seconds (those before a resume included).
//! - **Hooks** ([`Hooks`]): after each submission, with a [`Progress`] view of the fit and
//!   its log; returning `false` stops the session there (an interrupt).
//! - **Checkpoints** ([`CheckpointPlan`]): the state and the log written atomically every N
//!   iterations, at the end and when the session stops early, in the one checkpoint format of
//!   [`super::checkpoint`]; [`Resume::read`] reads one back (refusing another kind of fit,
//!   other inputs, another format or softvk version, or a damaged file, each with one line),
//!   and a session resumed from it ends bit for bit as the session that never stopped (softvk
//!   is deterministic, and every random number is keyed by the iteration).
//! - **Validation** ([`Session::validate`]): a score every N iterations (submissions end
//!   there), logged beside the rows and carried by checkpoints (the reconstruction trainers').
//! - **The stopping rule** ([`StopRule`]): a session may end when its loss has stopped
//!   improving (the pose fits' refinement).
//!
//! What a new fit needs, then: its [`Fit`] (the recording of an iteration), a [`LogRow`] and
//! a [`Trainee`] impl (its row, its state: about 70 lines for the articulated fit), a
//! fingerprint of its inputs, and a function that builds its [`Fitter`] and calls
//! [`Session::run`]; its command-line folder parses arguments (`args.rs`) and writes outputs.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::checkpoint::{Checkpoint, FitKind, Reader, Writer};
use super::driver::{self, Fit, Fitter};
pub use super::log::LogRow;
use super::log::{read_log, write_log};
use crate::error::{Error, Result};
use crate::gpu::Context;

/// What a [`Fit`] adds to run in a [`Session`]: its log row, and its state.
pub trait Trainee: Fit {
    /// Its log row.
    type Row: LogRow;
    /// Its kind of checkpoint.
    const KIND: FitKind;

    /// The rows of iterations `first ..= last`, which have just run (the last of them with
    /// `entries` (face, tile) entries), `seconds` into the session.
    fn rows(
        &mut self,
        ctx: &Context,
        first: u32,
        last: u32,
        entries: u64,
        seconds: f64,
    ) -> Result<Vec<Self::Row>>;

    /// Writes what a resumed session needs besides the log (the parameters and the optimizer's
    /// moments), read from the device now.
    fn save_state(&self, ctx: &Context, w: &mut Writer) -> Result<()>;

    /// Puts back what [`Trainee::save_state`] wrote, checking it (sizes, finiteness).
    fn restore_state(&mut self, ctx: &Context, r: &mut Reader<'_>) -> Result<()>;
}

/// Where and how often a session checkpoints, and what names its inputs.
#[derive(Clone, Debug)]
pub struct CheckpointPlan {
    /// The checkpoint file (replaced atomically each time).
    pub path: PathBuf,
    /// The fingerprint of the fit's inputs the checkpoints carry (each fit has a function for
    /// it, e.g. [`crate::fit::mesh_fit::MeshFit::fingerprint`]); [`Resume::read`] refuses a
    /// checkpoint of another.
    pub fingerprint: u64,
    /// Iterations between checkpoints, rounded up to a multiple of the logging interval; one
    /// is also written at the end and when the session stops early.
    pub every: u32,
}

/// When a session ends before its last iteration because its loss stopped improving: once
/// `window` iterations have passed since the best loss so far (over the rows logged from
/// iteration `from`) without a row below `best × (1 − min_improvement)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopRule {
    /// The first iteration whose row counts (before it, the session never stops: a schedule's
    /// early stages, whose losses are not comparable with the last stage's).
    pub from: u32,
    /// Iterations without improvement that end the session.
    pub window: u32,
    /// The relative improvement that counts as one.
    pub min_improvement: f64,
}

impl StopRule {
    /// Whether `log` (in iteration order) has stopped improving.
    pub fn stalled<R: LogRow>(&self, log: &[R]) -> bool {
        let mut best: Option<(f64, u32)> = None;
        for r in log.iter().filter(|r| r.iteration() >= self.from) {
            let loss = r.loss();
            match best {
                Some((b, _)) if loss >= b * (1.0 - self.min_improvement) => {}
                _ => best = Some((loss, r.iteration())),
            }
        }
        let last = log.last().map_or(0, LogRow::iteration);
        best.is_some_and(|(_, at)| last >= at + self.window)
    }
}

/// A checkpoint read back for a session to go on from.
#[derive(Clone, Debug)]
pub struct Resume<R> {
    /// Iterations done.
    pub iteration: u32,
    /// Seconds they took.
    pub seconds: f64,
    /// Their log.
    pub log: Vec<R>,
    /// Their validations, `(iteration, score)`.
    pub validations: Vec<(u32, f64)>,
    /// The fit's state ([`Trainee::save_state`]'s bytes).
    pub state: Vec<u8>,
}

impl<R: LogRow> Resume<R> {
    /// Reads the checkpoint at `path` of a `kind` fit of inputs of `fingerprint` (see
    /// [`Checkpoint::read`] for what is refused).
    pub fn read(path: &Path, kind: FitKind, fingerprint: u64) -> Result<Self> {
        let c = Checkpoint::read(path, kind, fingerprint)?;
        let mut r = Reader::new(&c.payload);
        let log: Vec<R> = read_log(&mut r, c.iteration)
            .map_err(|e| Error::Input(format!("{}: {e}", path.display())))?;
        let n = r.u32()?;
        if n > c.iteration {
            return Err(Error::Input(format!(
                "{}: checkpoint has more validations than iterations",
                path.display()
            )));
        }
        let validations = (0..n)
            .map(|_| Ok((r.u32()?, r.f64()?)))
            .collect::<Result<Vec<_>>>()?;
        let past = |it: u32| it > c.iteration;
        if log.last().is_some_and(|l| past(l.iteration())) || validations.iter().any(|v| past(v.0))
        {
            return Err(Error::Input(format!(
                "{}: checkpoint log past its iterations",
                path.display()
            )));
        }
        Ok(Self {
            iteration: c.iteration,
            seconds: c.seconds,
            log,
            validations,
            state: r.rest().to_vec(),
        })
    }
}

/// What hooks see after each submission.
pub struct Progress<'a, 'c, F: Trainee> {
    /// The fit (read its state, render a frame).
    pub fitter: &'a Fitter<'c, F>,
    /// The log so far (those of a resumed session included).
    pub log: &'a [F::Row],
    /// The submission's first iteration.
    pub first: u32,
    /// Its last iteration.
    pub last: u32,
    /// The last iteration asked for.
    pub iterations: u32,
    /// The validations so far, `(iteration, score)` ([`Session::validate`]); the last is this
    /// submission's when it ended at a validation boundary.
    pub validations: &'a [(u32, f64)],
}

impl<F: Trainee> Progress<'_, '_, F> {
    /// The last row.
    pub fn row(&self) -> &F::Row {
        self.log.last().expect("a submission logs at least one row")
    }
}

/// What watches a session: called after each submission, `false` stops it there.
pub trait Hooks<F: Trainee> {
    /// After iterations `p.first ..= p.last` ran and were logged.
    fn after(&mut self, p: &Progress<'_, '_, F>) -> Result<bool>;
}

impl<F: Trainee, H: FnMut(&Progress<'_, '_, F>) -> Result<bool>> Hooks<F> for H {
    fn after(&mut self, p: &Progress<'_, '_, F>) -> Result<bool> {
        self(p)
    }
}

/// Hooks that watch nothing.
pub struct NoHooks;

impl<F: Trainee> Hooks<F> for NoHooks {
    fn after(&mut self, _: &Progress<'_, '_, F>) -> Result<bool> {
        Ok(true)
    }
}

/// Why a session ended before its last iteration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stopped {
    /// A hook said so (an interrupt).
    Hook,
    /// The [`StopRule`].
    Converged,
}

/// A finished session.
#[derive(Clone, Debug)]
pub struct SessionEnd<R> {
    /// The whole log (a resumed session's earlier rows first).
    pub log: Vec<R>,
    /// The validations, `(iteration, score)` (those of a resumed session first).
    pub validations: Vec<(u32, f64)>,
    /// The first iteration this run ran (after a resume, the checkpoint's + 1).
    pub first: u32,
    /// The last iteration that ran.
    pub last: u32,
    /// Seconds of iterations, those before a resume included.
    pub seconds: f64,
    /// Seconds of this run spent after submissions: reading rows, the hooks and checkpoints.
    pub logging_seconds: f64,
    /// Why it ended early, if it did.
    pub stopped: Option<Stopped>,
}

/// A session's settings besides the fit's own: checkpoints, a resume, the stopping rule and
/// the hooks. The default has none of them.
pub struct Session<'h, F: Trainee> {
    /// Checkpoints, if any.
    pub checkpoint: Option<CheckpointPlan>,
    /// A checkpoint to go on from.
    pub resume: Option<Resume<F::Row>>,
    /// The stopping rule, if any.
    pub stop: Option<StopRule>,
    hooks: Box<dyn Hooks<F> + 'h>,
    validation: Option<(u32, Validator<'h, F>)>,
}

/// What scores a fit at validation boundaries ([`Session::validate`]).
type Validator<'h, F> = Box<dyn FnMut(&Progress<'_, '_, F>) -> Result<f64> + 'h>;

impl<F: Trainee> Default for Session<'_, F> {
    fn default() -> Self {
        Self::new()
    }
}

impl<'h, F: Trainee> Session<'h, F> {
    /// No checkpoint, resume, stopping rule or hook.
    pub fn new() -> Self {
        Self {
            checkpoint: None,
            resume: None,
            stop: None,
            hooks: Box::new(NoHooks),
            validation: None,
        }
    }

    /// With `hooks` after each submission.
    pub fn hooks(mut self, hooks: impl Hooks<F> + 'h) -> Self {
        self.hooks = Box::new(hooks);
        self
    }

    /// With hooks that see only the last row of each submission (`false` stops).
    pub fn on_row(self, mut f: impl FnMut(&F::Row) -> bool + 'h) -> Self
    where
        F: 'h,
    {
        self.hooks(move |p: &Progress<'_, '_, F>| Ok(f(p.row())))
    }

    /// Validation every `every` iterations and after the last: submissions end there, and
    /// `score` (given the fit after that iteration) is logged beside the rows, seen by the
    /// hooks, and carried by checkpoints.
    pub fn validate(
        mut self,
        every: u32,
        score: impl FnMut(&Progress<'_, '_, F>) -> Result<f64> + 'h,
    ) -> Self {
        self.validation = Some((every.max(1), Box::new(score)));
        self
    }

    /// Checkpointing as `plan` says.
    pub fn checkpoint(mut self, plan: Option<CheckpointPlan>) -> Self {
        self.checkpoint = plan;
        self
    }

    /// Going on from `resume`.
    pub fn resume(mut self, resume: Option<Resume<F::Row>>) -> Self {
        self.resume = resume;
        self
    }

    /// Ending early by `rule`.
    pub fn stop(mut self, rule: Option<StopRule>) -> Self {
        self.stop = rule;
        self
    }

    /// The first iteration [`Session::run`] will run.
    pub fn first_iteration(&self) -> u32 {
        self.resume.as_ref().map_or(1, |r| r.iteration + 1)
    }

    /// Runs `fitter` from the first iteration (after the resumed checkpoint's, whose state it
    /// restores) to iteration `iterations`, each submission ending where `plan` (given the
    /// fitter and the submission's first iteration) says, logging, calling the hooks,
    /// checkpointing (every multiple of `log_every` past the plan's interval) and applying the
    /// stopping rule.
    pub fn run<'c>(
        self,
        fitter: &mut Fitter<'c, F>,
        (iterations, log_every): (u32, u32),
        mut plan: impl FnMut(&mut Fitter<'c, F>, u32) -> Result<u32>,
    ) -> Result<SessionEnd<F::Row>> {
        let Session {
            checkpoint,
            resume,
            stop,
            mut hooks,
            mut validation,
        } = self;
        if iterations == 0 || log_every == 0 {
            return Err(Error::Input(format!(
                "{}: iterations and the logging interval must be at least 1",
                F::NAME
            )));
        }
        let ctx = fitter.ctx();
        let (mut log, mut validations, first, earlier) = match resume {
            Some(resume) => {
                if resume.iteration > iterations {
                    return Err(Error::Input(format!(
                        "resume: the state is after iteration {}, past the {iterations} asked",
                        resume.iteration
                    )));
                }
                let mut r = Reader::new(&resume.state);
                fitter.restore_state(ctx, &mut r)?;
                if !r.done() {
                    return Err(Error::Input(
                        "checkpoint has bytes after the fit's state".into(),
                    ));
                }
                (
                    resume.log,
                    resume.validations,
                    resume.iteration + 1,
                    resume.seconds,
                )
            }
            None => (Vec::new(), Vec::new(), 1, 0.0),
        };
        let validate_every = validation.as_ref().map(|v| v.0);
        let checkpoint_every = checkpoint
            .as_ref()
            .map(|c| c.every.max(1).div_ceil(log_every) * log_every);
        let start = Instant::now();
        let mut stopped = None;
        let mut logging_seconds = 0.0;
        // A checkpoint written where the rule ended the session (its last one) ends it again.
        let last_before = first - 1;
        let ended = last_before > 0 && stop.is_some_and(|s| s.stalled(&log));
        if ended {
            stopped = Some(Stopped::Converged);
        }
        let to = if ended { last_before } else { iterations };
        let last = fitter.drive(
            first,
            to,
            |fitter, it| {
                let end = plan(fitter, it)?;
                Ok(validate_every.map_or(end, |every| end.min(driver::to_next_log(it, every))))
            },
            |fitter, a, b| {
                let logging = Instant::now();
                let seconds = earlier + start.elapsed().as_secs_f64();
                let entries = fitter.last_entries();
                log.extend(fitter.rows(ctx, a, b, entries, seconds)?);
                if let Some((every, score)) = &mut validation
                    && (b % *every == 0 || b == iterations)
                {
                    let progress = Progress {
                        fitter,
                        log: &log,
                        first: a,
                        last: b,
                        iterations,
                        validations: &validations,
                    };
                    validations.push((b, score(&progress)?));
                }
                let progress = Progress {
                    fitter,
                    log: &log,
                    first: a,
                    last: b,
                    iterations,
                    validations: &validations,
                };
                let mut go_on = hooks.after(&progress)?;
                if !go_on {
                    stopped = Some(Stopped::Hook);
                } else if b < iterations && stop.is_some_and(|s| s.stalled(&log)) {
                    stopped = Some(Stopped::Converged);
                    go_on = false;
                }
                if let (Some(plan), Some(every)) = (&checkpoint, checkpoint_every)
                    && (!go_on || b % every == 0 || b == iterations)
                {
                    write_checkpoint(fitter, plan, b, seconds, &log, &validations)?;
                }
                logging_seconds += logging.elapsed().as_secs_f64();
                Ok(go_on)
            },
        )?;
        Ok(SessionEnd {
            log,
            validations,
            first,
            last,
            seconds: earlier + start.elapsed().as_secs_f64(),
            logging_seconds,
            stopped,
        })
    }
}

/// Writes the checkpoint of `fitter` after `iteration`: the log, the validations, then the
/// fit's state.
fn write_checkpoint<F: Trainee>(
    fitter: &Fitter<'_, F>,
    plan: &CheckpointPlan,
    iteration: u32,
    seconds: f64,
    log: &[F::Row],
    validations: &[(u32, f64)],
) -> Result<()> {
    let mut w = Writer::default();
    write_log(&mut w, log);
    w.u32(validations.len() as u32);
    for &(it, score) in validations {
        w.u32(it);
        w.f64(score);
    }
    fitter.save_state(fitter.ctx(), &mut w)?;
    Checkpoint {
        kind: F::KIND,
        fingerprint: plan.fingerprint,
        iteration,
        seconds,
        payload: w.0,
    }
    .write(&plan.path)
}

/// The plan most fits use: each submission up to the next logged iteration.
pub fn to_next_log<F>(every: u32) -> impl FnMut(&mut F, u32) -> Result<u32> {
    move |_, it| Ok(driver::to_next_log(it, every))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Clone, Default)]
    struct Row(u32, f64);

    impl LogRow for Row {
        fn iteration(&self) -> u32 {
            self.0
        }
        fn loss(&self) -> f64 {
            self.1
        }
        fn columns(&mut self, c: &mut dyn super::super::log::Columns) {
            c.u32("iteration", &mut self.0);
            c.f64("loss", &mut self.1);
        }
    }

    fn log(losses: &[f64]) -> Vec<Row> {
        (1..).zip(losses).map(|(i, &l)| Row(i, l)).collect()
    }

    #[test]
    fn the_stopping_rule_waits_a_window_after_the_last_real_improvement() {
        let rule = StopRule {
            from: 3,
            window: 3,
            min_improvement: 0.01,
        };
        // Rows before `from` never count: a high loss there is no best to beat.
        assert!(!rule.stalled(&log(&[0.1, 0.1, 5.0, 4.0, 3.0])));
        // Best at 5 (3.0); 6..8 improve by less than 1 %: stalled once 8 ≥ 5 + 3.
        let l = [9.0, 9.0, 5.0, 4.0, 3.0, 2.99, 2.985, 2.98];
        assert!(!rule.stalled(&log(&l[..7])));
        assert!(rule.stalled(&log(&l)));
        // A fall of more than 1 % moves the best, and the window starts again.
        let l = [9.0, 9.0, 5.0, 4.0, 3.0, 2.99, 2.985, 2.9];
        assert!(!rule.stalled(&log(&l)));
        // A rise never counts as an improvement.
        assert!(rule.stalled(&log(&[9.0, 9.0, 1.0, 2.0, 3.0, 4.0])));
        // Nothing logged from `from` on: never stalled.
        assert!(!rule.stalled(&log(&[1.0, 1.0])));
    }
}
