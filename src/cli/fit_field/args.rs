//! The flags of `softvk fit-field`, and the fit's options they make.

use crate::cli::args::{CheckpointArgs, finite, non_negative, positive, viewing_angle};
use clap::{Args, ValueEnum};
use softvk::camera::{Camera, Projection};
use softvk::field::{Cube, FieldKind};
use softvk::fit::AdamOptions;
use softvk::fit::field_fit::{self, DEFAULT_CUBE_MARGIN, FieldFitOptions};
use softvk::io;
use softvk::probe::{Aggregate, ProbeSettings};
use softvk::{Error, Result};
use std::path::PathBuf;

/// `--field`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldArg {
    /// A dense grid of logits, trilinear (`--grid-res`).
    Grid,
    /// An MLP with positional encoding (`--mlp-layers`, `--mlp-width`, `--mlp-freqs`).
    Mlp,
}

/// `--aggregate`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AggregateArg {
    /// ψ = max φ over the anchors a ray hits (the paper).
    Max,
    /// ψ = T log Σ exp(φ / T) (`--temperature`).
    Lse,
    /// ψ = 1 − Π (1 − φ).
    Union,
}

impl From<AggregateArg> for Aggregate {
    fn from(a: AggregateArg) -> Aggregate {
        match a {
            AggregateArg::Max => Aggregate::Max,
            AggregateArg::Lse => Aggregate::LogSumExp,
            AggregateArg::Union => Aggregate::Union,
        }
    }
}

/// `--cube`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CubeArg {
    /// Around the visual hull ([`auto_cube`]).
    Auto,
    /// Given.
    Given(Cube),
}

/// `--cube`: `auto` or `cx,cy,cz,half`.
pub(super) fn cube_arg(s: &str) -> std::result::Result<CubeArg, String> {
    if s.trim() == "auto" {
        return Ok(CubeArg::Auto);
    }
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 4 {
        return Err(format!(
            "expected `auto` or four comma-separated numbers cx,cy,cz,half, got {} value(s) in \
             `{s}`",
            parts.len()
        ));
    }
    let v = parts
        .iter()
        .map(|p| finite(p))
        .collect::<std::result::Result<Vec<f64>, String>>()?;
    Cube::new([v[0], v[1], v[2]], v[3])
        .map(CubeArg::Given)
        .map_err(|_| format!("the half-edge must be > 0, got {}", v[3]))
}

pub(super) fn fraction(s: &str) -> std::result::Result<f64, String> {
    let v = finite(s)?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("must be in [0, 1], got {v}"))
    }
}

/// The flags of `softvk fit-field`. Defaults were chosen by measurement on spot (RESULTS.md,
/// "Sphere probing").
#[derive(Args, Clone, Debug)]
pub struct FitFieldArgs {
    /// Folder of target silhouettes (PNG, sorted by name; alpha, else luminance, > 0.5 inside).
    #[arg(long, value_name = "DIR")]
    pub silhouettes: PathBuf,

    /// Cameras: CSV `distance,elevation,azimuth`, one row per silhouette, degrees.
    #[arg(long, value_name = "C.csv")]
    pub cameras: PathBuf,

    /// The fitted surface φ = 0.5 (OBJ, by marching cubes).
    #[arg(long, value_name = "M.obj")]
    pub out: PathBuf,

    /// Iterations.
    #[arg(long = "iters", value_name = "N", default_value_t = field_fit::DEFAULT_ITERATIONS)]
    pub iterations: u32,

    /// Image size; must match the silhouettes (default: theirs).
    #[arg(long, value_name = "N")]
    pub size: Option<u32>,

    /// Viewing angle of the cameras, degrees (as fit-mesh: 15).
    #[arg(long, value_name = "A", default_value_t = 15.0, value_parser = viewing_angle)]
    pub viewing_angle: f64,

    // ---- the field ----
    /// The field: a grid of logits or an MLP.
    #[arg(long, value_enum, default_value_t = FieldArg::Grid, help_heading = "Field")]
    pub field: FieldArg,

