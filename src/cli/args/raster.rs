//! `[raster]` ([`RasterArgs`]): soft rasterization, colours and lights, and the enums of its
//! choices.

use clap::{Args, ValueEnum};
use softvk::Result;
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::MAX_TEXTURE_RES;
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};

use super::{finite, non_negative, positive, triple};

/// `--dist`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DistArg {
    /// sigmoid(δ d² / σ), d the distance to the triangle's edges.
    Euclidean,
    /// sigmoid(m |m| / σ), m the smallest barycentric.
    Barycentric,
    /// 1 inside, 0 outside.
    Hard,
}

/// `--rgb`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum RgbArg {
    /// Depth softmax weighted by coverage, with a background term.
    Softmax,
    /// The nearest face covering the pixel.
    Hard,
}

/// `--alpha`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AlphaArg {
    /// 1 − Π(1 − D).
    Prod,
    /// Σ D / (face count).
    Sum,
    /// 1 where any D > 0.5.
    Hard,
}

impl From<DistArg> for Dist {
    fn from(d: DistArg) -> Dist {
        match d {
            DistArg::Euclidean => Dist::Euclidean,
            DistArg::Barycentric => Dist::Barycentric,
            DistArg::Hard => Dist::Hard,
        }
    }
}

impl From<RgbArg> for Rgb {
    fn from(r: RgbArg) -> Rgb {
        match r {
            RgbArg::Softmax => Rgb::Softmax,
            RgbArg::Hard => Rgb::Hard,
        }
    }
}

impl From<AlphaArg> for Alpha {
    fn from(a: AlphaArg) -> Alpha {
        match a {
            AlphaArg::Prod => Alpha::Prod,
            AlphaArg::Sum => Alpha::Sum,
            AlphaArg::Hard => Alpha::Hard,
        }
    }
}

/// `[raster]`: soft rasterization, colours and lights.
#[derive(Args, Clone, Debug, PartialEq)]
#[command(next_help_heading = "Raster")]
pub struct RasterArgs {
    /// Sharpness σ of the coverage sigmoid (> 0).
    #[arg(
        long, allow_negative_numbers = true, value_name = "SIGMA", default_value_t = 1e-5,
        value_parser = positive,
    )]
    pub sigma: f64,

    /// Temperature γ of the depth softmax (> 0).
    #[arg(
        long, allow_negative_numbers = true, value_name = "GAMMA", default_value_t = 1e-4,
        value_parser = positive,
    )]
    pub gamma: f64,

    /// Coverage function.
    #[arg(long, value_enum, default_value_t = DistArg::Euclidean)]
    pub dist: DistArg,

    /// ε_d: a face is ignored at a pixel outside it where its coverage would be below this
    /// (SoftRas's dist_eps; in (0, 0.5)).
    #[arg(
        long, allow_negative_numbers = true, value_name = "EPS", default_value_t = 1e-4,
        value_parser = positive,
    )]
    pub dist_eps: f64,

    /// Colour aggregation.
    #[arg(long, value_enum, default_value_t = RgbArg::Softmax)]
    pub rgb: RgbArg,

    /// Alpha aggregation.
    #[arg(long, value_enum, default_value_t = AlphaArg::Prod)]
    pub alpha: AlphaArg,

    /// Near plane (depth along the view axis); needs near < far.
    #[arg(
        long, value_name = "Z", default_value_t = 1.0, allow_negative_numbers = true,
        value_parser = finite,
    )]
    pub near: f64,

    /// Far plane.
    #[arg(
        long, value_name = "Z", default_value_t = 100.0, allow_negative_numbers = true,
        value_parser = finite,
    )]
    pub far: f64,

    /// Background colour [default: 0,0,0].
    #[arg(long, value_name = "R,G,B", allow_hyphen_values = true, value_parser = triple)]
    pub background: Option<[f64; 3]>,

    /// Back faces get no colour (SoftRas fill_back off).
    #[arg(long)]
    pub single_sided: bool,

    /// Render at 2× and average 2×2.
    #[arg(long)]
    pub antialias: bool,

    /// Per-face texture resolution R (R×R texels sampled from the MTL's map_Kd).
    #[arg(
        long, allow_negative_numbers = true, value_name = "R", default_value_t = 1,
        value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_TEXTURE_RES)),
    )]
    pub texture_res: u32,

    /// Colour by the OBJ's per-vertex colours (`v x y z r g b`), lit with vertex normals.
    #[arg(long)]
    pub vertex_colors: bool,

    /// Ambient light intensity (≥ 0).
    #[arg(
        long, allow_negative_numbers = true, value_name = "I", default_value_t = 0.5,
        value_parser = non_negative,
    )]
    pub ambient: f64,

    /// Directional light intensity (≥ 0).
    #[arg(
        long, allow_negative_numbers = true, value_name = "I", default_value_t = 0.5,
        value_parser = non_negative,
    )]
    pub directional: f64,

    /// Direction towards the directional light, used unnormalized as SoftRas does
    /// [default: 0,1,0].
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = triple)]
    pub light_dir: Option<[f64; 3]>,
}

impl Default for RasterArgs {
    fn default() -> Self {
        RasterArgs {
            sigma: 1e-5,
            gamma: 1e-4,
            dist: DistArg::Euclidean,
            dist_eps: 1e-4,
            rgb: RgbArg::Softmax,
            alpha: AlphaArg::Prod,
            near: 1.0,
            far: 100.0,
            background: None,
            single_sided: false,
            antialias: false,
            texture_res: 1,
            vertex_colors: false,
            ambient: 0.5,
            directional: 0.5,
            light_dir: None,
        }
    }
}

impl RasterArgs {
    /// The raster settings for a `width` × `height` image, validated.
    pub fn settings(&self, (width, height): (u32, u32)) -> Result<RasterSettings> {
        let settings = RasterSettings {
            width,
            height,
            sigma: self.sigma,
            gamma: self.gamma,
            near: self.near,
            far: self.far,
            dist: self.dist.into(),
            dist_eps: self.dist_eps,
            rgb: self.rgb.into(),
            alpha: self.alpha.into(),
            background: self.background.unwrap_or([0.0; 3]),
            double_sided: !self.single_sided,
            antialias: self.antialias,
            color_mode: if self.vertex_colors {
                ColorMode::Vertex
            } else {
                ColorMode::Surface
            },
            ..RasterSettings::default()
        };
        settings.validate()?;
        Ok(settings)
    }

    /// Ambient plus one white directional light.
    pub fn lighting(&self) -> Lighting {
        Lighting {
            ambient_intensity: self.ambient,
            ambient_color: [1.0; 3],
            directionals: vec![Directional {
                intensity: self.directional,
                color: [1.0; 3],
                direction: self.light_dir.unwrap_or([0.0, 1.0, 0.0]),
            }],
        }
    }
}
