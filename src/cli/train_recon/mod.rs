//! `softvk train-recon --dataset DIR --out MODEL [--iters N] [--field]`: trains the network on
//! the dataset's train split ([`softvk::recon::train`]; with `--field` the conditioned implicit
//! field of [`softvk::recon::field`]) in a fit session ([`softvk::fit::session`]), k
//! iterations per submission, with a progress bar, a loss log and plot, the validation split's
//! 3D IoU every `--val-every` iterations, and checkpoints (`--resume` goes on from the last
//! one, bit for bit).

use std::path::{Path, PathBuf};

use softvk::field::MlpLayout;
use softvk::fit::driver::{Fitter, to_next_log};
use softvk::fit::report::Series;
use softvk::fit::session::{Progress, Session, Trainee};
use softvk::gpu::{Context, ContextOptions};
use softvk::recon::dataset::{Dataset, Split};
use softvk::recon::field::FieldReconTraining;
use softvk::recon::model::ReconModel;
use softvk::recon::model::SETTINGS;
use softvk::recon::reconstruct::{spread_views, validation_iou};
use softvk::recon::session::{self, TrainRow};
use softvk::recon::train::{NetShape, ReconTraining, TrainImages, TrainedParams};
use softvk::{Error, Result};

use crate::cli::interrupt;
use crate::cli::output::AtomicFile;
use crate::cli::session::{LossPlot, Watch, curve, write_loss_report};

mod args;
pub use args::*;

fn report_dir(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}-train"))
}

/// `softvk train-recon`.
pub fn train(args: &TrainReconArgs) -> Result<()> {
    let data = Dataset::open(&args.dataset, Split::Train)?;
    let val = match Dataset::open(&args.dataset, Split::Val) {
        Ok(v) if !v.classes.is_empty() => Some(v),
        _ => None,
    };
    let net = args.net();
    let (mesh_opts, field_opts) = (args.mesh_options(), args.field_options());
    let field_layout = args.field.then_some(field_opts.net.mlp);
    let settings = if args.field {
        field_opts.settings()
    } else {
        mesh_opts.settings()
    };
    let per_iteration = if args.field {
        field_opts.batch
    } else {
        mesh_opts.inputs()
    };
    let iterations = match args.images {
        None => args.iters,
        Some(images) => u32::try_from(images.div_ceil(u64::from(per_iteration)))
            .map_err(|_| Error::Input(format!("--images {images}: over 2^32 iterations")))?,
    };
    let dir = report_dir(&args.out);
    let fingerprint = session::fingerprint(&net, field_layout);
    let shape = Shape {
        net: &net,
        field: field_layout,
        settings: &settings,
        fingerprint,
    };
    let ctx = Context::new(&ContextOptions::from_env())?;
    let images = TrainImages::from_dataset(data);
    let run = TrainingRun {
        args,
        ctx: &ctx,
        val,
        dir: dir.clone(),
        model_of: |params: Vec<f32>, iteration: u32| ReconModel {
            net,
            field: field_layout,
            params,
            iteration,
        },
        iterations,
        per_iteration,
    };
    if args.field {
        let session = shape.session(args, &dir)?;
        let trainer = FieldReconTraining::fitter(&ctx, &images, &field_opts, None)?;
        run.go(trainer, session)
    } else {
        let session = shape.session(args, &dir)?;
        run.go(
            ReconTraining::fitter(&ctx, &images, &mesh_opts, None)?,
            session,
        )
    }
}

/// The checkpoint's file in the report folder (or `--checkpoint DIR`).
const CHECKPOINT_FILE: &str = "checkpoint.ckpt";

/// What a trainer's checkpoint must match: the network's shape and the run's settings.
struct Shape<'a> {
    net: &'a NetShape,
    field: Option<MlpLayout>,
    settings: &'a [f64; SETTINGS],
    fingerprint: u64,
}

impl Shape<'_> {
    /// The checkpoint flags' session: `--resume DIR`'s checkpoint read and held to this shape
    /// and these settings, and checkpoints into `--checkpoint DIR` or, by default, the report
    /// folder `dir` at each validation.
    fn session<'h, T: Trainee<Row = TrainRow>>(
        &self,
        args: &TrainReconArgs,
        dir: &Path,
    ) -> Result<Session<'h, T>> {
        let c = &args.checkpoints;
        let default = Some((dir, args.val_every));
        let s = c.session_in(CHECKPOINT_FILE, self.fingerprint, default)?;
        if let (Some(r), Some(from)) = (&s.resume, &c.resume) {
            let path = from.join(CHECKPOINT_FILE);
            session::check_resume(&path, r, self.net, self.field, self.settings)?;
        }
        Ok(s)
    }
}

/// A training run's inputs beside its trainer.
struct TrainingRun<'a, M> {
    args: &'a TrainReconArgs,
    ctx: &'a Context,
    val: Option<Dataset>,
    dir: PathBuf,
    /// The model of parameters after an iteration.
    model_of: M,
    /// The last iteration (`--iters`, or `--images` over `per_iteration`).
    iterations: u32,
    /// Input images per iteration.
    per_iteration: u32,
}

