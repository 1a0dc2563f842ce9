//! The flags of `softvk fit-mesh` and `softvk demo`, and the fit's options they make.

use crate::cli::args::{AlphaArg, CheckpointArgs, DistArg, finite, positive};
use clap::Args;
use softvk::camera::{Camera, Projection};
use softvk::fit::AdamOptions;
use softvk::fit::mesh_fit::MeshFitOptions;
use softvk::io::{self};
use softvk::raster::gpu::{DEFAULT_TILE, Method};
use softvk::raster::settings::{Alpha, Dist, RasterSettings, Rgb};
use softvk::{Error, Result};
use std::path::PathBuf;

/// The fitting flags shared by `fit-mesh` and `demo`.
#[derive(Args, Clone, Debug)]
pub struct FitArgs {
    /// Iterations [default: 2000 as SoftRas's demo for fit-mesh; 200 for the demo].
    #[arg(long = "iters", value_name = "N")]
    pub iterations: Option<u32>,

    /// Viewing angle of the cameras, degrees (SoftRas's demo: 15).
    #[arg(long, value_name = "A", default_value_t = 15.0, value_parser = positive)]
    pub viewing_angle: f64,

    /// Sharpness σ of the coverage sigmoid.
    #[arg(long, value_name = "SIGMA", default_value_t = 1e-4, value_parser = positive)]
    pub sigma: f64,

    /// Coverage: euclidean, barycentric or hard.
    #[arg(long, value_enum, default_value_t = DistArg::Euclidean)]
    pub dist: DistArg,

    /// Alpha aggregation: prod, sum or hard.
    #[arg(long, value_enum, default_value_t = AlphaArg::Prod)]
    pub alpha: AlphaArg,

    /// Adam learning rate.
    #[arg(long, value_name = "LR", default_value_t = 0.01, value_parser = positive)]
    pub lr: f64,

    /// Adam β1.
    #[arg(long, value_name = "B1", default_value_t = 0.5, value_parser = finite)]
    pub beta1: f64,

    /// Adam β2.
    #[arg(long, value_name = "B2", default_value_t = 0.99, value_parser = finite)]
    pub beta2: f64,

    /// Weight of the Laplacian regularizer.
    #[arg(long, value_name = "W", default_value_t = 0.03, value_parser = finite)]
    pub laplacian: f64,

    /// Weight of the flatten regularizer.
    #[arg(long, value_name = "W", default_value_t = 0.0003, value_parser = finite)]
    pub flatten: f64,

    /// Tile edge in pixels (a multiple of 8).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_TILE)]
    pub tile: u32,

    /// Read the loss back (and draw a progress frame, and move the progress bar) every N
    /// iterations; the N iterations in between run on the GPU in one submission.
    #[arg(long, value_name = "N", default_value_t = 20)]
    pub log_every: u32,

    /// Where the report goes (default: the output's path without extension + `-report`).
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,

    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,

    #[command(flatten)]
    pub checkpoints: CheckpointArgs,
}

/// The flags of `softvk fit-mesh`.
#[derive(Args, Clone, Debug)]
pub struct FitMeshArgs {
    /// Folder of target silhouettes (PNG, sorted by name; alpha, else luminance, > 0.5 inside).
    #[arg(long, value_name = "DIR")]
    pub silhouettes: PathBuf,

    /// Cameras: CSV `distance,elevation,azimuth`, one row per silhouette, degrees.
    #[arg(long, value_name = "C.csv")]
    pub cameras: PathBuf,

    /// The fitted mesh (OBJ).
    #[arg(long, value_name = "M.obj")]
    pub out: PathBuf,

    /// Template to deform: an OBJ, scaled into (-0.5, 0.5)³ around its centre, or `icosphere`
    /// for a 642-vertex icosphere of radius 0.5 (default: SoftRas's 1 352-vertex sphere × 0.5,
    /// built in).
    #[arg(long, value_name = "T.obj|icosphere")]
    pub template: Option<PathBuf>,

    /// Image size; must match the silhouettes (default: theirs).
    #[arg(long, value_name = "N")]
    pub size: Option<u32>,

    #[command(flatten)]
    pub fit: FitArgs,
}

impl FitArgs {
    pub(super) fn options(
        &self,
        width: u32,
        height: u32,
        iterations: u32,
    ) -> Result<MeshFitOptions> {
        Method::check_tile(self.tile)?;
        let iterations = self.iterations.unwrap_or(iterations);
        if iterations == 0 || self.log_every == 0 {
            return Err(Error::Input(
                "--iters and --log-every must be at least 1".into(),
            ));
        }
        let adam = AdamOptions {
            lr: self.lr,
            betas: (self.beta1, self.beta2),
            eps: 1e-8,
        };
        adam.validate()?;
        let settings = RasterSettings {
            width,
            height,
            sigma: self.sigma,
            dist: Dist::from(self.dist),
            alpha: Alpha::from(self.alpha),
            rgb: Rgb::Hard,
            ..RasterSettings::default()
        };
        settings.validate()?;
        Ok(MeshFitOptions {
            iterations,
            adam,
            laplacian: self.laplacian as f32,
            flatten: self.flatten as f32,
            settings,
            tile: self.tile,
            log_every: self.log_every,
            entry_capacity: None,
        })
    }

    pub(super) fn cameras(&self, rows: &[io::CameraRow]) -> Vec<Camera> {
        rows.iter()
            .map(|r| Camera {
                projection: Projection::Perspective {
                    viewing_angle_deg: self.viewing_angle,
                },
                ..r.camera()
            })
            .collect()
    }
}