    /// Grid nodes per axis.
    #[arg(long, value_name = "N", default_value_t = field_fit::DEFAULT_GRID_RES,
          help_heading = "Field")]
    pub grid_res: u32,

    /// MLP hidden layers.
    #[arg(long, value_name = "L", default_value_t = 4, help_heading = "Field")]
    pub mlp_layers: u32,

    /// MLP units per hidden layer.
    #[arg(long, value_name = "W", default_value_t = 64, help_heading = "Field")]
    pub mlp_width: u32,

    /// MLP positional-encoding frequencies.
    #[arg(long, value_name = "F", default_value_t = 4, help_heading = "Field")]
    pub mlp_freqs: u32,

    /// The field's cube: `auto` (the visual hull's bounding cube, grown by --cube-margin) or
    /// `cx,cy,cz,half` in world units. Every camera must be outside it.
    #[arg(long, value_name = "auto|CX,CY,CZ,HALF", default_value = "auto",
          allow_hyphen_values = true, value_parser = cube_arg, help_heading = "Field")]
    pub cube: CubeArg,

    /// With --cube auto: the margin around the hull, a fraction of its half-edge.
    #[arg(long, value_name = "M", default_value_t = DEFAULT_CUBE_MARGIN,
          value_parser = non_negative, help_heading = "Field")]
    pub cube_margin: f64,

    /// A constant added to the initial logit (grid: every node; MLP: the output bias).
    #[arg(long, value_name = "L", default_value_t = field_fit::DEFAULT_INIT_LOGIT,
          allow_negative_numbers = true, value_parser = finite, help_heading = "Field")]
    pub init_logit: f64,

    // ---- sampling and probing (lengths in cube units) ----
    /// N_r, probing rays per view per iteration.
    #[arg(long, value_name = "N", default_value_t = FieldFitOptions::default().probe.rays_per_view,
          help_heading = "Probing")]
    pub rays: u32,

    /// Fraction of the rays drawn uniformly over the image (the rest near the contour).
    #[arg(long, value_name = "F", default_value_t = FieldFitOptions::default().probe.ray_uniform_fraction,
          value_parser = fraction, help_heading = "Probing")]
    pub ray_uniform: f64,

    /// σ_c, pixels: the Gaussian smoothing the silhouette's Laplacian into the contour density.
    #[arg(long, value_name = "PX", default_value_t = FieldFitOptions::default().probe.contour_sigma,
          value_parser = non_negative, help_heading = "Probing")]
    pub contour_sigma: f64,

    /// N_a, anchors per iteration.
    #[arg(long, value_name = "N", default_value_t = FieldFitOptions::default().probe.anchors,
          help_heading = "Probing")]
    pub anchors: u32,

    /// Fraction of the anchors uniform in the cube (the rest near the visual hull's boundary).
    #[arg(long, value_name = "F",
          default_value_t = FieldFitOptions::default().probe.anchor_uniform_fraction,
          value_parser = fraction, help_heading = "Probing")]
    pub anchor_uniform: f64,

    /// σ_a, cube units: the spread of the anchors around the visual hull's boundary.
    #[arg(long, value_name = "S", default_value_t = FieldFitOptions::default().probe.anchor_sigma,
          value_parser = non_negative, help_heading = "Probing")]
    pub anchor_sigma: f64,

    /// Lattice points per axis of the visual hull the anchors are drawn around.
    #[arg(long, value_name = "N", default_value_t = FieldFitOptions::default().probe.hull_resolution,
          help_heading = "Probing")]
    pub hull_res: u32,

    /// τ, cube units: the anchor spheres' radius.
    #[arg(long, value_name = "T", default_value_t = FieldFitOptions::default().probe.tau,
          value_parser = finite, help_heading = "Probing")]
    pub tau: f64,

    /// G, how a ray combines the φ of the anchors it hits.
    #[arg(long, value_enum, default_value_t = AggregateArg::Max, help_heading = "Probing")]
    pub aggregate: AggregateArg,

    /// The log-sum-exp temperature (with --aggregate lse).
    #[arg(long, value_name = "T", default_value_t = FieldFitOptions::default().probe.temperature,
          value_parser = positive, help_heading = "Probing")]
    pub temperature: f64,

    /// Turn off boundary-aware assignment (a ray then uses every anchor it hits).
    #[arg(long, help_heading = "Probing")]
    pub no_boundary_aware: bool,

    /// Screen tile edge of the anchor binning, pixels.
    #[arg(long, value_name = "PX", default_value_t = FieldFitOptions::default().probe.tile_size,
          help_heading = "Probing")]
    pub tile: u32,

    // ---- the geometric regularizer ----
    /// N, surface candidates of the regularizer per iteration (49 field points each).
    #[arg(long, value_name = "N", default_value_t = FieldFitOptions::default().probe.geo_candidates,
          help_heading = "Regularizer")]
    pub geo_candidates: u32,

    /// Fraction of the candidates uniform in the cube.
    #[arg(long, value_name = "F",
          default_value_t = FieldFitOptions::default().probe.geo_uniform_fraction,
          value_parser = fraction, help_heading = "Regularizer")]
    pub geo_uniform: f64,

    /// δ, cube units: the offset of a candidate's six neighbours.
    #[arg(long, value_name = "D", default_value_t = FieldFitOptions::default().probe.geo_delta,
          value_parser = finite, help_heading = "Regularizer")]
    pub geo_delta: f64,

    /// δ_n, cube units: the central-difference step of the normals.
    #[arg(long, value_name = "D", default_value_t = FieldFitOptions::default().probe.geo_normal_delta,
          value_parser = finite, help_heading = "Regularizer")]
    pub geo_normal_delta: f64,

    /// ε, half-width of the surface window W(x) = 1[|x − 0.5| < ε].
    #[arg(long, value_name = "E", default_value_t = FieldFitOptions::default().probe.geo_epsilon,
          value_parser = finite, help_heading = "Regularizer")]
    pub geo_epsilon: f64,

    /// p, the exponent of the normal-difference norm (≥ 1).
    #[arg(long, value_name = "P", default_value_t = FieldFitOptions::default().probe.geo_p,
          value_parser = finite, help_heading = "Regularizer")]
    pub geo_p: f64,

    /// λ, the weight of L_geo (0 turns the regularizer off).
    #[arg(long, value_name = "W", default_value_t = FieldFitOptions::default().probe.geo_lambda,
          value_parser = non_negative, help_heading = "Regularizer")]
    pub lambda: f64,

    // ---- optimization and outputs ----
    /// Adam learning rate.
    #[arg(long, value_name = "LR", default_value_t = field_fit::DEFAULT_LR,
          value_parser = positive, help_heading = "Optimizer")]
    pub lr: f64,

    /// Adam β1.
    #[arg(long, value_name = "B1", default_value_t = FieldFitOptions::default().adam.betas.0,
          value_parser = finite, help_heading = "Optimizer")]
    pub beta1: f64,

    /// Adam β2.
    #[arg(long, value_name = "B2", default_value_t = FieldFitOptions::default().adam.betas.1,
          value_parser = finite, help_heading = "Optimizer")]
    pub beta2: f64,

    /// Seed of every random stream (and of the MLP's initialization).
    #[arg(
        long,
        value_name = "S",
        default_value_t = 0,
        help_heading = "Optimizer"
    )]
    pub seed: u64,

    /// Marching-cubes lattice nodes per axis.
    #[arg(long, value_name = "N", default_value_t = 128, help_heading = "Output")]
    pub mc_res: u32,

    /// Side of the preview image, pixels.
    #[arg(long, value_name = "N", default_value_t = 256, help_heading = "Output")]
    pub preview_size: u32,

    /// Read the losses back every N iterations.
    #[arg(long, value_name = "N", default_value_t = FieldFitOptions::default().log_every,
          help_heading = "Output")]
    pub log_every: u32,

    /// Where the report goes (default: the output's path without extension + `-report`).
    #[arg(long, value_name = "DIR", help_heading = "Output")]
    pub report: Option<PathBuf>,

    /// No progress bar.
    #[arg(long, help_heading = "Output")]
    pub quiet: bool,

    #[command(flatten)]
    pub checkpoints: CheckpointArgs,
}

