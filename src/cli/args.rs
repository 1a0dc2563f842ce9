//! The flag groups of SPEC §6 that several subcommands share: `[view]` ([`ViewArgs`]) and
//! `[raster]` ([`RasterArgs`]). A subcommand flattens them (`#[command(flatten)]`) and turns them
//! into library types with [`ViewArgs::size`], [`ViewArgs::camera`], [`RasterArgs::settings`] and
//! [`RasterArgs::lighting`].
//!
//! Every number is checked where it is parsed (finite, in its domain), so a bad value is one
//! clap error naming the flag; the checks that involve two flags (near < far) are
//! `RasterSettings::validate`'s. Defaults are SoftRas's `SoftRenderer` ones, the same values as
//! the library's `Default` impls (a unit test keeps them equal).

use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};
use glam::DVec3;
use softvk::camera::{Camera, Projection};
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::{MAX_TEXTURE_RES, Mesh};
use softvk::raster::settings::{Alpha, ColorMode, Dist, MAX_IMAGE_SIDE, RasterSettings, Rgb};
use softvk::{Error, Result};

/// Default image side (SoftRas `image_size`).
pub const DEFAULT_SIZE: u32 = 256;

/// `[view]`: image size and camera.
#[derive(Args, Clone, Debug, PartialEq)]
#[command(next_help_heading = "View")]
pub struct ViewArgs {
    /// Square image side in pixels [default: 256].
    #[arg(
        long, allow_negative_numbers = true, value_name = "N",
        conflicts_with_all = ["width", "height"], value_parser = image_side(),
    )]
    pub size: Option<u32>,

    /// Image width in pixels (with --height).
    #[arg(
        long, allow_negative_numbers = true, value_name = "W", requires = "height",
        value_parser = image_side(),
    )]
    pub width: Option<u32>,

    /// Image height in pixels (with --width).
    #[arg(
        long, allow_negative_numbers = true, value_name = "H", requires = "width",
        value_parser = image_side(),
    )]
    pub height: Option<u32>,

    /// Distance of the eye from the origin.
    #[arg(
        long, value_name = "D", default_value_t = 2.732, allow_negative_numbers = true,
        value_parser = finite,
    )]
    pub distance: f64,

    /// Elevation of the eye, degrees.
    #[arg(
        long, value_name = "E", default_value_t = 0.0, allow_negative_numbers = true,
        value_parser = finite,
    )]
    pub elevation: f64,

    /// Azimuth of the eye, degrees (0 puts the eye on -z).
    #[arg(
        long, value_name = "A", default_value_t = 0.0, allow_negative_numbers = true,
        value_parser = finite,
    )]
    pub azimuth: f64,

    /// Eye position, instead of --distance/--elevation/--azimuth. The camera looks at the
    /// origin with +y up.
    #[arg(
        long, value_name = "X,Y,Z", conflicts_with_all = ["distance", "elevation", "azimuth"],
        allow_hyphen_values = true, value_parser = triple,
    )]
    pub eye: Option<[f64; 3]>,

    /// Perspective viewing angle, degrees, in (0, 90) (SoftRas: x_s = x / (z tan a)).
    #[arg(
        long, allow_negative_numbers = true, value_name = "A", default_value_t = 30.0,
        conflicts_with = "orthographic", value_parser = viewing_angle,
    )]
    pub viewing_angle: f64,

    /// Orthographic projection (x_s = s x, y_s = s y) instead of perspective.
    #[arg(long)]
    pub orthographic: bool,

    /// Orthographic scale s (needs --orthographic).
    #[arg(
        long, allow_negative_numbers = true, value_name = "S", default_value_t = 1.0,
        requires = "orthographic", value_parser = positive,
    )]
    pub scale: f64,
}

impl Default for ViewArgs {
    fn default() -> Self {
        ViewArgs {
            size: None,
            width: None,
            height: None,
            distance: 2.732,
            elevation: 0.0,
            azimuth: 0.0,
            eye: None,
            viewing_angle: 30.0,
            orthographic: false,
            scale: 1.0,
        }
    }
}

