//! The fitting benchmarks of the fits (`fit-120`, `fit-field`, `fit-pose`; the trainers' are
//! [`super::recon`]'s), timed by [`super::iteration`]: one iteration per submission with its
//! passes, and the fit loop at 1 and 10 iterations per submission.

use std::path::Path;

use super::forward::per_pair_summary;
use super::iteration::{Shape, time_fit_iteration, time_fit_loop};
use super::scenes::{DISTANCE, load};
use super::{BenchOptions, BenchRecord, FIT_BATCH};
use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::gpu::Context;
use crate::raster::gpu::{Method, Renderer};
use crate::raster::settings::{Dist, RasterSettings, Rgb};

/// The sphere-probing benchmark (`softvk bench --scene fit-field`): a `softvk fit-field`
/// iteration at its defaults ([`FieldFitOptions::default`](crate::fit::field_fit::FieldFitOptions),
/// scaled to the cube) on the silhouettes of spot (`spot_triangulated.obj`) rendered hard at 64²
/// from 24 views (elevation 30°, azimuth every 15°, distance 2.732, viewing angle 15°: setup A
/// of RESULTS.md), in the cube [`auto_cube`](crate::fit::field_fit::auto_cube) gives.
///
/// After one untimed iteration, `opts.repeat` iterations run as the fit runs them, each in one
/// submission ([`FieldFitter::run`](crate::fit::field_fit::FieldFitter::run), with GPU
/// timestamps; a fit runs `log_every` of them per submission): `wall_ms` is the median wall
/// time of a whole iteration (recording, submission, the gate's status read), `gpu_ms` the
/// median of the sum of its top-level passes, and `passes` every pass (parts of a pass indented,
/// after it). `pairs` is 0 (not counted for probing); `entries` is the binning's (anchor, tile)
/// entry count of the last iteration.
pub(super) fn run_field_fit(
    ctx: &Context,
    opts: &BenchOptions,
    assets: &Path,
    progress: &mut impl FnMut(&str),
) -> Result<BenchRecord> {
    use crate::fit::field_fit::{FieldFit, FieldFitOptions, auto_cube, scaled_to_cube};
    use crate::probe::Targets;
    let name = "fit-field";
    let size = 64;
    let spot = load(assets, "spot_triangulated.obj", 1)?;
    let cameras: Vec<Camera> = (0..24)
        .map(|i| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(DISTANCE, 30.0, 15.0 * f64::from(i))
        })
        .collect();
    let hard = RasterSettings {
        width: size,
        height: size,
        dist: Dist::Hard,
        alpha: crate::raster::settings::Alpha::Hard,
        ..RasterSettings::default()
    };
    let masks: Vec<f32> =
        Renderer::new(ctx)?.render_silhouettes(ctx, &spot, &cameras, &hard, Method::default())?;
    let targets = Targets::new(&cameras, size, size, masks)?;
    let cube = auto_cube(&targets, crate::fit::field_fit::DEFAULT_CUBE_MARGIN)?;
    let defaults = FieldFitOptions::default();
    let fit_opts = FieldFitOptions {
        probe: scaled_to_cube(&defaults.probe, &cube),
        ..defaults
    };
    let mut fitter = FieldFit::fitter(ctx, &targets, &fit_opts)?;
    let s = fit_opts.probe;
    progress(&format!(
        "{name}: spot silhouettes, {} views of {size}x{size}, field {:?}, {} rays per view, {} \
         anchors, tau {:.4}, tile {}, cube centre {:?} half-edge {:.4}",
        cameras.len(),
        fit_opts.field,
        s.rays_per_view,
        s.anchors,
        s.tau,
        s.tile_size,
        cube.center,
        cube.half
    ));
    let shape = Shape {
        name,
        method: Method::Tiled { tile: s.tile_size },
        views: cameras.len() as u32,
        faces: spot.face_count() as u32,
        width: size,
        height: size,
        counts: None,
    };
    let mut it = 1u32;
    let timing = time_fit_iteration(ctx, opts, &mut fitter, &mut it, 24, false, progress, name)?;
    Ok(shape.record(
        ctx,
        "fit-iteration",
        timing,
        opts.repeat,
        fitter.last_entries(),
    ))
}

