//! Single-view reconstruction learned from silhouettes:
//!
//! - `softvk train-recon --dataset DIR --out MODEL [--iters N] [--field]`: trains the network
//!   on the dataset's train split ([`softvk::recon::train`]; with `--field` the conditioned
//!   implicit field of [`softvk::recon::field`]), k iterations per submission, with a
//!   progress bar, a loss log and plot, the validation split's 3D IoU every `--val-every`
//!   iterations, and checkpoints (`--resume` goes on from the last one, bit for bit).
//! - `softvk recon --model MODEL --image IMG --out M.obj`: one image to a mesh (a field's by
//!   marching cubes), and a shaded turntable GIF of it beside the input.
//!
//! `softvk eval-recon` scores the models ([`super::eval_recon`]).

use std::path::{Path, PathBuf};

use clap::Args;
use softvk::camera::Camera;
use softvk::field::MlpLayout;
use softvk::fit::AdamOptions;
use softvk::fit::checkpoint::FitKind;
use softvk::fit::driver::{Fitter, to_next_log};
use softvk::fit::report::{self, GifWriter, Series};
use softvk::fit::session::{CheckpointPlan, Progress, Resume, Session, Trainee};
use softvk::gpu::{Context, ContextOptions};
use softvk::io::write_obj_colored;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::probe::ProbeSettings;
use softvk::raster::gpu::{Method, Renderer};
use softvk::recon::dataset::{self, Dataset, Split};
use softvk::recon::field::{
    self, FieldNet, FieldReconTrainer, FieldReconTraining, FieldTrainOptions,
};
use softvk::recon::model::ReconModel;
use softvk::recon::reconstruct::{
    AnyReconstructor, spread_views, upscale, validation_iou, view_settings,
};
use softvk::recon::session::{self, TrainRow};
use softvk::recon::train::{
    LrStep, NetShape, Recipe, ReconTrainer, ReconTraining, TrainImages, TrainOptions, TrainedParams,
};
use softvk::{Error, Result};

use super::args::{non_negative, positive};
use super::interrupt;
use super::output::AtomicFile;
use super::session::Watch;

/// `--channels`: three comma-separated positive widths.
fn channels(s: &str) -> std::result::Result<[u32; 3], String> {
    let v: Vec<u32> = s
        .split(',')
        .map(|p| p.trim().parse::<u32>().map_err(|e| format!("`{p}`: {e}")))
        .collect::<std::result::Result<_, _>>()?;
    match v[..] {
        [a, b, c] if a > 0 && b > 0 && c > 0 => Ok([a, b, c]),
        _ => Err(format!(
            "expected three positive widths like 16,32,64, got `{s}`"
        )),
    }
}

/// The flags of `softvk train-recon`.
#[derive(Args, Clone, Debug)]
pub struct TrainReconArgs {
    /// Dataset folder in the NMR layout (`<class>_<split>_images.npz`, `..._voxels.npz`), as
    /// `softvk dataset` writes it.
    #[arg(long, value_name = "DIR")]
    pub dataset: PathBuf,

    /// The trained model (.npz). Beside it, `<MODEL stem>-train/`: the checkpoint, loss.csv,
    /// loss.png and val.csv.
    #[arg(long, value_name = "MODEL")]
    pub out: PathBuf,

    /// Training iterations.
    #[arg(long, value_name = "N", default_value_t = 2000, value_parser = clap::value_parser!(u32).range(1..))]
    pub iters: u32,

    /// Instead of `--iters`: train until the network has seen N input images, rounded up to
    /// whole iterations (a mesh iteration sees the batch's objects from one view or, in
    /// SoftRas's recipe, two; a field iteration one view of each object), so that models
    /// trained by different recipes can be given the same budget.
    #[arg(long, value_name = "N", conflicts_with = "iters", value_parser = clap::value_parser!(u64).range(1..))]
    pub images: Option<u64>,