impl FitFieldArgs {
    /// The options in cube units (the cube itself is set by [`scaled_to_cube`] later).
    pub(super) fn options(&self) -> Result<FieldFitOptions> {
        let field = match self.field {
            FieldArg::Grid => FieldKind::Grid { res: self.grid_res },
            FieldArg::Mlp => FieldKind::Mlp {
                hidden_layers: self.mlp_layers,
                width: self.mlp_width,
                frequencies: self.mlp_freqs,
            },
        };
        let opts = FieldFitOptions {
            field,
            probe: ProbeSettings {
                rays_per_view: self.rays,
                ray_uniform_fraction: self.ray_uniform,
                contour_sigma: self.contour_sigma,
                anchors: self.anchors,
                anchor_uniform_fraction: self.anchor_uniform,
                anchor_sigma: self.anchor_sigma,
                hull_resolution: self.hull_res,
                tau: self.tau,
                aggregate: self.aggregate.into(),
                temperature: self.temperature,
                boundary_aware: !self.no_boundary_aware,
                tile_size: self.tile,
                geo_candidates: self.geo_candidates,
                geo_uniform_fraction: self.geo_uniform,
                geo_delta: self.geo_delta,
                geo_normal_delta: self.geo_normal_delta,
                geo_epsilon: self.geo_epsilon,
                geo_p: self.geo_p,
                geo_lambda: self.lambda,
                seed: self.seed,
                ..ProbeSettings::default()
            },
            adam: AdamOptions {
                lr: self.lr,
                betas: (self.beta1, self.beta2),
                eps: 1e-8,
            },
            iterations: self.iterations,
            log_every: self.log_every,
            init_logit: self.init_logit,
        };
        if self.iterations == 0 || self.log_every == 0 {
            return Err(Error::Input(
                "--iters and --log-every must be at least 1".into(),
            ));
        }
        if !(2..=1024).contains(&self.mc_res) {
            return Err(Error::Input(format!(
                "--mc-res {}: need 2..=1024",
                self.mc_res
            )));
        }
        if !(1..=4096).contains(&self.preview_size) {
            return Err(Error::Input(format!(
                "--preview-size {}: need 1..=4096",
                self.preview_size
            )));
        }
        // In cube units, on the unit cube: the same checks as in world units.
        opts.validate()?;
        Ok(opts)
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
