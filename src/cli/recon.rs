//! `softvk recon --model MODEL --image IMG --out M.obj`: one image to a mesh (a field's by
//! marching cubes), and a shaded turntable GIF of it beside the input. `softvk train-recon`
//! trains the models ([`super::train_recon`]), `softvk eval-recon` scores them
//! ([`super::eval_recon`]).

use std::path::{Path, PathBuf};

use clap::Args;
use softvk::camera::Camera;
use softvk::fit::report::{self, GifWriter};
use softvk::gpu::{Context, ContextOptions};
use softvk::io::write_obj_colored;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::recon::dataset;
use softvk::recon::model::ReconModel;
use softvk::recon::reconstruct::{AnyReconstructor, upscale, view_settings};
use softvk::{Error, Result};

/// The flags of `softvk recon`.
#[derive(Args, Clone, Debug)]
pub struct ReconArgs {
    /// A model written by `softvk train-recon`.
    #[arg(long, value_name = "MODEL")]
    pub model: PathBuf,

    /// The input: an RGBA PNG of the model's image size (64×64), the object on a transparent
    /// background as in the dataset.
    #[arg(long, value_name = "IMG")]
    pub image: PathBuf,

    /// The reconstructed mesh (OBJ). Beside it, `<stem>-turntable.gif`.
    #[arg(long, value_name = "M.obj")]
    pub out: PathBuf,
}

/// An RGBA PNG as the network's input bytes (planes R, G, B, A).
fn read_input(path: &Path, size: u32) -> Result<Vec<u8>> {
    let img = image::open(path)
        .map_err(|e| Error::Input(format!("{}: {e}", path.display())))?
        .to_rgba8();
    if img.width() != size || img.height() != size {
        return Err(Error::Input(format!(
            "{}: {}×{} pixels; the model takes {size}×{size}",
            path.display(),
            img.width(),
            img.height()
        )));
    }
    let px = (size * size) as usize;
    let mut planes = vec![0u8; 4 * px];
    for (i, p) in img.pixels().enumerate() {
        for c in 0..4 {
            planes[c * px + i] = p[c];
        }
    }
    Ok(planes)
}

/// `softvk recon`.
pub fn recon(args: &ReconArgs) -> Result<()> {
    let model = ReconModel::load(&args.model)?;
    let input = read_input(&args.image, model.net.image)?;
    let ctx = Context::new(&ContextOptions::from_env())?;
    let recon = AnyReconstructor::new(&ctx, &model, 1)?;
    let mesh = recon.mesh(&ctx, &input)?.ok_or_else(|| {
        Error::Input(format!(
            "{}: the field is empty for this image (no φ = 0.5 surface)",
            args.image.display()
        ))
    })?;
    let stem = args
        .out
        .file_stem()
        .map_or_else(|| "recon".into(), |s| s.to_string_lossy().into_owned());
    let gif = args.out.with_file_name(format!("{stem}-turntable.gif"));
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .map_err(|e| Error::Input(format!("cannot create {}: {e}", parent.display())))?;
    }
    write_turntable(&ctx, &gif, &mesh, &input, model.net.image)?;
    write_obj_colored(
        &args.out,
        &mesh.positions,
        mesh.vertex_colors.as_deref(),
        &mesh.faces,
    )?;
    println!("wrote {} and {}", args.out.display(), gif.display());
    Ok(())
}

/// The reconstruction shaded, turning (24 frames at the dataset's elevation and distance),
/// beside the input.
fn write_turntable(ctx: &Context, path: &Path, mesh: &Mesh, input: &[u8], size: u32) -> Result<()> {
    const SIZE: u32 = 128;
    let settings = view_settings(SIZE);
    let cams: Vec<Camera> = (0..dataset::VIEWS).map(dataset::view_camera).collect();
    let frames = Renderer::new(ctx)?.render_views(
        ctx,
        mesh,
        &cams,
        &Lighting::default(),
        &settings,
        Method::default(),
    )?;
    let big = upscale(input, size, SIZE);
    let n = (SIZE * SIZE) as usize;
    let frame = |v: usize| {
        report::side_by_side(
            &[
                ("input", &big[..]),
                ("reconstruction", &frames.images[v * n..(v + 1) * n]),
            ],
            SIZE,
            SIZE,
        )
    };
    let first = frame(0);
    let mut gif = GifWriter::create(path, first.width(), first.height(), 120)?;
    gif.push(&first)?;
    for v in 1..dataset::VIEWS {
        gif.push(&frame(v))?;
    }
    gif.finish()
}
