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
use indicatif::{ProgressBar, ProgressStyle};
use softvk::camera::Camera;
use softvk::field::MlpLayout;
use softvk::fit::AdamOptions;
use softvk::fit::driver::{Fit, Fitter};
use softvk::fit::report::{self, GifWriter, Series};
use softvk::gpu::{Context, ContextOptions};
use softvk::io::write_obj_colored;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::probe::ProbeSettings;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::{ColorMode, RasterSettings};
use softvk::recon::dataset::{self, ClassData, Dataset, Split};
use softvk::recon::eval;
use softvk::recon::field::{
    self, FieldNet, FieldReconTrainer, FieldReconTraining, FieldReconstructor, FieldTrainOptions,
};
use softvk::recon::model::{ReconModel, Reconstruction, Reconstructor, SETTINGS, TrainState};
use softvk::recon::train::{
    self, LrStep, NetShape, Recipe, ReconTrainer, ReconTraining, TrainImages, TrainOptions,
    TrainedParams,
};
use softvk::{Error, Result};

use super::args::{non_negative, positive};
use super::interrupt;
use super::output::AtomicFile;

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

/// `n` views spread evenly over the 24.
pub(super) fn spread_views(n: u32) -> Vec<usize> {
    let n = n.min(dataset::VIEWS as u32) as usize;
    (0..n).map(|i| i * dataset::VIEWS / n).collect()
}

/// The train split as the trainer takes it (each class's images freed once copied: the
/// default data are 1.2 GB).
fn train_images(data: Dataset) -> TrainImages {
    let mut images = Vec::with_capacity(data.classes.iter().map(|c| c.images.len()).sum());
    let mut classes = Vec::new();
    let mut start = 0u32;
    for c in data.classes {
        images.extend_from_slice(&c.images);
        let end = start + c.count as u32;
        classes.push((c.class_id, start..end));
        start = end;
    }
    TrainImages {
        images,
        classes,
        size: dataset::IMAGE_SIZE as u32,
    }
}

fn report_dir(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}-train"))
}

/// A trained model of either kind, ready to reconstruct.
pub(super) enum AnyReconstructor {
    /// The mesh decoder's.
    Mesh(Box<Reconstructor>),
    /// A conditioned field's.
    Field(Box<FieldReconstructor>),
}

impl AnyReconstructor {
    /// `model`'s reconstructor, for batches of up to `capacity` images.
    pub(super) fn new(ctx: &Context, model: &ReconModel, capacity: u32) -> Result<Self> {
        Ok(match model.field {
            Some(_) => Self::Field(Box::new(FieldReconstructor::new(ctx, model, capacity)?)),
            None => Self::Mesh(Box::new(Reconstructor::new(ctx, model, capacity)?)),
        })
    }

    /// The 3D IoU of the reconstruction from each `(object, view)` input of `class`.
    pub(super) fn ious(
        &self,
        ctx: &Context,
        class: &ClassData,
        inputs: &[(usize, usize)],
        voxelizer: eval::Voxelizer,
    ) -> Result<Vec<f64>> {
        match self {
            Self::Mesh(r) => {
                Ok(eval::reconstruction_ious(ctx, r, class, inputs, &[voxelizer])?.remove(0))
            }
            Self::Field(r) => eval::field_reconstruction_ious(ctx, r, class, inputs),
        }
    }

    /// The mesh of one image (`4 × H × W` bytes): the deformed template with its colours, or
    /// the field's marching-cubes mesh in grey (`None` when φ never crosses 0.5).
    pub(super) fn mesh(&self, ctx: &Context, image: &[u8]) -> Result<Option<Mesh>> {
        match self {
            Self::Mesh(r) => Ok(Some(colored_mesh(r.reconstruct(ctx, image)?.remove(0)))),
            Self::Field(r) => {
                let iso = r.isosurface(ctx, image, FIELD_MESH_RES)?;
                if iso.is_empty() {
                    return Ok(None);
                }
                let mut mesh = iso.to_mesh()?;
                mesh.vertex_colors = Some(vec![[0.7; 3]; mesh.positions.len()]);
                Ok(Some(mesh))
            }
        }
    }

