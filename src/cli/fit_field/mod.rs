//! `softvk fit-field --silhouettes DIR --cameras C.csv --out M.obj [--iters N] [field options]`
//! (SPEC §6): an implicit field fitted to silhouettes by sphere probing
//! ([`softvk::fit::field_fit`]), then its surface φ = 0.5 by marching cubes.
//!
//! Writes the mesh (OBJ) and a report folder (default: `<out>` without its extension +
//! `-report/`): `preview.png` (the field's surface shaded by ray marching, from the first
//! camera's direction), `compare.png` (the visual hull's surface beside the fitted one, both
//! rasterized by softvk from that camera), `loss.png` (L_sil against the iteration; with λ > 0
//! also λ L_geo and the sum) and `loss.csv` (the same numbers). Every input is checked before
//! anything is written, and the files are computed in memory first, so a failure writes
//! nothing.

use softvk::camera::{Camera, Projection};
use softvk::field::mcubes::{Isosurface, MarchingCubes};
use softvk::field::preview::{PreviewOptions, render_preview};
use softvk::field::voxel::visual_hull_surface;
use softvk::fit::field_fit::{
    FieldFit, FieldFitOptions, auto_cube, check_cameras_outside, fit_field, scaled_to_cube,
};
use softvk::fit::report;
use softvk::gpu::{Context, ContextOptions};
use softvk::lighting::Lighting;
use softvk::probe::Targets;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::RasterSettings;
use softvk::{Error, Result};

use crate::cli::args::{default_report, load_silhouette_views};
use crate::cli::session::{LossPlot, Watch, curve, summary, write_loss_report};
use softvk::fit::session::Progress;

mod args;
pub use args::*;

/// The checkpoint's file in `--checkpoint DIR` / `--resume DIR`.
pub const CHECKPOINT_FILE: &str = "field-fit.ckpt";

/// Runs `softvk fit-field`.
pub fn run(args: &FitFieldArgs) -> Result<()> {
    let (sil, rows) = load_silhouette_views(&args.silhouettes, &args.cameras, args.size)?;
    let unit = args.options()?;
    let cams = args.cameras(&rows);
    let targets = Targets::from_silhouettes(&cams, &sil)?;
    let cube = match args.cube {
        CubeArg::Given(c) => c,
        CubeArg::Auto => auto_cube(&targets, args.cube_margin)?,
    };
    check_cameras_outside(&targets, &cube)?;
    let opts = FieldFitOptions {
        probe: scaled_to_cube(&unit.probe, &cube),
        ..unit
    };
    opts.validate()?;
    let report_dir = args
        .report
        .clone()
        .unwrap_or_else(|| default_report(&args.out));
    // The checkpoint is checked before anything is written.
    let fingerprint = FieldFit::fingerprint(&targets, &opts);
    let session = args.checkpoints.session(CHECKPOINT_FILE, fingerprint)?;

    let ctx = Context::new(&ContextOptions::from_env())?;
    let watch = Watch::new(args.quiet, u64::from(opts.iterations));
    let hooks = |p: &Progress<'_, '_, FieldFit>| {
        let l = p.row();
        let message = format!(
            "loss {:.5} (L_sil {:.5}, L_geo {:.4})",
            l.total, l.silhouette, l.geo
        );
        Ok(watch.update(l.iteration, message))
    };
    let result = fit_field(&ctx, &targets, &opts, session.hooks(hooks))?;
    watch.finish();

    // Everything in memory first: an empty surface fails before any file is written.
    let iso = MarchingCubes::new(&ctx)?.extract(&ctx, &result.field, args.mc_res)?;
    if iso.is_empty() {
        return Err(Error::Input(format!(
            "the fitted field has no surface (φ never crosses 0.5 on the {}³ lattice); try more \
             --iters or another --lr",
            args.mc_res
        )));
    }
    let preview_cam = Camera {
        projection: Projection::Perspective {
            viewing_angle_deg: args.viewing_angle,
        },
        ..cams[0]
    };
    let preview = render_preview(
        &ctx,
        &result.field,
        &preview_cam,
        &PreviewOptions {
            width: args.preview_size,
            height: args.preview_size,
            ..PreviewOptions::default()
        },
    )?;
    // The fitted surface beside the silhouettes' visual hull, both shaded by softvk's rasterizer
    // from the preview's camera: what the fit rounded off or carved beyond the hull.
    let hull = visual_hull_surface(&sil, &cams, result.field.cube(), args.mc_res)?;
    let compare = surfaces_side_by_side(
        &ctx,
        &[("visual hull", &hull), ("fitted", &iso)],
        &preview_cam,
        args.preview_size,
    )?;
    ctx.check_validation()?;
    let lambda = opts.probe.geo_lambda;
    // Without the regularizer the total is L_sil: one curve.
    let log = &result.log;
    let series = if lambda > 0.0 {
        vec![
            curve(log, "total", "total", [0, 0, 0], 1.0),
            curve(log, "l_sil", "L_sil", [220, 40, 40], 1.0),
            curve(log, "l_geo", "lambda L_geo", [40, 120, 220], lambda),
        ]
    } else {
        vec![curve(log, "l_sil", "L_sil", [220, 40, 40], 1.0)]
    };
    let plot = LossPlot {
        series,
        width: 800,
        height: 500,
        log_y: true,
    };

    std::fs::create_dir_all(&report_dir)
        .map_err(|e| Error::Input(format!("cannot create {}: {e}", report_dir.display())))?;
    report::write_png(&report_dir.join("preview.png"), &preview)?;
    report::write_png(&report_dir.join("compare.png"), &compare)?;
    write_loss_report(&report_dir, log, &plot, result.iterations, opts.iterations)?;
    iso.write_obj(&args.out)?;
    let t = &result.timings;
    let what = format!(
        " on the cube centre ({:.4}, {:.4}, {:.4}) half-edge {:.4}; final L_sil {:.5}; {} \
         vertices, {} faces",
        cube.center[0],
        cube.center[1],
        cube.center[2],
        cube.half,
        log.last().map_or(f32::NAN, |l| l.silhouette),
        iso.positions.len(),
        iso.faces.len(),
    );
    let wrote = [args.out.as_path(), &report_dir];
    let (first, done) = (result.first_iteration, result.iterations);
    println!("{}", summary(first, done, t.iterations_s, &what, &wrote));
    Ok(())
}

/// Surfaces rendered side by side (`size`² each, lit white, SoftRas's sharp σ) under their
/// names; an empty surface leaves its panel black.
fn surfaces_side_by_side(
    ctx: &Context,
    surfaces: &[(&str, &Isosurface)],
    camera: &Camera,
    size: u32,
) -> Result<image::RgbaImage> {
    let renderer = Renderer::new(ctx)?;
    let settings = RasterSettings {
        width: size,
        height: size,
        ..RasterSettings::default()
    };
    let images = surfaces
        .iter()
        .map(|(_, iso)| {
            if iso.is_empty() {
                return Ok(vec![[0.0; 4]; (size * size) as usize]);
            }
            let frames = renderer.render_views(
                ctx,
                &iso.to_mesh()?,
                std::slice::from_ref(camera),
                &Lighting::default(),
                &settings,
                Method::default(),
            )?;
            Ok(frames.images)
        })
        .collect::<Result<Vec<_>>>()?;
    let named: Vec<(&str, &[[f32; 4]])> = surfaces
        .iter()
        .zip(&images)
        .map(|((name, _), img)| (*name, img.as_slice()))
        .collect();
    Ok(report::side_by_side(&named, size, size))
}
