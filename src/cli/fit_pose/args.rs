//! The flags of `softvk fit-pose`, and the fit's options they make.

use std::path::PathBuf;

use clap::Args;
use softvk::Result;
use softvk::fit::pose::{PoseFitOptions, Refine, Schedule};
use softvk::raster::gpu::Method;

use crate::cli::args::{CheckpointArgs, RasterArgs, ViewArgs, overlay, positive, triple};

/// The defaults of the pose fit (chosen by `examples/pose_study.rs`; RESULTS.md).
pub(super) fn defaults() -> PoseFitOptions {
    PoseFitOptions::default()
}

/// The flags of `softvk fit-pose`.
#[derive(Args, Clone, Debug)]
pub struct FitPoseArgs {
    /// The mesh (OBJ; its MTL map_Kd texture is sampled with --texture-res).
    #[arg(long, value_name = "M.obj")]
    pub mesh: PathBuf,

    /// Centre the mesh and scale its longest side to [-1, 1], as SoftRas's
    /// `load_obj(normalization=True)` (for meshes as distributed, in their own units).
    #[arg(long)]
    pub normalize: bool,

    /// The target image: a PNG with an alpha channel (as `softvk render` writes).
    #[arg(long, value_name = "T.png")]
    pub target: PathBuf,

    /// The pose to write (JSON).
    #[arg(long, value_name = "pose.json")]
    pub out: PathBuf,

    /// The final render (PNG) [default: <out stem>-render.png beside --out].
    #[arg(long, value_name = "R.png")]
    pub render: Option<PathBuf>,

    /// Heat map of |render − target| (PNG) [default: <out stem>-error.png beside --out].
    #[arg(long, value_name = "E.png")]
    pub error: Option<PathBuf>,

    /// Target, start and result side by side, labelled (PNG) [default: <out stem>-compare.png
    /// beside --out]. The start is rendered at the final σ and γ, as the result is.
    #[arg(long, value_name = "C.png")]
    pub compare: Option<PathBuf>,

    /// Iterations of the σ/γ schedule [default: 80].
    #[arg(long = "iters", value_name = "N")]
    pub iterations: Option<u32>,

    /// After the schedule, at most N more iterations at the sharp σ/γ, ended when the loss has
    /// stopped improving (of several starts, the winner's only); 0: none [default: 220].
    #[arg(long, value_name = "N")]
    pub refine: Option<u32>,

    /// Initial rotation: an axis-angle vector in degrees (direction the axis, length the angle).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = triple)]
    pub init_rotation: Option<[f64; 3]>,

    /// Initial translation.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = triple)]
    pub init_translation: Option<[f64; 3]>,

    /// Render every iteration at the sharp --sigma/--gamma (no blurry-to-sharp schedule).
    #[arg(long)]
    pub no_schedule: bool,

    /// Fit from K starts and keep the one that ends with the lowest loss: the K best of
    /// --candidates rotations spread over all rotations (the first is --init-rotation),
    /// rendered once each and at least 30° apart. Far starts land in wrong basins; one of K
    /// screened starts usually begins in the right one [default: 8; 1 with --checkpoint or
    /// --resume, as a checkpoint holds one fit].
    #[arg(long, value_name = "K", value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub starts: Option<u32>,

    /// Rotations screened for --starts [default: 32 × K; K or fewer: the K spread evenly,
    /// unscreened].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub candidates: Option<u32>,

    /// σ of the schedule's first (blurry) stage [default: 1e-3].
    #[arg(long, value_name = "S", value_parser = positive, conflicts_with = "no_schedule")]
    pub sigma_start: Option<f64>,

    /// γ of the schedule's first stage [default: 1e-3].
    #[arg(long, value_name = "G", value_parser = positive, conflicts_with = "no_schedule")]
    pub gamma_start: Option<f64>,

    /// Stages of the schedule (geometric from the start σ/γ to --sigma/--gamma; the last is
    /// sharp) [default: 4].
    #[arg(long, value_name = "N", conflicts_with = "no_schedule",
          value_parser = clap::value_parser!(u32).range(1..))]
    pub stages: Option<u32>,

    /// Adam learning rate of the rotation (radians) [default: 0.1].
    #[arg(long, value_name = "LR", value_parser = positive)]
    pub lr: Option<f64>,

    /// Adam learning rate of the translation [default: 0.005].
    #[arg(long, value_name = "LR", value_parser = positive)]
    pub lr_translation: Option<f64>,

    /// Both learning rates decay geometrically to this factor at the last iteration
    /// [default: 0.1].
    #[arg(long, value_name = "F", value_parser = positive)]
    pub lr_final: Option<f64>,

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

/// `--starts`' default: enough screened starts that one begins in the right basin from any
/// rotation (RESULTS.md, "Pose estimation").
pub(super) const DEFAULT_STARTS: u32 = 8;

impl FitPoseArgs {
    /// `--starts`, or its default: [`DEFAULT_STARTS`], 1 with checkpoints.
    pub(super) fn starts(&self) -> u32 {
        let checkpoints =
            self.checkpoints.checkpoint.is_some() || self.checkpoints.resume.is_some();
        self.starts
            .unwrap_or(if checkpoints { 1 } else { DEFAULT_STARTS })
    }

    /// The fit's options these flags ask for, for an image of `size`: the library's defaults
    /// ([`defaults`]), each flag given in place of its default.
    pub(super) fn options(&self, size: (u32, u32)) -> Result<PoseFitOptions> {
        let mut o = defaults();
        overlay(&mut o.iterations, self.iterations);
        overlay(&mut o.lr_rotation, self.lr);
        overlay(&mut o.lr_translation, self.lr_translation);
        overlay(&mut o.lr_final, self.lr_final);
        overlay(&mut o.tile, self.tile);
        Method::check_tile(o.tile)?;
        // The schedule's defaults are the schedule's own, not the fit's (which may have none).
        o.schedule = (!self.no_schedule).then(|| {
            let mut s = Schedule::default();
            overlay(&mut s.sigma_start, self.sigma_start);
            overlay(&mut s.gamma_start, self.gamma_start);
            overlay(&mut s.stages, self.stages);
            s
        });
        o.refine = match self.refine {
            Some(0) => None,
            Some(iterations) => Some(Refine {
                iterations,
                ..o.refine.unwrap_or_default()
            }),
            None => o.refine,
        };
        o.settings = self.raster.settings(size)?;
        o.validate()?;
        Ok(o)
    }
}