    /// Objects per batch, two views each [default: 64 (SoftRas's), 16 with --field].
    #[arg(long, value_name = "B", value_parser = clap::value_parser!(u32).range(1..))]
    pub batch: Option<u32>,

    /// How the mesh decoder's batches are seen and scored: `softras` (SoftRas's: both views
    /// of an object are inputs, each prediction rendered from both, the mean of the four IoU
    /// losses, `dist_eps` 1e-10, σ stepped with the learning rate) or `one-view` (view a is the
    /// input, rendered from both views, the sum of the two IoU losses).
    #[arg(long, value_enum, default_value_t = RecipeArg::Softras)]
    pub recipe: RecipeArg,

    /// Adam's learning rate [default: 1e-4 (SoftRas's), 1e-3 with --field].
    #[arg(long, value_parser = positive)]
    pub lr: Option<f64>,

    /// From this iteration on, train at `--lr-decay` × `--lr` (SoftRas's `step` schedule:
    /// × 0.3 from 150 000). A resumed run may add or move the step if the iterations already
    /// run are not affected.
    #[arg(long, value_name = "IT", value_parser = clap::value_parser!(u32).range(1..))]
    pub lr_step: Option<u32>,

    /// The learning rate's factor from `--lr-step` on.
    #[arg(long, value_name = "F", default_value_t = 0.3, value_parser = non_negative)]
    pub lr_decay: f64,

    /// Seeds the parameters and the batches.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,

    /// The encoder's convolution widths.
    #[arg(long, default_value = "16,32,64", value_parser = channels)]
    pub channels: [u32; 3],

    /// The latent code's width.
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(1..))]
    pub latent: u32,

    /// The decoder's hidden width.
    #[arg(long, default_value_t = 512, value_parser = clap::value_parser!(u32).range(1..))]
    pub hidden: u32,

    /// The renderer's σ (SoftRas: 1e-4).
    #[arg(long, default_value_t = 1e-4, value_parser = positive)]
    pub sigma: f64,

    /// λ of the colour loss (the rendered RGBA against the views'); 0 trains silhouettes only
    /// (cheaper: the copies render as silhouettes) and leaves the colour generator untrained.
    #[arg(long, default_value_t = 1.0, value_parser = non_negative)]
    pub color: f64,

    /// Iterations per GPU submission (the losses are read once per submission).
    #[arg(long, value_name = "K", default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..))]
    pub log_every: u32,

    /// Iterations between validations (3D IoU on the val split) and checkpoints (both
    /// rounded to a submission's end).
    #[arg(long, value_name = "N", default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..))]
    pub val_every: u32,

    /// Validation inputs per val object (views spread evenly over the 24).
    #[arg(long, value_name = "V", default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..))]
    pub val_views: u32,

    /// Go on from the checkpoint in `<MODEL stem>-train/` (same dataset and options).
    #[arg(long)]
    pub resume: bool,

    /// Train a conditioned implicit field instead of the mesh decoder: the encoder predicts
    /// each hidden layer's bias of a shared occupancy MLP, trained by sphere probing against
    /// every view's silhouette. `--sigma` and `--color` do not apply.
    #[arg(long)]
    pub field: bool,

    /// With --field: the MLP's hidden layers.
    #[arg(long, value_name = "L", default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=32))]
    pub field_layers: u32,

    /// With --field: the MLP's width.
    #[arg(long, value_name = "W", default_value_t = 32, value_parser = clap::value_parser!(u32).range(1..=256))]
    pub field_width: u32,

    /// With --field: the MLP's positional-encoding frequencies.
    #[arg(long, value_name = "F", default_value_t = 3, value_parser = clap::value_parser!(u32).range(0..=16))]
    pub field_freqs: u32,

    /// With --field: probing rays per view (all 24 views) per object and iteration.
    #[arg(long, value_name = "N", default_value_t = 64, value_parser = clap::value_parser!(u32).range(1..))]
    pub rays: u32,

    /// With --field: anchors per object and iteration.
    #[arg(long, value_name = "N", default_value_t = 2048, value_parser = clap::value_parser!(u32).range(1..))]
    pub anchors: u32,

    /// With --field: the anchors' radius τ, in half-edges of the field's cube.
    #[arg(long, default_value_t = 0.045, value_parser = positive)]
    pub tau: f64,
}