impl ViewArgs {
    /// `(width, height)`: `--size`, or `--width`/`--height`, or 256².
    pub fn size(&self) -> (u32, u32) {
        match (self.size, self.width, self.height) {
            (Some(s), _, _) => (s, s),
            (None, Some(w), Some(h)) => (w, h),
            _ => (DEFAULT_SIZE, DEFAULT_SIZE),
        }
    }

    /// The camera: SoftRas `look_at` from the eye to the origin with +y up, perspective or
    /// orthographic. An eye at the origin, or one straight above or below it (elevation ±90°),
    /// leaves `look_at` without an orientation (SoftRas then projects everything to the image
    /// centre); that is an error here rather than a blank image.
    pub fn camera(&self) -> Result<Camera> {
        let mut camera = match self.eye {
            Some(e) => Camera {
                eye: DVec3::from(e),
                ..Camera::default()
            },
            None => Camera::from_angles(self.distance, self.elevation, self.azimuth),
        };
        camera.projection = if self.orthographic {
            Projection::Orthographic { scale: self.scale }
        } else {
            Projection::Perspective {
                viewing_angle_deg: self.viewing_angle,
            }
        };
        // The eps SoftRas's look_at normalizes with: below it the axes collapse.
        const LOOK_AT_EPS: f64 = 1e-5;
        let dir = camera.at - camera.eye;
        if dir.length() < LOOK_AT_EPS {
            return Err(Error::Input(format!(
                "the eye {:?} is at the point looked at (the origin): no view direction",
                camera.eye.to_array()
            )));
        }
        if camera.up.cross(dir.normalize()).length() < LOOK_AT_EPS {
            return Err(Error::Input(format!(
                "the eye {:?} looks straight along the up axis +y (elevation ±90°): look_at \
                 has no orientation there",
                camera.eye.to_array()
            )));
        }
        Ok(camera)
    }
}

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

/// Image sides: 1..=[`MAX_IMAGE_SIDE`] (the renderer may still refuse a size that does not fit
/// the device's buffers, with its own one-line error).
fn image_side() -> clap::builder::RangedI64ValueParser<u32> {
    clap::value_parser!(u32).range(1..=i64::from(MAX_IMAGE_SIDE))
}

/// A finite number. Rust's `f64::from_str` accepts `nan` and `inf`; a flag never wants them.
pub fn finite(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(format!("`{s}` is not a finite number"))
    }
}

/// A finite number > 0.
pub fn positive(s: &str) -> std::result::Result<f64, String> {
    let v = finite(s)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(format!("must be > 0, got {v}"))
    }
}

/// A finite number ≥ 0.
pub fn non_negative(s: &str) -> std::result::Result<f64, String> {
    let v = finite(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err(format!("must be >= 0, got {v}"))
    }
}

/// A perspective viewing angle in degrees: tan must be finite and positive.
pub fn viewing_angle(s: &str) -> std::result::Result<f64, String> {
    let v = finite(s)?;
    if v > 0.0 && v < 90.0 {
        Ok(v)
    } else {
        Err(format!("must be in (0, 90) degrees, got {v}"))
    }
}

/// `x,y,z`: exactly three finite numbers separated by commas (spaces around them allowed).
pub fn triple(s: &str) -> std::result::Result<[f64; 3], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected three comma-separated numbers x,y,z, got {} value(s) in `{s}`",
            parts.len()
        ));
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = finite(p)?;
    }
    Ok(out)
}