    /// The IoU columns of this model over `inputs` of `class` (`[column][input]`): a mesh
    /// model's once per voxelizer of `mesh_voxelizers`, a field's once.
    pub(super) fn columns(
        &self,
        ctx: &Context,
        class: &ClassData,
        inputs: &[(usize, usize)],
        mesh_voxelizers: &[eval::Voxelizer],
    ) -> Result<Vec<Vec<f64>>> {
        match self {
            Self::Mesh(r) => eval::reconstruction_ious(ctx, r, class, inputs, mesh_voxelizers),
            Self::Field(r) => Ok(vec![eval::field_reconstruction_ious(
                ctx, r, class, inputs,
            )?]),
        }
    }

    /// `mesh` or `field`.
    pub(super) fn kind(&self) -> &'static str {
        match self {
            Self::Mesh(_) => "mesh",
            Self::Field(_) => "field",
        }
    }
}

/// Lattice of the marching cubes that mesh a conditioned field.
const FIELD_MESH_RES: u32 = 64;

/// The mean validation IoU of `model` over `views` of every val object.
fn validate(ctx: &Context, model: &ReconModel, val: &Dataset, views: &[usize]) -> Result<f64> {
    let recon = AnyReconstructor::new(ctx, model, 32)?;
    let mut all = Vec::new();
    for c in &val.classes {
        let inputs: Vec<(usize, usize)> = (0..c.count)
            .flat_map(|n| views.iter().map(move |&v| (n, v)))
            .collect();
        all.extend(recon.ious(ctx, c, &inputs, eval::Voxelizer::default())?);
    }
    Ok(all.iter().sum::<f64>() / all.len().max(1) as f64)
}

/// What the training loop needs of either trainer beside its iterations.
trait Training: Fit {
    /// The log row of the last iteration: iteration, L_sil, L_col, L_lap, L_flat, total.
    fn log(&self, iteration: u32) -> Result<[f64; 6]>;
    /// The parameters, their gradient and Adam's moments.
    fn trained(&self) -> &TrainedParams;
}

impl Training for ReconTraining<'_> {
    fn log(&self, iteration: u32) -> Result<[f64; 6]> {
        let l = self.read_log(iteration)?;
        Ok([
            f64::from(iteration),
            f64::from(l.silhouette),
            f64::from(l.color),
            f64::from(l.laplacian),
            f64::from(l.flatten),
            f64::from(l.total),
        ])
    }
    fn trained(&self) -> &TrainedParams {
        ReconTraining::trained(self)
    }
}

impl Training for FieldReconTraining<'_> {
    fn log(&self, iteration: u32) -> Result<[f64; 6]> {
        let l = f64::from(self.read_log(iteration)?.silhouette);
        Ok([f64::from(iteration), l, 0.0, 0.0, 0.0, l])
    }
    fn trained(&self) -> &TrainedParams {
        FieldReconTraining::trained(self)
    }
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
    let step = [
        lr_step.map_or(0.0, |s| f64::from(s.at)),
        lr_step.map_or(1.0, |s| s.factor),
    ];
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
    let (adam, seed, batch) = if args.field {
        (field_opts.adam, field_opts.seed, field_opts.batch)
    } else {
        (mesh_opts.adam, mesh_opts.seed, mesh_opts.batch)
    };
    let specific = if args.field {
        let p = &field_opts.probe;
        [
            f64::from(p.rays_per_view),
            f64::from(p.anchors),
            p.tau,
            f64::from(p.tile_size),
        ]
    } else {
        [
            f64::from(mesh_opts.laplacian),
            f64::from(mesh_opts.flatten),
            f64::from(mesh_opts.color),
            mesh_opts.sigma,
        ]
    };
    let settings = [
        seed as f64,
        f64::from(batch),
        adam.lr,
        adam.betas.0,
        adam.betas.1,
        specific[0],
        specific[1],
        specific[2],
        specific[3],
        step[0],
        step[1],
        if args.field {
            0.0
        } else {
            mesh_opts.recipe.code()
        },
    ];
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
    let ckpt_path = dir.join("checkpoint.npz");
    let resumed = if args.resume {
        let m = ReconModel::load(&ckpt_path)?;
        let Some(t) = &m.train else {
            return Err(Error::Input(format!(
                "{}: a final model, not a checkpoint",
                ckpt_path.display()
            )));
        };
        if m.net != net
            || m.field != field_layout
            || !same_past(&t.settings, &settings, m.iteration)
        {
            return Err(Error::Input(format!(
                "{}: written by a run with other options (network {:?}, field {:?}, settings \
                 {:?})",
                ckpt_path.display(),
                m.net,
                m.field,
                t.settings
            )));
        }
        Some(m)
    } else {
        None
    };
    let ctx = Context::new(&ContextOptions::from_env())?;
    let images = train_images(data);
    let resume_params = resumed.as_ref().map(|m| m.params.clone());
    let resume_params = resume_params.as_deref();
    let run = TrainingRun {
        args,
        ctx: &ctx,
        val,
        dir,
        ckpt_path,
        resumed,
        model_of: |params: Vec<f32>, iteration: u32, train: Option<TrainState>| ReconModel {
            net,
            field: field_layout,
            params,
            iteration,
            train,
        },
        settings,
        iterations,
        per_iteration,
    };
    if args.field {
        let trainer = FieldReconTrainer::new(&ctx, &images, &field_opts, resume_params)?;
        run.go(trainer)
    } else {
        run.go(ReconTrainer::new(&ctx, &images, &mesh_opts, resume_params)?)
    }
}