/// The flags of `softvk recon`.
#[derive(Args, Clone, Debug)]
pub struct ReconArgs {
    /// A model written by `softvk train-recon`.
    #[arg(long, value_name = "MODEL")]
    pub model: PathBuf,

    /// The input: an RGBA PNG of the model's image size (64×64), the object on a transparent
    /// background as in the dataset.
    #[arg(long, value_name = "IMG")]
    pub image: PathBuf,

    /// The reconstructed mesh (OBJ). Beside it, `<stem>-turntable.gif`.
    #[arg(long, value_name = "M.obj")]
    pub out: PathBuf,
}

/// `--recipe` of `softvk train-recon`: [`Recipe`]'s two.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecipeArg {
    /// SoftRas's: both views encoded, four renders per object, the mean of the IoU losses.
    Softras,
    /// View a encoded, two renders per object, the sum of the IoU losses.
    OneView,
}

impl From<RecipeArg> for Recipe {
    fn from(r: RecipeArg) -> Self {
        match r {
            RecipeArg::Softras => Recipe::SoftRas,
            RecipeArg::OneView => Recipe::OneView,
        }
    }
}

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
    let net = NetShape {
        image: dataset::IMAGE_SIZE as u32,
        channels: args.channels,
        latent: args.latent,
        hidden: args.hidden,
    };
    let lr_step = args.lr_step.map(|at| LrStep {
        at,
        factor: args.lr_decay,
    });
    let mesh_opts = TrainOptions {
        net,
        recipe: args.recipe.into(),
        batch: args.batch.unwrap_or(TrainOptions::default().batch),
        adam: AdamOptions {
            lr: args.lr.unwrap_or(1e-4),
            ..AdamOptions::default()
        },
        lr_step,
        sigma: args.sigma,
        color: args.color as f32,
        seed: args.seed,
        ..TrainOptions::default()
    };
    let field_opts = FieldTrainOptions {
        net: FieldNet {
            net,
            mlp: MlpLayout {
                hidden_layers: args.field_layers,
                width: args.field_width,
                frequencies: args.field_freqs,
            },
        },
        batch: args.batch.unwrap_or(FieldTrainOptions::default().batch),
        adam: AdamOptions {
            lr: args.lr.unwrap_or(1e-3),
            ..AdamOptions::default()
        },
        lr_step,
        probe: ProbeSettings {
            rays_per_view: args.rays,
            anchors: args.anchors,
            tau: args.tau * field::field_cube().half,
            ..field::default_probe()
        },
        seed: args.seed,
    };
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
                write_train_report(&dir, p.log, p.validations)?;
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

fn write_train_report(dir: &Path, rows: &[TrainRow], vals: &[(u32, f64)]) -> Result<()> {
    let log: Vec<[f64; 6]> = rows
        .iter()
        .map(|r| {
            let it = f64::from(r.iteration);
            [it, r.silhouette, r.color, r.laplacian, r.flatten, r.total]
        })
        .collect();
    let vals: Vec<[f64; 2]> = vals.iter().map(|&(it, v)| [f64::from(it), v]).collect();
    let mut csv = String::from("iteration,silhouette,color,laplacian,flatten,total\n");
    for r in &log {
        csv.push_str(&format!(
            "{},{},{},{},{},{}\n",
            r[0], r[1], r[2], r[3], r[4], r[5]
        ));
    }
    AtomicFile::create(&dir.join("loss.csv"))?.commit(csv.as_bytes())?;
    let mut csv = String::from("iteration,val_iou\n");
    for r in &vals {
        csv.push_str(&format!("{},{}\n", r[0], r[1]));
    }
    AtomicFile::create(&dir.join("val.csv"))?.commit(csv.as_bytes())?;
    let series = [
        Series {
            name: "L_sil".into(),
            points: log.iter().map(|r| (r[0], r[1])).collect(),
            color: [200, 40, 40],
        },
        Series {
            name: "L_col".into(),
            points: log.iter().map(|r| (r[0], r[2])).collect(),
            color: [200, 140, 20],
        },
        Series {
            name: "total".into(),
            points: log.iter().map(|r| (r[0], r[5])).collect(),
            color: [40, 40, 200],
        },
        Series {
            name: "1 - val IoU".into(),
            points: vals.iter().map(|r| (r[0], 1.0 - r[1])).collect(),
            color: [30, 150, 60],
        },
    ];
    report::write_png(
        &dir.join("loss.png"),
        &report::loss_plot(&series, 640, 400, false),
    )
}

