//! What every fitting command shares around its session ([`softvk::fit::session`]): the
//! checkpoint flags turned into a resume and a checkpoint plan, the progress bar, the interrupt
//! check, and the note an interrupted run leaves.

use std::path::Path;

use indicatif::{ProgressBar, ProgressStyle};
use softvk::fit::session::{CheckpointPlan, Resume, Session, Trainee};
use softvk::{Error, Result};

use super::args::CheckpointArgs;
use super::interrupt;
use super::output::AtomicFile;

impl CheckpointArgs {
    /// The session these flags ask for: the checkpoint in `--resume DIR` (file `file`) read and
    /// checked against `fingerprint` (before anything is written: a refused one leaves nothing
    /// behind), then the `--checkpoint DIR` folder created and checkpoints planned into it.
    pub fn session<'h, F: Trainee>(&self, file: &str, fingerprint: u64) -> Result<Session<'h, F>> {
        let resume = match &self.resume {
            Some(dir) => Some(Resume::read(&dir.join(file), F::KIND, fingerprint)?),
            None => None,
        };
        if self.checkpoint_every == 0 {
            return Err(Error::Input("--checkpoint-every must be at least 1".into()));
        }
        let plan = match &self.checkpoint {
            Some(dir) => {
                std::fs::create_dir_all(dir)
                    .map_err(|e| Error::Input(format!("cannot create {}: {e}", dir.display())))?;
                Some(CheckpointPlan {
                    path: dir.join(file),
                    fingerprint,
                    every: self.checkpoint_every,
                })
            }
            None => None,
        };
        Ok(Session::new().resume(resume).checkpoint(plan))
    }
}

/// A fitting command's progress bar (hidden with `--quiet`) and interrupt check.
pub struct Watch {
    bar: ProgressBar,
}

impl Watch {
    /// A bar of `length` iterations.
    pub fn new(quiet: bool, length: u64) -> Self {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(length).with_style(
                ProgressStyle::with_template(
                    "{bar:40} {pos}/{len} iterations  {msg}  [{elapsed} < {eta}]",
                )
                .expect("a valid template"),
            )
        };
        Self { bar }
    }

    /// The bar.
    pub fn bar(&self) -> &ProgressBar {
        &self.bar
    }

    /// After a submission: the bar at `position` with `message`; whether to go on (no
    /// interrupt asked for).
    pub fn update(&self, position: u32, message: String) -> bool {
        self.bar.set_position(u64::from(position));
        self.bar.set_message(message);
        interrupt::requested().is_none()
    }

    /// A line above the bar (on standard error when it is hidden).
    pub fn println(&self, line: String) {
        if self.bar.is_hidden() {
            eprintln!("{line}");
        } else {
            self.bar.println(line);
        }
    }

    /// Clears the bar.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// After an interrupt ([`interrupt`]), `interrupted.txt` in the report folder says so: the
/// report and the result are the fit's state after iteration `done` of `asked`. A fit that ends
/// normally removes one an earlier, interrupted run left (a resumed fit's report is whole).
pub fn write_interrupted(report_dir: &Path, done: u32, asked: u32) -> Result<()> {
    let path = report_dir.join("interrupted.txt");
    match interrupt::requested() {
        Some(signal) => {
            let line = format!(
                "{}: stopped after iteration {done} of {asked}; the result and this report are \
                 the fit's state then\n",
                interrupt::name(signal)
            );
            AtomicFile::create(&path)?.commit(line.as_bytes())
        }
        None => match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                Err(Error::Io { path, source: e })
            }
            _ => Ok(()),
        },
    }
}
