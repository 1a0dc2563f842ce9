//! The shell around every fitting command's session ([`softvk::fit::session`]), written once:
//! the checkpoint flags turned into a resume and a checkpoint plan ([`CheckpointArgs::session`]),
//! the progress bar and the interrupt check ([`Watch`], [`CheckpointArgs::watched`]), the files
//! planned before the fit and committed after it ([`Outputs`]), the report every fit's log
//! gives (`loss.csv`, `loss.png`, `interrupted.txt`: [`write_loss_report`]) and the summary
//! line with its resume note ([`summary`]).

use std::path::{Path, PathBuf};

use indicatif::{ProgressBar, ProgressStyle};
use softvk::fit::log::{self, LogRow};
use softvk::fit::report::{self, Series};
use softvk::fit::session::{CheckpointPlan, Resume, Session, Trainee};
use softvk::{Error, Result};

use super::args::CheckpointArgs;
use super::interrupt;
use super::output::{AtomicFile, SideFile, side_files};

impl CheckpointArgs {
    /// The session these flags ask for: the checkpoint in `--resume DIR` (file `file`) read and
    /// checked against `fingerprint` (before anything is written: a refused one leaves nothing
    /// behind), then the `--checkpoint DIR` folder created and checkpoints planned into it.
    pub fn session<'h, F: Trainee>(&self, file: &str, fingerprint: u64) -> Result<Session<'h, F>> {
        self.session_in(file, fingerprint, None)
    }

    /// [`CheckpointArgs::session`], checkpointing into `default`'s folder every `default`'s
    /// iterations when `--checkpoint` is not given (a trainer always checkpoints).
    pub fn session_in<'h, F: Trainee>(
        &self,
        file: &str,
        fingerprint: u64,
        default: Option<(&Path, u32)>,
    ) -> Result<Session<'h, F>> {
        let resume = match &self.resume {
            Some(dir) => Some(Resume::read(&dir.join(file), F::KIND, fingerprint)?),
            None => None,
        };
        if self.checkpoint_every == 0 {
            return Err(Error::Input("--checkpoint-every must be at least 1".into()));
        }
        let planned = match (&self.checkpoint, default) {
            (Some(dir), _) => Some((dir.as_path(), self.checkpoint_every)),
            (None, d) => d,
        };
        let plan = match planned {
            Some((dir, every)) => {
                std::fs::create_dir_all(dir)
                    .map_err(|e| Error::Input(format!("cannot create {}: {e}", dir.display())))?;
                Some(CheckpointPlan {
                    path: dir.join(file),
                    fingerprint,
                    every,
                })
            }
            None => None,
        };
        Ok(Session::new().resume(resume).checkpoint(plan))
    }

    /// [`CheckpointArgs::session`] watched by a [`Watch`] of `iterations` (hidden with
    /// `quiet`) that shows `message` of each submission's last row and stops the session at an
    /// interrupt.
    pub fn watched<'h, F: Trainee + 'h>(
        &self,
        file: &str,
        fingerprint: u64,
        quiet: bool,
        iterations: u32,
        message: impl Fn(&F::Row) -> String + 'h,
    ) -> Result<(Session<'h, F>, Watch)> {
        let session = self.session(file, fingerprint)?;
        let watch = Watch::new(quiet, u64::from(iterations));
        let bar = watch.clone();
        let session = session.on_row(move |row: &F::Row| bar.update(row.iteration(), message(row)));
        Ok((session, watch))
    }
}

/// A fitting command's progress bar (hidden with `--quiet`) and interrupt check; a clone shows
/// the same bar.
#[derive(Clone)]
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