/// A training run's inputs beside its trainer.
struct TrainingRun<'a, M> {
    args: &'a TrainReconArgs,
    ctx: &'a Context,
    val: Option<Dataset>,
    dir: PathBuf,
    ckpt_path: PathBuf,
    resumed: Option<ReconModel>,
    /// The model of parameters after an iteration, with the training state of a checkpoint.
    model_of: M,
    settings: [f64; SETTINGS],
    /// The last iteration (`--iters`, or `--images` over `per_iteration`).
    iterations: u32,
    /// Input images per iteration.
    per_iteration: u32,
}

impl<M: Fn(Vec<f32>, u32, Option<TrainState>) -> ReconModel> TrainingRun<'_, M> {
    /// Trains to the last iteration (validating and checkpointing every `--val-every`, stopping at an
    /// interrupt with a checkpoint) and writes the model.
    fn go<T: Training>(self, mut trainer: Fitter<'_, T>) -> Result<()> {
        let Self {
            args,
            ctx,
            val,
            dir,
            ckpt_path,
            resumed,
            model_of,
            settings,
            iterations,
            per_iteration,
        } = self;
        let (mut log, mut vals, start) = match &resumed {
            Some(m) => {
                let t = m.train.as_ref().expect("checked above");
                trainer.trained().write_moments(ctx, &t.adam_m, &t.adam_v)?;
                (t.log.clone(), t.val.clone(), m.iteration)
            }
            None => (Vec::new(), Vec::new(), 0),
        };
        std::fs::create_dir_all(&dir)
            .map_err(|e| Error::Input(format!("cannot create {}: {e}", dir.display())))?;
        let val_views = spread_views(args.val_views);
        let bar = ProgressBar::new(u64::from(iterations));
        bar.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} it {elapsed} eta {eta} {msg}")
                .expect("a valid template"),
        );
        bar.set_position(u64::from(start));
        let save = |trainer: &T, it: u32, log: &[[f64; 6]], vals: &[[f64; 2]]| {
            let (adam_m, adam_v) = trainer.trained().read_moments(ctx)?;
            model_of(
                trainer.trained().read_params(ctx)?,
                it,
                Some(TrainState {
                    adam_m,
                    adam_v,
                    settings,
                    log: log.to_vec(),
                    val: vals.to_vec(),
                }),
            )
            .save(&ckpt_path)
        };
        // Submissions of `--log-every` iterations, ending at each validation.
        let boundary = |it: u32| (it - 1) / args.val_every * args.val_every + args.val_every;
        let done = trainer.drive(
            start + 1,
            iterations,
            |_, it| Ok((it + args.log_every - 1).min(boundary(it))),
            |trainer, first, last| {
                let row = trainer.log(last)?;
                if !row[5].is_finite() {
                    return Err(Error::Input(format!(
                        "training diverged at iteration {last} (loss {}); try a smaller --lr",
                        row[5]
                    )));
                }
                log.push(row);
                bar.set_position(u64::from(last));
                bar.set_message(format!("L_sil {:.4}", row[1]));
                let interrupted = interrupt::requested().is_some();
                let at_boundary = last == boundary(first) || last == iterations;
                if at_boundary && let Some(val) = &val {
                    let model = model_of(trainer.trained().read_params(ctx)?, last, None);
                    let iou = validate(ctx, &model, val, &val_views)?;
                    vals.push([f64::from(last), iou]);
                    let line = format!(
                        "iteration {last}: L_sil {:.4}, validation 3D IoU {iou:.4}",
                        row[1]
                    );
                    if bar.is_hidden() {
                        eprintln!("{line}");
                    } else {
                        bar.println(line);
                    }
                }
                if at_boundary || interrupted {
                    save(trainer, last, &log, &vals)?;
                    write_train_report(&dir, &log, &vals)?;
                }
                Ok(!interrupted)
            },
        )?;
        bar.finish_and_clear();
        if done < iterations {
            eprintln!(
                "softvk: stopped after iteration {done} of {}; `--resume` goes on from {}",
                iterations,
                ckpt_path.display()
            );
            return Ok(());
        }
        model_of(trainer.trained().read_params(ctx)?, done, None).save(&args.out)?;
        let last = log.last().copied().unwrap_or([0.0; 6]);
        println!(
            "{}trained {done} iterations ({} input images): L_sil {:.4}{}; model {}",
            interrupt::resumed_note(start + 1, done),
            u64::from(done) * u64::from(per_iteration),
            last[1],
            vals.last()
                .map(|v| format!(", validation 3D IoU {:.4}", v[1]))
                .unwrap_or_default(),
            args.out.display()
        );
        Ok(())
    }
}