/// An RGBA PNG as the network's input bytes (planes R, G, B, A).
fn read_input(path: &Path, size: u32) -> Result<Vec<u8>> {
    let img = image::open(path)
        .map_err(|e| Error::Input(format!("{}: {e}", path.display())))?
        .to_rgba8();
    if img.width() != size || img.height() != size {
        return Err(Error::Input(format!(
            "{}: {}×{} pixels; the model takes {size}×{size}",
            path.display(),
            img.width(),
            img.height()
        )));
    }
    let px = (size * size) as usize;
    let mut planes = vec![0u8; 4 * px];
    for (i, p) in img.pixels().enumerate() {
        for c in 0..4 {
            planes[c * px + i] = p[c];
        }
    }
    Ok(planes)
}

/// `softvk recon`.
pub fn recon(args: &ReconArgs) -> Result<()> {
    let model = ReconModel::load(&args.model)?;
    let input = read_input(&args.image, model.net.image)?;
    let ctx = Context::new(&ContextOptions::from_env())?;
    let recon = AnyReconstructor::new(&ctx, &model, 1)?;
    let mesh = recon.mesh(&ctx, &input)?.ok_or_else(|| {
        Error::Input(format!(
            "{}: the field is empty for this image (no φ = 0.5 surface)",
            args.image.display()
        ))
    })?;
    let stem = args
        .out
        .file_stem()
        .map_or_else(|| "recon".into(), |s| s.to_string_lossy().into_owned());
    let gif = args.out.with_file_name(format!("{stem}-turntable.gif"));
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .map_err(|e| Error::Input(format!("cannot create {}: {e}", parent.display())))?;
    }
    write_turntable(&ctx, &gif, &mesh, &input, model.net.image)?;
    write_obj_colored(
        &args.out,
        &mesh.positions,
        mesh.vertex_colors.as_deref(),
        &mesh.faces,
    )?;
    println!("wrote {} and {}", args.out.display(), gif.display());
    Ok(())
}

/// The reconstruction shaded, turning (24 frames at the dataset's elevation and distance),
/// beside the input.
fn write_turntable(ctx: &Context, path: &Path, mesh: &Mesh, input: &[u8], size: u32) -> Result<()> {
    const SIZE: u32 = 128;
    let settings = view_settings(SIZE);
    let cams: Vec<Camera> = (0..dataset::VIEWS).map(dataset::view_camera).collect();
    let frames = Renderer::new(ctx)?.render_views(
        ctx,
        mesh,
        &cams,
        &Lighting::default(),
        &settings,
        Method::default(),
    )?;
    let big = upscale(input, size, SIZE);
    let n = (SIZE * SIZE) as usize;
    let frame = |v: usize| {
        report::side_by_side(
            &[
                ("input", &big[..]),
                ("reconstruction", &frames.images[v * n..(v + 1) * n]),
            ],
            SIZE,
            SIZE,
        )
    };
    let first = frame(0);
    let mut gif = GifWriter::create(path, first.width(), first.height(), 120)?;
    gif.push(&first)?;
    for v in 1..dataset::VIEWS {
        gif.push(&frame(v))?;
    }
    gif.finish()
}
