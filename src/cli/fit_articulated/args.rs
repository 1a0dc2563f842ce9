//! The flags of `softvk fit-articulated`.

use std::path::PathBuf;

use clap::Args;
use softvk::fit::articulated::ArticulatedFitOptions;
use softvk::fit::rig::Rig;
use softvk::raster::gpu::Method;
use softvk::{Error, Result};

use crate::cli::args::{CheckpointArgs, RasterArgs, ViewArgs, non_negative, overlay, positive};
use crate::cli::output::{SideFile, side_files};

/// RGBA pixels, row 0 at the top.
type Image = Vec<[f32; 4]>;
use crate::cli::session::Outputs;

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

impl FitArticulatedArgs {
    /// The start (`--init-angles`, default the rest pose) and the target's angles
    /// (`--target-angles`), radians, one per joint of `rig`.
    pub fn angles(&self, rig: &Rig) -> Result<(Vec<f64>, Option<Vec<f64>>)> {
        let init = match &self.init_angles {
            Some(a) => joint_angles(rig, "--init-angles", &a.0)?,
            None => vec![0.0; rig.joint_count()],
        };
        let target = self.target_angles.as_ref();
        let target = target.map(|a| joint_angles(rig, "--target-angles", &a.0));
        Ok((init, target.transpose()?))
    }

    /// The image size and the `--target` image: the target's size (the size flags must agree),
    /// else the flags', else the defaults'.
    pub fn size_and_target(&self) -> Result<((u32, u32), Option<Image>)> {
        let d = self.defaults().settings;
        Ok(match &self.target {
            Some(path) => self.view.target(path).map(|(size, t)| (size, Some(t)))?,
            None if self.view.sized() => (self.view.size(), None),
            None => ((d.width, d.height), None),
        })
    }

    /// `--out`, `--render` and `--compare`, created ([`Outputs`]), and the path of
    /// `--mesh-out` (which its writer commits itself).
    pub fn outputs(&self) -> Result<(Outputs, PathBuf)> {
        let side = |flag, path, suffix| SideFile { flag, path, suffix };
        let [render, compare, mesh]: [PathBuf; 3] = side_files(
            &self.out,
            "angles",
            &[
                side("--render", self.render.as_deref(), "-render.png"),
                side("--compare", self.compare.as_deref(), "-compare.png"),
                side("--mesh-out", self.mesh_out.as_deref(), "-posed.obj"),
            ],
        )?
        .try_into()
        .expect("three side files");
        Ok((Outputs::create([self.out.clone(), render, compare])?, mesh))
    }

    /// The library's defaults for this kind of target: a target re-rendered per stage can
    /// start softer than a fixed image.
    pub fn defaults(&self) -> ArticulatedFitOptions {
        if self.target_angles.is_some() {
            ArticulatedFitOptions::for_rendered_target()
        } else {
            ArticulatedFitOptions::default()
        }
    }

    /// The fit's options at image `size`: the library's defaults for this kind of target
    /// ([`ArticulatedFitOptions::for_rendered_target`] with `--target-angles`, else
    /// [`ArticulatedFitOptions::default`]), each flag given in place of its default.
    pub fn options(&self, size: (u32, u32)) -> Result<ArticulatedFitOptions> {
        let mut o = self.defaults();
        overlay(&mut o.iterations, self.iterations);
        overlay(&mut o.lr, self.lr);
        overlay(&mut o.lr_final, self.lr_final);
        overlay(&mut o.tile, self.tile);
        Method::check_tile(o.tile)?;
        o.schedule = (!self.no_schedule).then(|| {
            let mut s = o.schedule.unwrap_or_default();
            overlay(&mut s.sigma_start, self.sigma_start);
            overlay(&mut s.gamma_start, self.gamma_start);
            overlay(&mut s.stages, self.stages);
            s
        });
        let mut blur = o.blur.unwrap_or_default();
        overlay(&mut blur.start, self.blur);
        overlay(&mut blur.stages, self.stages);
        o.blur = Some(blur).filter(|b| b.start > 0.0);
        o.settings = self.raster.settings(size)?;
        o.validate()?;
        Ok(o)
    }
}

/// Degrees to radians, one per joint of `rig` ([`Error::Input`] naming `flag` otherwise).
fn joint_angles(rig: &Rig, flag: &str, degrees: &[f64]) -> Result<Vec<f64>> {
    if degrees.len() != rig.joint_count() {
        let names: Vec<&str> = rig.joints.iter().map(|j| j.name.as_str()).collect();
        return Err(Error::Input(format!(
            "{flag}: the figure has {} joints ({}); got {} angles",
            rig.joint_count(),
            names.join(", "),
            degrees.len()
        )));
    }
    Ok(degrees.iter().map(|d| d.to_radians()).collect())
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
