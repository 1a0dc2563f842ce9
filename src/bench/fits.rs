//! Fitting iterations per scene kind (`fit-120`, `fit-field`, `fit-pose`; `train-recon` in
//! [`super::recon`]): one iteration per
//! submission with its passes, and the fit loop at 1 and 10 iterations per submission.

use std::path::Path;
use std::time::Instant;

use super::forward::{Timing, per_pair_summary, summary};
use super::scenes::{DISTANCE, load};
use super::{BenchOptions, BenchRecord, FIT_BATCH};
use crate::camera::{Camera, Projection};
use crate::error::Result;
use crate::fit::driver::{Fit, Fitter};
use crate::gpu::{Context, PassTime, Timer};
use crate::raster::gpu::{Method, PairCounts, Renderer};
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
fn run_field_fit(
    ctx: &Context,
    opts: &BenchOptions,
    assets: &Path,
    progress: &mut impl FnMut(&str),
) -> Result<BenchRecord> {
    use crate::fit::field_fit::{FieldFitOptions, FieldFitter, auto_cube, scaled_to_cube};
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
    let mut fitter = FieldFitter::new(ctx, &targets, &fit_opts)?;
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
fn run_pose_fit(
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

/// The fit loop: [`FIT_BATCH`] iterations of `fitter`, `k` per submission, from `it`. Wall and
/// GPU time per iteration (means), and as the one pass the `host overhead`, wall minus GPU
/// (recording, submission, fence, the gate's status read), which is what batching cuts; on a
/// shared CPU device the GPU time itself moves with the load. Says so through `progress`.
fn time_fit_loop(
    ctx: &Context,
    fitter: &mut Fitter<'_, impl Fit>,
    it: &mut u32,
    k: u32,
    progress: &mut impl FnMut(&str),
    name: &str,
    pass: &str,
) -> Result<Timing> {
    let mut timer = if ctx.info().timestamp_valid_bits > 0 {
        Some(Timer::new(ctx, 20 * FIT_BATCH)?)
    } else {
        None
    };
    let (mut wall, mut gpu) = (0.0, 0.0);
    for _ in 0..FIT_BATCH / k {
        wall += fit_iterations(fitter, it, k, timer.as_mut(), progress, name)?;
        if let Some(timer) = &timer {
            gpu += timer.total_ms(ctx)?;
        }
    }
    let n = f64::from(FIT_BATCH);
    let gpu_ms = timer.is_some().then_some(gpu / n);
    let host = gpu_ms.map(|g| wall / n - g);
    progress(&format!(
        "{name} {pass}: {:.1} ms wall per iteration over {FIT_BATCH} iterations, {k} per \
         submission; gpu {}, host overhead {} per iteration",
        wall / n,
        gpu_ms.map_or("n/a".into(), |g| format!("{g:.1} ms")),
        host.map_or("n/a".into(), |h| format!("{h:.2} ms")),
    ));
    let passes = host
        .map(|h| vec![("host overhead".to_string(), h)])
        .unwrap_or_default();
    Ok(Timing {
        gpu_ms,
        wall_ms: wall / n,
        passes,
    })
}

/// What a fitting benchmark's records say of its iterations besides the times.
pub(super) struct Shape {
    pub(super) name: &'static str,
    pub(super) method: Method,
    /// Renders (mesh) or probed views (field) an iteration.
    pub(super) views: u32,
    /// Faces a render (0: no mesh).
    pub(super) faces: u32,
    pub(super) width: u32,
    pub(super) height: u32,
    /// The fine kernels' pairs of the fit's scene, where counted (the records' `pairs` is
    /// their binned count, else 0).
    pub(super) counts: Option<PairCounts>,
}

impl Shape {
    /// The record of `pass`: `timing` over `repeats` iterations, `entries` binned by the last.
    pub(super) fn record(
        &self,
        ctx: &Context,
        pass: &'static str,
        timing: Timing,
        repeats: u32,
        entries: u64,
    ) -> BenchRecord {
        BenchRecord {
            scene: self.name.to_string(),
            method: self.method,
            pass,
            gpu_ms: timing.gpu_ms,
            wall_ms: timing.wall_ms,
            pairs: self.counts.map_or(0, |c| c.binned),
            counts: self.counts,
            device: ctx.info().name.clone(),
            driver: ctx.info().driver.clone(),
            repeats,
            passes: timing.passes,
            views: self.views,
            faces: self.faces,
            width: self.width,
            height: self.height,
            rows: None,
            entries: Some(entries),
            identical_to_brute: None,
        }
    }
}

/// One untimed iteration of `fitter` from `*it`, then `opts.repeat` timed ones
/// ([`time_iterations`], with room for `timer_passes` passes and, with `shares`, the shares
/// first); says their summary through `progress` and leaves `it` after them.
#[allow(clippy::too_many_arguments)]
pub(super) fn time_fit_iteration(
    ctx: &Context,
    opts: &BenchOptions,
    fitter: &mut Fitter<'_, impl Fit>,
    it: &mut u32,
    timer_passes: u32,
    shares: bool,
    progress: &mut impl FnMut(&str),
    name: &str,
) -> Result<Timing> {
    fit_iterations(fitter, it, 1, None, progress, name)?;
    let timing = time_iterations(
        ctx,
        fitter,
        it,
        opts.repeat,
        timer_passes,
        shares,
        progress,
        name,
    )?;
    progress(&format!(
        "{name} fit-iteration: {} entries; {}",
        fitter.last_entries(),
        summary(&timing, opts.repeat)
    ));
    Ok(timing)
}

/// `repeat` iterations of `fitter` from `*it`, one per submission, with GPU timestamps (room for
/// `timer_passes` passes): per iteration the wall time, the GPU time (the top-level passes: a
/// nested pass, listed indented after its parent, is part of its parent's time) and every pass;
/// with `shares`, the `render`, `backward` and `rest` sums of [`fit_pass_share`] over the
/// top-level passes first. Medians.
#[allow(clippy::too_many_arguments)]
fn time_iterations(
    ctx: &Context,
    fitter: &mut Fitter<'_, impl Fit>,
    it: &mut u32,
    repeat: u32,
    timer_passes: u32,
    shares: bool,
    progress: &mut impl FnMut(&str),
    name: &str,
) -> Result<Timing> {
    let mut timer = if ctx.info().timestamp_valid_bits > 0 {
        Some(Timer::new(ctx, timer_passes)?)
    } else {
        None
    };
    let (mut wall, mut gpu) = (Vec::new(), Vec::new());
    let mut passes: Vec<(String, Vec<f64>)> = Vec::new();
    for _ in 0..repeat {
        wall.push(fit_iterations(
            fitter,
            it,
            1,
            timer.as_mut(),
            progress,
            name,
        )?);
        let Some(timer) = &timer else { continue };
        let times = timer.results(ctx)?;
        gpu.push(PassTime::top_level_ms(&times));
        let mut row: Vec<(String, f64)> = Vec::new();
        if shares {
            row.extend(["render", "backward", "rest"].iter().map(|share| {
                let ms = times
                    .iter()
                    .filter(|t| t.depth == 0 && fit_pass_share(&t.name) == *share)
                    .map(|t| t.ms)
                    .sum();
                (share.to_string(), ms)
            }));
        }
        row.extend(times.iter().map(|t| (t.indented(), t.ms)));
        if passes.is_empty() {
            passes = row.iter().map(|(n, _)| (n.clone(), Vec::new())).collect();
        }
        // Every iteration records the same passes in the same order.
        for ((_, series), (_, ms)) in passes.iter_mut().zip(&row) {
            series.push(*ms);
        }
    }
    Ok(Timing::medians(&gpu, &wall, &passes))
}

/// Runs iterations `it .. it + k` of `fitter` in one submission (again from a stopped one, until
/// all ran) and advances `it`; the wall time of the submission that ran them all, ms.
fn fit_iterations(
    fitter: &mut Fitter<'_, impl Fit>,
    it: &mut u32,
    k: u32,
    mut timer: Option<&mut Timer>,
    progress: &mut impl FnMut(&str),
    name: &str,
) -> Result<f64> {
    loop {
        let start = Instant::now();
        let stopped = fitter.run(*it, *it + k - 1, timer.as_deref_mut())?;
        let wall = start.elapsed().as_secs_f64() * 1e3;
        match stopped {
            None => {
                *it += k;
                return Ok(wall);
            }
            Some(again) => {
                progress(&format!(
                    "{name}: iteration {again} outgrew the entry capacity; now {} (re-run, not \
                     timed)",
                    Fit::capacity(&**fitter)
                ));
                *it = again;
            }
        }
    }
}

/// Which share of a fitting iteration a timed pass belongs to: `render` (face setup and the
/// binning's count, sort and fine pass), `backward` (the grad passes) or `rest` (deformation,
/// gate, loss, regularizers, deformation backward, Adam).
pub fn fit_pass_share(pass: &str) -> &'static str {
    match pass {
        "face setup" | "bin count" | "bin sort" | "raster tiled" | "downsample 2x2" => "render",
        _ if pass.starts_with("grad ") => "backward",
        _ => "rest",
    }
}

/// The fitting benchmark (`softvk bench --scene fit-120`): SoftRas's deformation demo setting,
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
pub fn run_fit(
    ctx: &Context,
    opts: &BenchOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    let assets = opts.assets.clone().unwrap_or_else(crate::assets::dir);
    let mut records = Vec::new();
    for name in opts.checked_fit_scenes()? {
        match name {
            "fit-field" => records.push(run_field_fit(ctx, opts, &assets, &mut progress)?),
            "fit-pose" => records.extend(run_pose_fit(ctx, opts, &assets, &mut progress)?),
            "train-recon" => records.push(super::recon::run_recon_train(ctx, opts, &mut progress)?),
            "train-recon-field" => records.push(super::recon::run_field_recon_train(
                ctx,
                opts,
                &mut progress,
            )?),
            // `fit-120`, the one left of FIT_SCENES.
            _ => records.extend(run_mesh_fit(ctx, opts, name, &mut progress)?),
        }
    }
    Ok(records)
}

/// The `fit-120` records of [`run_fit`].
fn run_mesh_fit(
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
    let counts = fitter.binned()?.pair_counts(ctx)?;
    progress(&format!(
        "{name} fit-iteration per pair:{}",
        per_pair_summary(&timing.passes, &counts)
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
