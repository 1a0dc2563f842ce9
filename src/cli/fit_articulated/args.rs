//! The flags of `softvk fit-articulated`.

use crate::cli::args::{CheckpointArgs, RasterArgs, ViewArgs, non_negative, positive};
use clap::Args;
use std::path::PathBuf;

/// The flags of `softvk fit-articulated`.
#[derive(Args, Clone, Debug)]
pub struct FitArticulatedArgs {
    /// The fitted angles to write (JSON).
    #[arg(long, value_name = "angles.json")]
    pub out: PathBuf,

    /// The target image: a PNG with an alpha channel (as `softvk render` writes).
    #[arg(
        long,
        value_name = "T.png",
        required_unless_present = "target_angles",
        conflicts_with = "target_angles"
    )]
    pub target: Option<PathBuf>,

    /// The target as the figure posed at these joint angles, degrees (one per joint).
    #[arg(long, value_name = "A,B,...", allow_hyphen_values = true, value_parser = angle_list)]
    pub target_angles: Option<AngleList>,

    /// The start, degrees (one per joint) [default: all 0, the rest pose].
    #[arg(long, value_name = "A,B,...", allow_hyphen_values = true, value_parser = angle_list)]
    pub init_angles: Option<AngleList>,

    /// The final render (PNG) [default: <out stem>-render.png beside --out].
    #[arg(long, value_name = "R.png")]
    pub render: Option<PathBuf>,

    /// Target, start and result side by side (PNG) [default: <out stem>-compare.png].
    #[arg(long, value_name = "C.png")]
    pub compare: Option<PathBuf>,

    /// The posed mesh with its colours (OBJ) [default: <out stem>-posed.obj].
    #[arg(long, value_name = "M.obj")]
    pub mesh_out: Option<PathBuf>,

    /// Iterations [default: 240].
    #[arg(long = "iters", value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub iterations: Option<u32>,

    /// Adam learning rate of the angles (radians) [default: 0.05].
    #[arg(long, value_name = "LR", value_parser = positive)]
    pub lr: Option<f64>,

    /// The learning rate decays geometrically to this factor at the last iteration
    /// [default: 0.1].
    #[arg(long, value_name = "F", value_parser = positive)]
    pub lr_final: Option<f64>,

    /// Render every iteration at the sharp --sigma/--gamma (no σ/γ schedule).
    #[arg(long)]
    pub no_schedule: bool,

    /// σ of the schedule's first stage [default: 1e-4 with --target, 1e-2 with
    /// --target-angles].
    #[arg(long, value_name = "S", value_parser = positive, conflicts_with = "no_schedule")]
    pub sigma_start: Option<f64>,

    /// γ of the schedule's first stage [default: as σ's].
    #[arg(long, value_name = "G", value_parser = positive, conflicts_with = "no_schedule")]
    pub gamma_start: Option<f64>,

    /// Standard deviation in pixels of the blur of render and target in the loss's first stage,
    /// falling linearly to none at the last (0: the plain MSE throughout) [default: 2].
    #[arg(long, value_name = "PX", value_parser = non_negative)]
    pub blur: Option<f64>,

    /// Stages of the σ/γ and blur schedules [default: 4].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub stages: Option<u32>,

    /// Tile edge in pixels (a multiple of 8) [default: 8].
    #[arg(long, value_name = "N")]
    pub tile: Option<u32>,

    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub raster: RasterArgs,

    #[command(flatten)]
    pub checkpoints: CheckpointArgs,
}

/// The checkpoint's file in `--checkpoint DIR` / `--resume DIR`.
pub const CHECKPOINT_FILE: &str = "articulated-fit.ckpt";

/// Angles in degrees, one per joint (a type of its own: clap would take a `Vec` for a
/// repeated flag).
#[derive(Clone, Debug, PartialEq)]
pub struct AngleList(pub Vec<f64>);

/// Comma-separated finite numbers.
pub(super) fn angle_list(s: &str) -> std::result::Result<AngleList, String> {
    s.split(',')
        .map(|p| {
            p.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("`{p}` is not a finite number (in `{s}`)"))
        })
        .collect::<std::result::Result<_, _>>()
        .map(AngleList)
}
