//! The flags of `softvk train-recon`, and the training options they make.

use std::path::PathBuf;

use clap::Args;
use softvk::field::MlpLayout;
use softvk::probe::ProbeSettings;
use softvk::recon::dataset::{self};
use softvk::recon::field::{self, FieldNet, FieldTrainOptions};
use softvk::recon::train::{LrStep, NetShape, Recipe, TrainOptions};

use crate::cli::args::{CheckpointArgs, non_negative, overlay, positive};

/// `--channels`: three comma-separated positive widths.
pub(super) fn channels(s: &str) -> std::result::Result<[u32; 3], String> {
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

    /// `--checkpoint DIR` [default: `<MODEL stem>-train/`, every `--val-every`], and
    /// `--resume DIR` (the same dataset and options).
    #[command(flatten)]
    pub checkpoints: CheckpointArgs,

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

impl TrainReconArgs {
    /// The encoder's shape.
    pub(super) fn net(&self) -> NetShape {
        NetShape {
            image: dataset::IMAGE_SIZE as u32,
            channels: self.channels,
            latent: self.latent,
            hidden: self.hidden,
        }
    }

    fn lr_step(&self) -> Option<LrStep> {
        self.lr_step.map(|at| LrStep {
            at,
            factor: self.lr_decay,
        })
    }

    /// The mesh network's training options: SoftRas's ([`TrainOptions::default`]), each flag
    /// given in place of its default.
    pub(super) fn mesh_options(&self) -> TrainOptions {
        let mut o = TrainOptions {
            net: self.net(),
            recipe: self.recipe.into(),
            lr_step: self.lr_step(),
            sigma: self.sigma,
            color: self.color as f32,
            seed: self.seed,
            ..TrainOptions::default()
        };
        overlay(&mut o.batch, self.batch);
        overlay(&mut o.adam.lr, self.lr);
        o
    }

    /// The conditioned field's training options: [`FieldTrainOptions::default`]'s, each flag
    /// given in place of its default.
    pub(super) fn field_options(&self) -> FieldTrainOptions {
        let mut o = FieldTrainOptions {
            net: FieldNet {
                net: self.net(),
                mlp: MlpLayout {
                    hidden_layers: self.field_layers,
                    width: self.field_width,
                    frequencies: self.field_freqs,
                },
            },
            lr_step: self.lr_step(),
            probe: ProbeSettings {
                rays_per_view: self.rays,
                anchors: self.anchors,
                tau: self.tau * field::field_cube().half,
                ..field::default_probe()
            },
            seed: self.seed,
            ..FieldTrainOptions::default()
        };
        overlay(&mut o.batch, self.batch);
        overlay(&mut o.adam.lr, self.lr);
        o
    }
}