/// The OBJ at `path` with `texture_res`² texels a face, normalized as SoftRas's
/// `load_obj(normalization=True)` with `--normalize` ([`Mesh::normalize`]).
pub fn load_mesh(path: &Path, texture_res: u32, normalize: bool) -> Result<Mesh> {
    let mut mesh = Mesh::load_obj(path, texture_res)?;
    if normalize {
        mesh.normalize()
            .map_err(|e| Error::Input(format!("{}: {e}", path.display())))?;
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct Both {
        #[command(flatten)]
        view: ViewArgs,
        #[command(flatten)]
        raster: RasterArgs,
    }

    fn parse(args: &[&str]) -> std::result::Result<Both, clap::Error> {
        Both::try_parse_from(std::iter::once("t").chain(args.iter().copied()))
    }

    #[test]
    fn triples_take_exactly_three_finite_numbers() {
        assert_eq!(triple("1,-2.5, 3e-1"), Ok([1.0, -2.5, 0.3]));
        assert_eq!(triple(" 0 , 0 , 0 "), Ok([0.0; 3]));
        for bad in [
            "1,2", "1,2,3,4", "", "1,,3", "a,b,c", "nan,0,0", "0,inf,0", "0,0,-inf",
        ] {
            let err = triple(bad).unwrap_err();
            assert!(!err.contains('\n'), "{err}");
        }
        assert!(triple("1,2").unwrap_err().contains("three"));
        assert!(triple("nan,0,0").unwrap_err().contains("finite"));
    }

    #[test]
    fn numbers_reject_nan_inf_and_out_of_domain_values() {
        assert_eq!(finite("-3"), Ok(-3.0));
        assert!(finite("NaN").is_err() && finite("inf").is_err() && finite("x").is_err());
        assert!(positive("0").is_err() && positive("-1e-9").is_err());
        assert_eq!(positive("1e-9"), Ok(1e-9));
        assert!(non_negative("-0.1").is_err());
        assert_eq!(non_negative("0"), Ok(0.0));
        assert!(viewing_angle("0").is_err() && viewing_angle("90").is_err());
        assert_eq!(viewing_angle("45"), Ok(45.0));
    }

    #[test]
    fn no_flags_give_the_library_defaults() {
        let b = parse(&[]).unwrap();
        assert_eq!(b.view, ViewArgs::default());
        assert_eq!(b.raster, RasterArgs::default());
        assert_eq!(b.view.size(), (256, 256));
        assert_eq!(b.view.camera().unwrap(), Camera::default());
        assert_eq!(
            b.raster.settings(b.view.size()).unwrap(),
            RasterSettings::default()
        );
        assert_eq!(b.raster.lighting(), Lighting::default());
    }

    #[test]
    fn every_flag_reaches_its_setting() {
        let b = parse(&[
            "--width",
            "40",
            "--height",
            "24",
            "--eye",
            "1,-2,3",
            "--viewing-angle",
            "25",
            "--sigma",
            "1e-3",
            "--gamma",
            "0.02",
            "--dist",
            "barycentric",
            "--rgb",
            "hard",
            "--alpha",
            "sum",
            "--near",
            "-0.5",
            "--far",
            "7",
            "--background",
            "0.1,0.2,-0.3",
            "--single-sided",
            "--antialias",
            "--texture-res",
            "4",
            "--vertex-colors",
            "--ambient",
            "0.25",
            "--directional",
            "0.75",
            "--light-dir",
            "-1,0.5,2",
        ])
        .unwrap();
        assert_eq!(b.view.size(), (40, 24));
        assert_eq!(
            b.view.camera().unwrap(),
            Camera {
                eye: DVec3::new(1.0, -2.0, 3.0),
                projection: Projection::Perspective {
                    viewing_angle_deg: 25.0
                },
                ..Camera::default()
            }
        );
        assert_eq!(
            b.raster.settings((40, 24)).unwrap(),
            RasterSettings {
                width: 40,
                height: 24,
                sigma: 1e-3,
                gamma: 0.02,
                near: -0.5,
                far: 7.0,
                dist: Dist::Barycentric,
                rgb: Rgb::Hard,
                alpha: Alpha::Sum,
                background: [0.1, 0.2, -0.3],
                double_sided: false,
                antialias: true,
                color_mode: ColorMode::Vertex,
                ..RasterSettings::default()
            }
        );
        assert_eq!(b.raster.texture_res, 4);
        assert_eq!(
            b.raster.lighting(),
            Lighting {
                ambient_intensity: 0.25,
                ambient_color: [1.0; 3],
                directionals: vec![Directional {
                    intensity: 0.75,
                    color: [1.0; 3],
                    direction: [-1.0, 0.5, 2.0],
                }],
            }
        );

        let b = parse(&[
            "--size",
            "9",
            "--distance",
            "3",
            "--elevation",
            "-20",
            "--azimuth",
            "135",
            "--orthographic",
            "--scale",
            "0.5",
        ])
        .unwrap();
        assert_eq!(b.view.size(), (9, 9));
        assert_eq!(
            b.view.camera().unwrap(),
            Camera {
                projection: Projection::Orthographic { scale: 0.5 },
                ..Camera::from_angles(3.0, -20.0, 135.0)
            }
        );
    }

    #[test]
    fn exclusive_and_paired_flags_are_usage_errors() {
        for bad in [
            &["--size", "8", "--width", "8", "--height", "8"][..],
            &["--width", "8"],
            &["--height", "8"],
            &["--eye", "0,0,-3", "--distance", "3"],
            &["--eye", "0,0,-3", "--azimuth", "10"],
            &["--scale", "2"],
            &["--orthographic", "--viewing-angle", "20"],
            &["--size", "0"],
            &["--size", "100000"],
            &["--texture-res", "0"],
            &["--texture-res", "65"],
            &["--sigma", "0"],
            &["--gamma", "-1"],
            &["--dist", "manhattan"],
            &["--rgb", "max"],
            &["--alpha", "min"],
            &["--background", "1,1"],
            &["--light-dir", "nan,1,0"],
            &["--ambient", "-1"],
            &["--near", "inf"],
        ] {
            assert!(parse(bad).is_err(), "{bad:?} was accepted");
        }
        // Negative numbers are values, not flags.
        assert!(parse(&["--azimuth", "-45", "--elevation", "-1e1"]).is_ok());
        assert!(parse(&["--eye", "-1,-1,-1"]).is_ok());
    }

    #[test]
    fn cross_flag_checks_are_errors_not_images() {
        let b = parse(&["--near", "5", "--far", "5"]).unwrap();
        assert!(b.raster.settings((8, 8)).is_err());
        for eye in ["0,0,0", "0,2,0", "0,-1e-3,0"] {
            let b = parse(&["--eye", eye]).unwrap();
            assert!(b.view.camera().is_err(), "{eye}");
        }
        let b = parse(&["--elevation", "90"]).unwrap();
        assert!(b.view.camera().is_err());
        let b = parse(&["--distance", "0"]).unwrap();
        assert!(b.view.camera().is_err());
    }
}

/// `--checkpoint DIR`, `--checkpoint-every N`, `--resume DIR`: a fit's complete state on disk
/// (`fit-mesh`, `demo`, `fit-field`; `softvk::fit::checkpoint`).
#[derive(Args, Clone, Debug, Default)]
pub struct CheckpointArgs {
    /// Write the fit's complete state (parameters, Adam's moments, iteration, log) to a file in
    /// DIR every --checkpoint-every iterations, at an interrupt and at the end, atomically;
    /// `--resume DIR` goes on from it.
    #[arg(long, value_name = "DIR")]
    pub checkpoint: Option<PathBuf>,

    /// Iterations between checkpoints (rounded up to a multiple of --log-every).
    #[arg(long, value_name = "N", default_value_t = 100, requires = "checkpoint")]
    pub checkpoint_every: u32,

    /// Go on from the checkpoint in DIR, written by a fit of the same inputs and options (a mesh
    /// or field fit may ask for more iterations; a pose or articulated fit's schedule is spread
    /// over its iterations, so they must match); it ends bit for bit as the fit that never
    /// stopped.
    #[arg(long, value_name = "DIR")]
    pub resume: Option<PathBuf>,
}