/// Whether a run with `now`'s settings would have run a checkpoint's first `done` iterations
/// as `then`'s did: the same settings, except that the learning rate's step may differ where it
/// has not acted yet (both steps later than `done`, or none).
fn same_past(then: &[f64; SETTINGS], now: &[f64; SETTINGS], done: u32) -> bool {
    let unacted = |s: &[f64; SETTINGS]| s[9] == 0.0 || s[9] > f64::from(done);
    then[..9] == now[..9]
        && then[11] == now[11]
        && (then[9..11] == now[9..11] || (unacted(then) && unacted(now)))
}

fn write_train_report(dir: &Path, log: &[[f64; 6]], vals: &[[f64; 2]]) -> Result<()> {
    let mut csv = String::from("iteration,silhouette,color,laplacian,flatten,total\n");
    for r in log {
        csv.push_str(&format!(
            "{},{},{},{},{},{}\n",
            r[0], r[1], r[2], r[3], r[4], r[5]
        ));
    }
    AtomicFile::create(&dir.join("loss.csv"))?.commit(csv.as_bytes())?;
    let mut csv = String::from("iteration,val_iou\n");
    for r in vals {
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

/// The template with a reconstruction's positions and vertex colours.
fn colored_mesh(r: Reconstruction) -> Mesh {
    let mut mesh = train::template();
    mesh.positions = r.positions;
    mesh.vertex_colors = Some(r.colors);
    mesh
}

/// Renders of reconstructions: their vertex colours under the default light (the colour
/// generator samples the input's shaded colours; the light shows the shape even where it did
/// not), crisp.
pub(super) fn view_settings(size: u32) -> RasterSettings {
    RasterSettings {
        width: size,
        height: size,
        sigma: 1e-5,
        gamma: 1e-4,
        color_mode: ColorMode::Vertex,
        ..RasterSettings::default()
    }
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

/// NMR-layout RGBA planes (`size²` each) as `big × big` pixels (nearest), values in [0, 1].
pub(super) fn upscale(planes: &[u8], size: u32, big: u32) -> Vec<[f32; 4]> {
    let px = (size * size) as usize;
    (0..big * big)
        .map(|i| {
            let (x, y) = ((i % big) * size / big, (i / big) * size / big);
            let j = (y * size + x) as usize;
            [0, 1, 2, 3].map(|c| f32::from(planes[c * px + j]) / 255.0)
        })
        .collect()
}
