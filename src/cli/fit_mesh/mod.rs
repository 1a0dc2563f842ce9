//! `softvk fit-mesh --silhouettes DIR --cameras C.csv --out M.obj [--template T.obj] [--iters N]
//! [raster]` (SPEC §6): SoftRas's mesh deformation from silhouettes on the GPU
//! ([`softvk::fit::mesh_fit`]), and `softvk demo`, which makes its own targets first.
//!
//! Besides the mesh it writes a report folder (default: `<out>` without its extension +
//! `-report/`): `ious.csv` (final per-view IoU of the hard silhouettes), `contact_sheet.png`
//! (predicted vs target at 3× the view size, labelled with each view's IoU: white both, red
//! predicted only, cyan target only), `turntable.gif` (the fitted mesh shaded, turning; beside
//! the target's for `demo`), `loss.png` (the loss curves), `loss.csv` (the logged losses,
//! each logged iteration's (face, tile) entries and the seconds) and `progress.gif` (the contact sheet every
//! logged iteration). Defaults are
//! SoftRas's deformation demo: σ 1e-4, hard colour aggregation, viewing angle 15°, Adam lr 0.01
//! with betas 0.5, 0.99, 1 − IoU + 0.03 Laplacian + 0.0003 flatten.

use std::path::{Path, PathBuf};

use clap::Args;
use softvk::camera::Camera;
use softvk::fit::mesh_fit::{
    MeshFit, default_template, demo_target, fit_mesh, icosphere_template, normalize_template,
};
use softvk::fit::report::{self, GifWriter};
use softvk::fit::session::Progress;
use softvk::gpu::{Context, ContextOptions};
use softvk::io::{self, Silhouettes};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::{Alpha, Dist, RasterSettings};
use softvk::{Error, Result};

use crate::cli::args::{default_report, load_silhouette_views};
use crate::cli::output::AtomicFile;
use crate::cli::session::{LossPlot, Watch, curve, summary, write_loss_report};

mod args;
pub use args::*;