impl<M: Fn(Vec<f32>, u32) -> ReconModel> TrainingRun<'_, M> {
    /// Trains to the last iteration in a session (validating and checkpointing every
    /// `--val-every`, stopping at an interrupt with a checkpoint) and writes the model.
    fn go<'c, T>(self, mut trainer: Fitter<'c, T>, session: Session<'_, T>) -> Result<()>
    where
        T: Trainee<Row = TrainRow> + Trained,
    {
        let Self {
            args,
            ctx,
            val,
            dir,
            model_of,
            iterations,
            per_iteration,
        } = self;
        let start = session.resume.as_ref().map_or(0, |r| r.iteration);
        let plan = session
            .checkpoint
            .clone()
            .expect("a trainer always checkpoints");
        std::fs::create_dir_all(&dir)
            .map_err(|e| Error::Input(format!("cannot create {}: {e}", dir.display())))?;
        let val_views = spread_views(args.val_views);
        let watch = Watch::new(false, u64::from(iterations));
        watch.bar().set_position(u64::from(start));
        let model_now = |p: &Progress<'_, '_, T>| -> Result<ReconModel> {
            Ok(model_of(p.fitter.trained().read_params(ctx)?, p.last))
        };
        let hooks = |p: &Progress<'_, '_, T>| {
            let row = p.row();
            let go_on = watch.update(p.last, format!("L_sil {:.4}", row.silhouette));
            let validated = p.validations.last().filter(|v| v.0 == p.last);
            if let Some(&(_, iou)) = validated {
                watch.println(format!(
                    "iteration {}: L_sil {:.4}, validation 3D IoU {iou:.4}",
                    p.last, row.silhouette
                ));
            }
            let at_boundary = p.last % args.val_every == 0 || p.last == iterations;
            if at_boundary || !go_on {
                write_train_report(&dir, p.log, p.validations, (p.last, iterations))?;
            }
            Ok(go_on)
        };
        let mut session = session.hooks(hooks);
        if let Some(val) = &val {
            session = session.validate(args.val_every, |p: &Progress<'_, '_, T>| {
                validation_iou(ctx, &model_now(p)?, val, &val_views)
            });
        }
        // Submissions of `--log-every` iterations, ending at each validation and checkpoint.
        let end = session.run(&mut trainer, (iterations, 1), |_, it| {
            let boundary = to_next_log(it, args.val_every).min(to_next_log(it, plan.every));
            Ok((it + args.log_every - 1).min(boundary))
        })?;
        watch.finish();
        let done = end.last;
        if done < iterations {
            let folder = plan.path.parent().unwrap_or(Path::new("."));
            eprintln!(
                "softvk: stopped after iteration {done} of {iterations}; `--resume {}` goes on \
                 from it",
                folder.display()
            );
            return Ok(());
        }
        model_of(trainer.trained().read_params(ctx)?, done).save(&args.out)?;
        let last = end.log.last().map_or(0.0, |r| r.silhouette);
        println!(
            "{}trained {done} iterations ({} input images): L_sil {last:.4}{}; model {}",
            interrupt::resumed_note(start + 1, done),
            u64::from(done) * u64::from(per_iteration),
            end.validations
                .last()
                .map(|v| format!(", validation 3D IoU {:.4}", v.1))
                .unwrap_or_default(),
            args.out.display()
        );
        Ok(())
    }
}

/// The trained parameters of either trainer.
trait Trained {
    fn trained(&self) -> &TrainedParams;
}

impl Trained for ReconTraining<'_> {
    fn trained(&self) -> &TrainedParams {
        ReconTraining::trained(self)
    }
}

impl Trained for FieldReconTraining<'_> {
    fn trained(&self) -> &TrainedParams {
        FieldReconTraining::trained(self)
    }
}

/// The report of `rows` after iteration `done` of `asked`: `loss.csv`, `loss.png` and
/// `interrupted.txt` ([`write_loss_report`]), and `val.csv`, the validations.
fn write_train_report(
    dir: &Path,
    rows: &[TrainRow],
    vals: &[(u32, f64)],
    (done, asked): (u32, u32),
) -> Result<()> {
    let mut csv = String::from("iteration,val_iou\n");
    for &(it, v) in vals {
        csv.push_str(&format!("{it},{v}\n"));
    }
    AtomicFile::create(&dir.join("val.csv"))?.commit(csv.as_bytes())?;
    let validation = Series {
        name: "1 - val IoU".into(),
        points: vals
            .iter()
            .map(|&(it, v)| (f64::from(it), 1.0 - v))
            .collect(),
        color: [30, 150, 60],
    };
    let plot = LossPlot {
        series: vec![
            curve(rows, "silhouette", "L_sil", [200, 40, 40], 1.0),
            curve(rows, "color", "L_col", [200, 140, 20], 1.0),
            curve(rows, "total", "total", [40, 40, 200], 1.0),
            validation,
        ],
        width: 640,
        height: 400,
        log_y: false,
    };
    write_loss_report(dir, rows, &plot, done, asked)
}