/// The pose-fitting benchmark (`softvk bench --scene fit-pose`): a `softvk fit-pose`
/// iteration at its defaults ([`PoseFitOptions::default`](crate::fit::pose::PoseFitOptions):
/// 48², σ/γ schedule, tile 8) fitting spot (`spot_triangulated.obj`, R = 5, SoftRas's default
/// lighting) seen from distance 2.732, elevation 20°, azimuth 30° to its own render at the rest
/// pose, from 20° off about an oblique axis.
///
/// After one untimed iteration, `opts.repeat` iterations run one per submission with GPU
/// timestamps (`fit-iteration`: medians, every pass), then [`FIT_BATCH`] iterations in one
/// submission (`fit-loop-k10`: wall and GPU time per iteration, and the host overhead).
pub(super) fn run_pose_fit(
    ctx: &Context,
    opts: &BenchOptions,
    assets: &Path,
    progress: &mut impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    use crate::fit::pose::{Pose, PoseFitOptions, PoseFitter};
    use crate::lighting::Lighting;
    let name = "fit-pose";
    let spot = load(assets, "spot_triangulated.obj", 5)?;
    let camera = Camera::from_angles(DISTANCE, 20.0, 30.0);
    let lighting = Lighting::default();
    let iterations = opts.repeat + FIT_BATCH + 1;
    let fit_opts = PoseFitOptions {
        iterations,
        ..PoseFitOptions::default()
    };
    let s = fit_opts.settings;
    let target = Renderer::new(ctx)?
        .render_views(ctx, &spot, &[camera], &lighting, &s, Method::default())?
        .images;
    let axis = glam::DVec3::new(1.0, 2.0, 0.5).normalize();
    let init = Pose {
        rotation: axis * 20f64.to_radians(),
        translation: glam::DVec3::ZERO,
    };
    let mut fitter = PoseFitter::new(ctx, &spot, &camera, &lighting, &target, &init, &fit_opts)?;
    progress(&format!(
        "{name}: spot (R = 5, {} faces) at {}x{}, sigma/gamma schedule over {iterations} \
         iterations, tile {}; entry capacity {}",
        spot.face_count(),
        s.width,
        s.height,
        fit_opts.tile,
        fitter.capacity()
    ));
    let shape = Shape {
        name,
        method: Method::Tiled {
            tile: fit_opts.tile,
        },
        views: 1,
        faces: spot.face_count() as u32,
        width: s.width,
        height: s.height,
        counts: None,
    };
    let mut it = 1u32;
    let timing = time_fit_iteration(ctx, opts, &mut fitter, &mut it, 32, false, progress, name)?;
    let mut records = vec![shape.record(
        ctx,
        "fit-iteration",
        timing,
        opts.repeat,
        fitter.last_entries(),
    )];
    let timing = time_fit_loop(
        ctx,
        &mut fitter,
        &mut it,
        FIT_BATCH,
        progress,
        name,
        "fit-loop-k10",
    )?;
    records.push(shape.record(
        ctx,
        "fit-loop-k10",
        timing,
        FIT_BATCH,
        fitter.last_entries(),
    ));
    Ok(records)
}