/// Runs a fit and writes the mesh and the report. `targets` are the silhouettes; the
/// `target_mesh`, when known (`demo`), turns beside the fitted one in the report.
// The inputs of `fit-mesh` and `demo` are each a caller's; bundling them would only move the
// count into a struct used once.
#[allow(clippy::too_many_arguments)]
fn fit_and_report(
    fit: &FitArgs,
    template: &Mesh,
    cams: &[Camera],
    sil: &Silhouettes,
    out: &Path,
    report_dir: &Path,
    default_iterations: u32,
    target_mesh: Option<&Mesh>,
) -> Result<()> {
    let opts = fit.options(sil.width, sil.height, default_iterations)?;
    let ctx = Context::new(&ContextOptions::from_env())?;
    // The checkpoint is checked before anything is written.
    let fingerprint = MeshFit::fingerprint(template, cams, &sil.masks, &opts);
    let session = fit.checkpoints.session(CHECKPOINT_FILE, fingerprint)?;
    std::fs::create_dir_all(report_dir)
        .map_err(|e| Error::Input(format!("cannot create {}: {e}", report_dir.display())))?;
    let views = sil.views();
    let columns = (views as f64).sqrt().ceil() as u32;
    let (w, h) = (sil.width, sil.height);
    let ones = vec![1.0f32; views];
    let sheet_size =
        report::contact_sheet(&sil.masks, &sil.masks, views, w, h, columns, Some(&ones))
            .dimensions();
    let mut gif = GifWriter::create(
        &report_dir.join("progress.gif"),
        sheet_size.0,
        sheet_size.1,
        120,
    )?;
    let watch = Watch::new(fit.quiet, u64::from(opts.iterations));
    let hooks = |p: &Progress<'_, '_, MeshFit<'_>>| {
        let ious = p.fitter.read_ious()?;
        let alphas = p.fitter.read_alphas()?;
        gif.push(&report::contact_sheet(
            &alphas,
            &sil.masks,
            views,
            w,
            h,
            columns,
            Some(&ious),
        ))?;
        let mean = ious.iter().sum::<f32>() / ious.len().max(1) as f32;
        let message = format!("loss {:.4}  soft IoU {mean:.4}", p.row().total);
        Ok(watch.update(p.last, message))
    };
    let result = fit_mesh(
        &ctx,
        template,
        cams,
        &sil.masks,
        &opts,
        session.hooks(hooks),
    )?;
    watch.finish();
    ctx.check_validation()?;

    // Final hard silhouettes of the fitted mesh, their IoUs and the contact sheet.
    let hard = RasterSettings {
        width: w,
        height: h,
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..RasterSettings::default()
    };
    let pred: Vec<f32> = Renderer::new(&ctx)?.render_silhouettes(
        &ctx,
        &result.mesh,
        cams,
        &hard,
        Method::default(),
    )?;
    let ious = softvk::fit::silhouette::hard_ious(&pred, &sil.masks, sil.pixels());
    let mut csv = String::from("view,name,iou\n");
    for (v, iou) in ious.iter().enumerate() {
        csv.push_str(&format!("{v},{},{iou}\n", sil.names[v]));
    }
    let mean = ious.iter().sum::<f32>() / views as f32;
    csv.push_str(&format!("mean,,{mean}\n"));
    AtomicFile::create(&report_dir.join("ious.csv"))?.commit(csv.as_bytes())?;
    report::write_png(
        &report_dir.join("contact_sheet.png"),
        &report::labelled_contact_sheet(
            &pred,
            &sil.masks,
            &ious,
            views,
            w,
            h,
            columns,
            SHEET_SCALE,
        ),
    )?;
    write_turntable(
        &ctx,
        &report_dir.join("turntable.gif"),
        &result.mesh,
        target_mesh,
        &cams[0],
    )?;
    let its = result.log.last().map_or(0, |l| l.iteration);
    let plot = LossPlot {
        series: vec![
            curve(&result.log, "total", "total", [0, 0, 0], 1.0),
            curve(&result.log, "silhouette", "1 - IoU", [220, 40, 40], 1.0),
            curve(&result.log, "laplacian", "laplacian", [40, 120, 220], 1.0),
        ],
        width: 800,
        height: 500,
        log_y: true,
    };
    write_loss_report(report_dir, &result.log, &plot, its, opts.iterations)?;
    gif.finish()?;
    io::write_obj(out, &result.mesh.positions, &result.mesh.faces)?;
    let what = format!("; mean IoU {mean:.4} over {views} views");
    let wrote = [out, report_dir];
    println!(
        "{}",
        summary(result.first_iteration, its, result.seconds, &what, &wrote)
    );
    Ok(())
}

/// Runs `softvk fit-mesh`.
pub fn run(args: &FitMeshArgs) -> Result<()> {
    let (sil, rows) = load_silhouette_views(&args.silhouettes, &args.cameras, args.size)?;
    args.fit.options(sil.width, sil.height, FIT_ITERATIONS)?;
    let template = match &args.template {
        Some(path) if path.as_os_str() == "icosphere" => icosphere_template(),
        Some(path) => normalize_template(Mesh::load_obj(path, 1)?),
        None => default_template(),
    };
    template.validate()?;
    let cams = args.fit.cameras(&rows);
    let report_dir = args
        .fit
        .report
        .clone()
        .unwrap_or_else(|| default_report(&args.out));
    fit_and_report(
        &args.fit,
        &template,
        &cams,
        &sil,
        &args.out,
        &report_dir,
        FIT_ITERATIONS,
        None,
    )
}

/// The checkpoint's file in `--checkpoint DIR` / `--resume DIR`.
pub const CHECKPOINT_FILE: &str = "mesh-fit.ckpt";

/// The final contact sheet's tiles, in view sizes.
const SHEET_SCALE: u32 = 3;

