//! `softvk train-recon --dataset DIR --out MODEL [--iters N] [--field]`: trains the network on
//! the dataset's train split ([`softvk::recon::train`]; with `--field` the conditioned implicit
//! field of [`softvk::recon::field`]) in a fit session ([`softvk::fit::session`]), k
//! iterations per submission, with a progress bar, a loss log and plot, the validation split's
//! 3D IoU every `--val-every` iterations, and checkpoints (`--resume` goes on from the last
//! one, bit for bit).

use std::path::{Path, PathBuf};

use softvk::fit::checkpoint::FitKind;
use softvk::fit::driver::{Fitter, to_next_log};
use softvk::fit::report::Series;
use softvk::fit::session::{CheckpointPlan, Progress, Resume, Session, Trainee};
use softvk::gpu::{Context, ContextOptions};
use softvk::recon::dataset::{Dataset, Split};
use softvk::recon::field::{FieldReconTrainer, FieldReconTraining};
use softvk::recon::model::ReconModel;
use softvk::recon::reconstruct::{spread_views, validation_iou};
use softvk::recon::session::{self, TrainRow};
use softvk::recon::train::{ReconTrainer, ReconTraining, TrainImages, TrainedParams};
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
    let ckpt_path = dir.join(CHECKPOINT_FILE);
    let fingerprint = session::fingerprint(&net, field_layout);
    let resume = if args.resume {
        let kind = if args.field {
            FitKind::ReconField
        } else {
            FitKind::ReconMesh
        };
        let r = Resume::read(&ckpt_path, kind, fingerprint)?;
        session::check_resume(&ckpt_path, &r, &net, field_layout, &settings)?;
        Some(r)
    } else {
        None
    };
    let ctx = Context::new(&ContextOptions::from_env())?;
    let images = TrainImages::from_dataset(data);
    let run = TrainingRun {
        args,
        ctx: &ctx,
        val,
        dir,
        ckpt_path,
        fingerprint,
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
        let trainer = FieldReconTrainer::new(&ctx, &images, &field_opts, None)?;
        run.go(trainer, resume)
    } else {
        run.go(ReconTrainer::new(&ctx, &images, &mesh_opts, None)?, resume)
    }
}

/// The checkpoint's file in the report folder.
const CHECKPOINT_FILE: &str = "checkpoint.ckpt";

/// A training run's inputs beside its trainer.
struct TrainingRun<'a, M> {
    args: &'a TrainReconArgs,
    ctx: &'a Context,
    val: Option<Dataset>,
    dir: PathBuf,
    ckpt_path: PathBuf,
    fingerprint: u64,
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
    fn go<'c, T>(self, mut trainer: Fitter<'c, T>, resume: Option<Resume<TrainRow>>) -> Result<()>
    where
        T: Trainee<Row = TrainRow> + Trained,
    {
        let Self {
            args,
            ctx,
            val,
            dir,
            ckpt_path,
            fingerprint,
            model_of,
            iterations,
            per_iteration,
        } = self;
        let start = resume.as_ref().map_or(0, |r| r.iteration);
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
        let mut session = Session::new()
            .resume(resume)
            .checkpoint(Some(CheckpointPlan {
                path: ckpt_path.clone(),
                fingerprint,
                every: args.val_every,
            }))
            .hooks(hooks);
        if let Some(val) = &val {
            session = session.validate(args.val_every, |p: &Progress<'_, '_, T>| {
                validation_iou(ctx, &model_now(p)?, val, &val_views)
            });
        }
        // Submissions of `--log-every` iterations, ending at each validation.
        let end = session.run(&mut trainer, (iterations, 1), |_, it| {
            Ok((it + args.log_every - 1).min(to_next_log(it, args.val_every)))
        })?;
        watch.finish();
        let done = end.last;
        if done < iterations {
            eprintln!(
                "softvk: stopped after iteration {done} of {}; `--resume` goes on from {}",
                iterations,
                ckpt_path.display()
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