/// After an interrupt ([`interrupt`]), what a fit's result says of it: the signal, and that it
/// stopped after iteration `done` of `asked`.
pub fn interrupted(done: u32, asked: u32) -> Option<String> {
    interrupt::requested().map(|signal| {
        format!(
            "{}: stopped after iteration {done} of {asked}",
            interrupt::name(signal)
        )
    })
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

/// The report every fit's and trainer's log gives, in `dir`: `loss.csv` (the log's columns,
/// [`log::csv`]), `loss.png` (`plot`) and `interrupted.txt` ([`write_interrupted`]; `done` of
/// `asked` iterations ran).
pub fn write_loss_report<R: LogRow>(
    dir: &Path,
    log: &[R],
    plot: &LossPlot,
    done: u32,
    asked: u32,
) -> Result<()> {
    report::write_png(
        &dir.join("loss.png"),
        &report::loss_plot(&plot.series, plot.width, plot.height, plot.log_y),
    )?;
    AtomicFile::create(&dir.join("loss.csv"))?.commit(log::csv(log).as_bytes())?;
    write_interrupted(dir, done, asked)
}

/// `loss.png`: its curves and size, and whether its loss axis is logarithmic.
pub struct LossPlot {
    /// The curves ([`curve`]).
    pub series: Vec<Series>,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// A logarithmic loss axis.
    pub log_y: bool,
}

/// The curve of `log`'s column `column`, named `name` in the legend, in `color`, each value
/// times `scale`.
pub fn curve<R: LogRow>(log: &[R], column: &str, name: &str, color: [u8; 3], scale: f64) -> Series {
    let points = log::column(log, column).unwrap_or_else(|| panic!("no column `{column}`"));
    Series {
        name: name.into(),
        points: if scale == 1.0 {
            points
        } else {
            points.into_iter().map(|(x, y)| (x, scale * y)).collect()
        },
        color,
    }
}

/// A fit's summary line: the resume note ([`interrupt::resumed_note`]; `first` is the first
/// iteration this run ran), then `N iterations in S s (M ms per iteration)`, `what` (which
/// starts with its own separator), and `wrote A, B and C`.
pub fn summary(first: u32, done: u32, seconds: f64, what: &str, wrote: &[&Path]) -> String {
    let names: Vec<String> = wrote.iter().map(|p| p.display().to_string()).collect();
    let wrote = match names.split_last() {
        Some((last, [])) => last.clone(),
        Some((last, rest)) => format!("{} and {last}", rest.join(", ")),
        None => String::new(),
    };
    format!(
        "{}{done} iterations in {seconds:.1} s ({:.1} ms per iteration){what}; wrote {wrote}",
        interrupt::resumed_note(first, done),
        1e3 * seconds / f64::from(done.max(1)),
    )
}

/// The files a command writes, hidden until all are ready (`--out` and its side files,
/// [`side_files`]), each created before the fit (a path that cannot be written fails before
/// any work) and all committed after it, or none.
pub struct Outputs {
    /// `--out`, then the side files, in order.
    pub paths: Vec<PathBuf>,
    files: Vec<AtomicFile>,
}

impl Outputs {
    /// `paths`, created.
    pub fn create(paths: impl IntoIterator<Item = PathBuf>) -> Result<Outputs> {
        let paths: Vec<PathBuf> = paths.into_iter().collect();
        let files = paths
            .iter()
            .map(|p| AtomicFile::create(p))
            .collect::<Result<_>>()?;
        Ok(Outputs { paths, files })
    }

    /// `out` and its side files `side` ([`side_files`]: `<stem><suffix>` beside `out` by
    /// default; `stem` when `out` has none), created.
    pub fn beside(out: &Path, stem: &str, side: &[SideFile<'_>]) -> Result<Outputs> {
        let side = side_files(out, stem, side)?;
        Outputs::create(std::iter::once(out.to_path_buf()).chain(side))
    }

    /// Writes `contents` (one for each path, in order).
    pub fn commit(self, contents: &[&[u8]]) -> Result<()> {
        assert_eq!(contents.len(), self.files.len(), "one content a file");
        for (file, bytes) in self.files.into_iter().zip(contents) {
            file.commit(bytes)?;
        }
        Ok(())
    }
}