/// `turntable.gif`: `fitted` (and `target`, beside it) shaded under the default lighting from
/// 24 azimuths (every 15°) at elevation 20°, 192² each, at the distance and with the projection
/// of the fit's first camera `view`.
fn write_turntable(
    ctx: &Context,
    path: &Path,
    fitted: &Mesh,
    target: Option<&Mesh>,
    view: &Camera,
) -> Result<()> {
    const SIZE: u32 = 192;
    const FRAMES: u32 = 24;
    let settings = RasterSettings {
        width: SIZE,
        height: SIZE,
        sigma: 1e-5,
        gamma: 1e-4,
        ..RasterSettings::default()
    };
    let cams: Vec<Camera> = (0..FRAMES)
        .map(|i| Camera {
            projection: view.projection,
            ..Camera::from_angles(
                view.eye.length(),
                20.0,
                360.0 * f64::from(i) / f64::from(FRAMES),
            )
        })
        .collect();
    let renderer = Renderer::new(ctx)?;
    let lighting = Lighting::default();
    let mut meshes = vec![("fitted", fitted)];
    if let Some(t) = target {
        meshes.push(("target", t));
    }
    let renders = meshes
        .iter()
        .map(|(name, m)| {
            let frames =
                renderer.render_views(ctx, m, &cams, &lighting, &settings, Method::default())?;
            Ok((*name, frames.images))
        })
        .collect::<Result<Vec<_>>>()?;
    let px = (SIZE * SIZE) as usize;
    let frame = |i: usize| {
        let images: Vec<(&str, &[[f32; 4]])> = renders
            .iter()
            .map(|(name, images)| (*name, &images[i * px..(i + 1) * px]))
            .collect();
        report::side_by_side(&images, SIZE, SIZE)
    };
    let first = frame(0);
    let mut gif = GifWriter::create(path, first.width(), first.height(), 120)?;
    gif.push(&first)?;
    for i in 1..FRAMES as usize {
        gif.push(&frame(i))?;
    }
    gif.finish()
}

/// `fit-mesh`'s default iterations (SoftRas's demo).
const FIT_ITERATIONS: u32 = 2000;
/// The demo's default iterations: a few minutes on lavapipe (8 views at 64²: mean IoU 0.95
/// after 60).
const DEMO_ITERATIONS: u32 = 200;

/// The flags of `softvk demo`.
#[derive(Args, Clone, Debug)]
pub struct DemoArgs {
    /// Where everything goes.
    #[arg(long, value_name = "DIR", default_value = "softvk-demo")]
    pub out: PathBuf,

    /// Views of the generated target (elevation 30°, azimuths evenly spaced).
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub views: u32,

    /// Image size.
    #[arg(long, value_name = "N", default_value_t = 64)]
    pub size: u32,

    #[command(flatten)]
    pub fit: FitArgs,
}

/// Runs `softvk demo`: renders the generated target's silhouettes, writes them with their
/// cameras (so `fit-mesh` can be re-run on them), and fits the default sphere.
pub fn demo(args: &DemoArgs) -> Result<()> {
    if args.views == 0 || args.size == 0 || args.size > 4096 {
        return Err(Error::Input(
            "--views must be ≥ 1 and --size in 1..=4096".into(),
        ));
    }
    let dir = &args.out;
    let sil_dir = dir.join("silhouettes");
    std::fs::create_dir_all(&sil_dir)
        .map_err(|e| Error::Input(format!("cannot create {}: {e}", sil_dir.display())))?;
    let rows: Vec<io::CameraRow> = (0..args.views)
        .map(|i| io::CameraRow {
            distance: 2.732,
            elevation: 30.0,
            azimuth: 360.0 * f64::from(i) / f64::from(args.views),
        })
        .collect();
    let cams = args.fit.cameras(&rows);
    let target = demo_target();
    let ctx = Context::new(&ContextOptions::from_env())?;
    let hard = RasterSettings {
        width: args.size,
        height: args.size,
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..RasterSettings::default()
    };
    let masks: Vec<f32> =
        Renderer::new(&ctx)?.render_silhouettes(&ctx, &target, &cams, &hard, Method::default())?;
    drop(ctx);
    let names = io::silhouette_names(rows.len());
    io::write_silhouettes(&sil_dir, &names, args.size, args.size, &masks)?;
    io::write_cameras(&dir.join("cameras.csv"), &rows)?;
    io::write_obj(&dir.join("target.obj"), &target.positions, &target.faces)?;
    let sil = io::load_silhouettes(&sil_dir)?;
    let report_dir = args
        .fit
        .report
        .clone()
        .unwrap_or_else(|| dir.join("report"));
    fit_and_report(
        &args.fit,
        &default_template(),
        &cams,
        &sil,
        &dir.join("fitted.obj"),
        &report_dir,
        DEMO_ITERATIONS,
        Some(&target),
    )
}
