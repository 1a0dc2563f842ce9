//! `softvk render --mesh M.obj --out IMG.(png|exr) [view] [raster]`: one view of a mesh, written
//! as RGBA (SPEC §6).
//!
//! Order of work: every check that needs no file or device first (flags, output format, camera,
//! settings), then the mesh, then the output's temporary file (an unwritable destination fails
//! before the render), then the device and the render. Any error leaves no file behind.

use std::path::PathBuf;

use clap::Args;
use softvk::camera::Camera;
use softvk::gpu::{Context, ContextOptions};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{DEFAULT_TILE, Frames, Method, Renderer};
use softvk::raster::settings::RasterSettings;
use softvk::{Error, Result};

use super::args::{RasterArgs, ViewArgs};
use super::output::{AtomicFile, ImageFormat};

/// The flags of `softvk render`.
#[derive(Args, Clone, Debug)]
pub struct RenderArgs {
    /// The mesh (OBJ; all objects merged, polygons fan-triangulated, MTL map_Kd textures).
    #[arg(long, value_name = "M.obj")]
    pub mesh: PathBuf,

    /// Centre the mesh and scale its longest side to [-1, 1], as SoftRas's
    /// `load_obj(normalization=True)` (for meshes as distributed, in their own units).
    #[arg(long)]
    pub normalize: bool,

    /// The image to write: .png (8-bit RGBA) or .exr (float32 R, G, B, A).
    #[arg(long, value_name = "IMG")]
    pub out: PathBuf,

    #[command(flatten)]
    pub view: ViewArgs,

    #[command(flatten)]
    pub raster: RasterArgs,

    /// Tile edge in pixels for the tiled rasterizer (a multiple of 8).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_TILE)]
    pub tile: u32,

    /// Use the brute-force kernel (every face for every pixel, as SoftRas) instead of tiles.
    /// Same pixels, bit for bit; slower.
    #[arg(long)]
    pub brute: bool,
}

impl RenderArgs {
    /// The fine pass these flags ask for.
    pub fn method(&self) -> Method {
        if self.brute {
            Method::Brute
        } else {
            Method::Tiled { tile: self.tile }
        }
    }
}

/// Runs `softvk render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let format = ImageFormat::from_path(&args.out)?;
    Method::check_tile(args.tile)?;
    let camera = args.view.camera()?;
    let settings = args.raster.settings(args.view.size())?;
    let lighting = args.raster.lighting();

    let mesh = super::args::load_mesh(&args.mesh, args.raster.texture_res, args.normalize)?;
    if args.raster.vertex_colors && mesh.vertex_colors.is_none() {
        return Err(Error::Input(format!(
            "--vertex-colors: {} has no vertex colours (every `v` line needs `x y z r g b`)",
            args.mesh.display()
        )));
    }

    let out = AtomicFile::create(&args.out)?;
    let ctx = Context::new(&ContextOptions::from_env())?;
    let frames =
        render_frames(&ctx, &mesh, &camera, &lighting, &settings, args.method()).map_err(|e| {
            match e {
                // Say which request is too large, not only which buffer: the image, or the
                // mesh and its per-face textures.
                Error::Limit(m) => Error::Limit(format!(
                    "the scene is too large for this device ({}x{} image{}, {} faces at \
                     --texture-res {}): {m}",
                    settings.width,
                    settings.height,
                    if settings.antialias {
                        " rendered at 2x for --antialias"
                    } else {
                        ""
                    },
                    mesh.face_count(),
                    mesh.texture_res
                )),
                e => e,
            }
        })?;
    ctx.check_validation()?;

    let bytes = format
        .encode(frames.image(0), frames.width, frames.height)
        .map_err(|e| Error::Input(format!("{}: {e}", args.out.display())))?;
    out.commit(&bytes)
}

/// The one call through which the CLI renders an image: the tiled GPU rasterizer by default
/// (bit for bit the brute-force kernel's pixels), or the brute-force kernel itself.
pub fn render_frames(
    ctx: &Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    settings: &RasterSettings,
    method: Method,
) -> Result<Frames> {
    Renderer::new(ctx)?.render_views(
        ctx,
        mesh,
        std::slice::from_ref(camera),
        lighting,
        settings,
        method,
    )
}
