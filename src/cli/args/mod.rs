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

use clap::Args;
use glam::DVec3;
use softvk::camera::{Camera, Projection};
use softvk::io;
use softvk::mesh::Mesh;
use softvk::raster::settings::MAX_IMAGE_SIDE;
use softvk::{Error, Result};

mod raster;
pub use raster::*;

#[cfg(test)]
mod tests;

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

/// An image size `(width, height)` and its RGBA pixels (row 0 at the top).
pub type SizedImage = ((u32, u32), Vec<[f32; 4]>);

impl ViewArgs {
    /// Whether the image size was given (`--size` or `--width`/`--height`).
    pub fn sized(&self) -> bool {
        self.size.is_some() || self.width.is_some()
    }

    /// The target image at `path` (a PNG with alpha, [`load_target`]) and the image size: the
    /// target's, which the size flags, where given, must agree with.
    ///
    /// [`load_target`]: crate::cli::output::load_target
    pub fn target(&self, path: &Path) -> Result<SizedImage> {
        let (tw, th, pixels) = crate::cli::output::load_target(path)?;
        let size = if self.sized() { self.size() } else { (tw, th) };
        if size != (tw, th) {
            return Err(Error::Input(format!(
                "the target {} is {tw}x{th} but the image is {}x{}",
                path.display(),
                size.0,
                size.1
            )));
        }
        Ok((size, pixels))
    }

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

/// Image sides: 1..=[`MAX_IMAGE_SIDE`] (the renderer may still refuse a size that does not fit
/// the device's buffers, with its own one-line error).
pub(super) fn image_side() -> clap::builder::RangedI64ValueParser<u32> {
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

/// Layers a flag over its default: `flag`, where given, in place of `*default`. Each command
/// layers its flags over the library's defaults once, in its options function.
pub fn overlay<T>(default: &mut T, flag: Option<T>) {
    if let Some(v) = flag {
        *default = v;
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

/// A silhouette fit's views (`fit-mesh`, `fit-field`): the silhouettes in `dir`, the cameras'
/// CSV rows, one per silhouette, and the `--size` given, which must be the silhouettes'.
pub fn load_silhouette_views(
    dir: &Path,
    cameras: &Path,
    size: Option<u32>,
) -> Result<(io::Silhouettes, Vec<io::CameraRow>)> {
    let sil = io::load_silhouettes(dir)?;
    let rows = io::load_cameras(cameras)?;
    io::check_counts(&rows, &sil)?;
    if let Some(n) = size {
        if (n, n) != (sil.width, sil.height) {
            return Err(Error::Input(format!(
                "--size {n}, but the silhouettes are {}x{}",
                sil.width, sil.height
            )));
        }
    }
    Ok((sil, rows))
}

/// A fit's report folder by default: `<out stem>-report` beside `out`.
pub fn default_report(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map_or("fit".into(), |s| s.to_string_lossy().into_owned());
    out.with_file_name(format!("{stem}-report"))
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
