//! `softvk grad --mesh M.obj --weights W.exr --out G.csv [view] [raster]` (SPEC §6): the gradient
//! of `L = Σ_pixels,channels W ⊙ image` with respect to the mesh's world vertex positions, as
//! CSV `vertex,dx,dy,dz`, one row per vertex in the OBJ's `v` order.
//!
//! The image size is the weights' size unless `--size` or `--width/--height` say otherwise (then
//! they must agree). The forward and backward run on the GPU (tiled unless `--brute`); lighting's
//! share and the look-at are added on the host in f64. `--camera-out C.csv` also writes
//! dL/d(eye) and dL/d(distance, elevation, azimuth).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use clap::Args;
use softvk::gpu::{Context, ContextOptions};
use softvk::raster::gpu::{DEFAULT_TILE, Method, Renderer};
use softvk::{Error, Result};

use super::args::{RasterArgs, ViewArgs};
use super::output::AtomicFile;

/// The flags of `softvk grad`.
#[derive(Args, Clone, Debug)]
pub struct GradArgs {
    /// The mesh (OBJ; all objects merged, polygons fan-triangulated, MTL map_Kd textures).
    #[arg(long, value_name = "M.obj")]
    pub mesh: PathBuf,

    /// Centre the mesh and scale its longest side to [-1, 1], as SoftRas's
    /// `load_obj(normalization=True)` (for meshes as distributed, in their own units).
    #[arg(long)]
    pub normalize: bool,

    /// dL/d(image): an RGBA EXR (float channels R, G, B, A) of the rendered size.
    #[arg(long, value_name = "W.exr")]
    pub weights: PathBuf,

    /// The CSV to write: `vertex,dx,dy,dz`, one row per vertex in file order.
    #[arg(long, value_name = "G.csv")]
    pub out: PathBuf,

    /// Also write the camera gradient here: `parameter,value` rows for eye_x, eye_y, eye_z,
    /// distance, elevation and azimuth (degrees).
    #[arg(long, value_name = "C.csv")]
    pub camera_out: Option<PathBuf>,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub raster: RasterArgs,

    /// Tile edge in pixels (a multiple of 8).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_TILE)]
    pub tile: u32,

    /// Use the brute-force kernels (every face for every pixel) instead of tiles.
    #[arg(long)]
    pub brute: bool,
}

/// RGBA f32 pixels of an EXR's first layer (row 0 at the top) and its size. Missing channels
/// read as 0 (alpha too): a weight map for colour only may omit A.
pub fn read_weights(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>)> {
    let (width, height, pixels) = softvk::exr_io::read_rgba(path)?;
    if let Some(i) = pixels.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::Input(format!(
            "{}: weight at pixel ({}, {}) is not finite",
            path.display(),
            i % width as usize,
            i / width as usize
        )));
    }
    Ok((width, height, pixels))
}

/// Runs `softvk grad`.
pub fn run(args: &GradArgs) -> Result<()> {
    Method::check_tile(args.tile)?;
    let (ww, wh, weights) = read_weights(&args.weights)?;
    let explicit = args.view.size.is_some() || args.view.width.is_some();
    let size = if explicit { args.view.size() } else { (ww, wh) };
    if size != (ww, wh) {
        return Err(Error::Input(format!(
            "{} is {ww}x{wh} but the image is {}x{}",
            args.weights.display(),
            size.0,
            size.1
        )));
    }
    let camera = args.view.camera()?;
    let settings = args.raster.settings(size)?;
    let lighting = args.raster.lighting();
    let mesh = super::args::load_mesh(&args.mesh, args.raster.texture_res, args.normalize)?;
    if args.raster.vertex_colors && mesh.vertex_colors.is_none() {
        return Err(Error::Input(format!(
            "--vertex-colors: {} has no vertex colours (every `v` line needs `x y z r g b`)",
            args.mesh.display()
        )));
    }
    let out = AtomicFile::create(&args.out)?;
    let camera_out = args
        .camera_out
        .as_deref()
        .map(AtomicFile::create)
        .transpose()?;

    let ctx = Context::new(&ContextOptions::from_env())?;
    let method = if args.brute {
        Method::Brute
    } else {
        Method::Tiled { tile: args.tile }
    };
    let renderer = Renderer::new(&ctx)?;
    let mut scene = renderer.prepare(&ctx, &mesh, &[camera], &lighting, &settings)?;
    let binned = renderer.run(&ctx, &mut scene, method)?.binned();
    let grads = renderer.backward(&ctx, &binned, &weights, camera_out.is_some())?;
    ctx.check_validation()?;

    let mut csv = String::from("vertex,dx,dy,dz\n");
    for (i, g) in grads.positions.iter().enumerate() {
        writeln!(csv, "{i},{:e},{:e},{:e}", g[0], g[1], g[2]).expect("write to a String");
    }
    if let (Some(file), Some(g)) = (camera_out, grads.cameras.first()) {
        let v = &args.view;
        let [dd, de, da] = g.angles(v.distance, v.elevation, v.azimuth);
        let mut c = String::from("parameter,value\n");
        for (name, value) in [
            ("eye_x", g.eye[0]),
            ("eye_y", g.eye[1]),
            ("eye_z", g.eye[2]),
            ("distance", dd),
            ("elevation", de),
            ("azimuth", da),
        ] {
            writeln!(c, "{name},{value:e}").expect("write to a String");
        }
        file.commit(c.as_bytes())?;
    }
    out.commit(csv.as_bytes())
}