/// The `fit-120` records of [`run_fit`](super::run_fit): SoftRas's deformation demo setting,
/// the 1352-vertex sphere (`sphere_1352.obj` scaled by 0.5) fitted to the silhouettes of the
/// demo's generated target ([`crate::fit::mesh_fit::demo_target`]) from 120 views (elevation
/// 30°, azimuth every 3°, distance 2.732, viewing angle 15°) at 64², σ 1e-4, hard colour,
/// `1 − IoU + 0.03 Laplacian + 0.0003 flatten`, Adam (0.01, 0.5, 0.99), tile 8
/// ([`MeshFitOptions::default`](crate::fit::mesh_fit::MeshFitOptions)).
///
/// After one untimed iteration, `opts.repeat` iterations run one per submission with GPU
/// timestamps: record `fit-iteration` (medians; `passes` starts with the `render`, `backward`
/// and `rest` shares of [`fit_pass_share`], then every pass). Then the fit loop: [`FIT_BATCH`]
/// iterations one per submission (`fit-loop-k1`) and the next [`FIT_BATCH`] in one submission
/// (`fit-loop-k10`): wall and GPU time per iteration (means), and as its one pass the `host
/// overhead`, wall minus GPU (recording, submission, fence, the gate's status read).
/// The fit goes on from iteration to iteration (the shape changes a little), as a real fit
/// does; an iteration stopped by the gate (its entries outgrew the capacity) is re-run and not
/// counted.
pub(super) fn run_mesh_fit(
    ctx: &Context,
    opts: &BenchOptions,
    name: &'static str,
    progress: &mut impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    use crate::fit::mesh_fit::{MeshFitOptions, MeshFitter, default_template, demo_target};
    // SoftRas's template, as `softvk fit-mesh` uses it by default.
    let template = default_template();
    let fit_opts = MeshFitOptions {
        log_every: 1,
        ..MeshFitOptions::default()
    };
    let s = fit_opts.settings;
    let cameras: Vec<Camera> = (0..120)
        .map(|i| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(DISTANCE, 30.0, f64::from(3 * i))
        })
        .collect();
    let hard = RasterSettings {
        dist: Dist::Hard,
        alpha: crate::raster::settings::Alpha::Hard,
        rgb: Rgb::Hard,
        ..s
    };
    let targets: Vec<f32> = Renderer::new(ctx)?.render_silhouettes(
        ctx,
        &demo_target(),
        &cameras,
        &hard,
        Method::default(),
    )?;
    let mut fitter = MeshFitter::new(ctx, &template, &cameras, &targets, &fit_opts)?;
    let method = Method::Tiled {
        tile: fit_opts.tile,
    };
    progress(&format!(
        "{name}: sphere_1352 x0.5 ({} faces) fitted to the demo target's silhouettes, {} \
         views of {}x{}, sigma {:e}, rgb {:?}, tile {}; entry capacity {}",
        template.face_count(),
        cameras.len(),
        s.width,
        s.height,
        s.sigma,
        s.rgb,
        fit_opts.tile,
        fitter.capacity()
    ));
    let mut it = 1u32;
    let timing = time_fit_iteration(ctx, opts, &mut fitter, &mut it, 32, true, progress, name)?;
    let binned = fitter.binned()?;
    let counts = binned.pair_counts(ctx)?;
    progress(&format!(
        "{name} fit-iteration per pair:{}",
        per_pair_summary(&timing.passes, &counts)
    ));
    progress(&format!(
        "{name} alpha: {}",
        settled_summary(&binned.scene().read_frames(ctx)?.aux)
    ));
    let shape = Shape {
        name,
        method,
        views: cameras.len() as u32,
        faces: template.face_count() as u32,
        width: s.width,
        height: s.height,
        counts: Some(counts),
    };
    let mut records = vec![shape.record(
        ctx,
        "fit-iteration",
        timing,
        opts.repeat,
        fitter.last_entries(),
    )];
    // The loop, one and ten iterations per submission.
    for (pass, k) in [("fit-loop-k1", 1), ("fit-loop-k10", FIT_BATCH)] {
        let timing = time_fit_loop(ctx, &mut fitter, &mut it, k, progress, name, pass)?;
        records.push(shape.record(ctx, pass, timing, FIT_BATCH, fitter.last_entries()));
    }
    Ok(records)
}

/// How many rendered pixels ended with their alpha settled (SoftRas's product: two or more
/// factors `1 − D_j` exactly 0, or the product of the others 0 — every `∂A/∂D_j` is then exactly
/// zero), and how many with one factor exactly 0 (only that face's is not): what a backward that
/// skips such pixels, or such faces, could save.
fn settled_summary(aux: &[crate::raster::fine::PixelAux]) -> String {
    let settled = aux
        .iter()
        .filter(|a| a.alpha_zeros >= 2 || a.alpha_acc == 0.0)
        .count();
    let one = aux
        .iter()
        .filter(|a| a.alpha_zeros == 1 && a.alpha_acc != 0.0)
        .count();
    let covered = aux
        .iter()
        .filter(|a| a.alpha_zeros > 0 || a.alpha_acc < 1.0)
        .count();
    format!(
        "{} pixels, {covered} with some coverage; settled (every dA/dD_j exactly 0) {settled}, \
         one factor exactly 0 {one}",
        aux.len()
    )
}
