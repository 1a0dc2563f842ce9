//! Timing a fit's iterations, for every fitting benchmark ([`super::fits`] and
//! [`super::recon`]): one untimed iteration then timed ones, one per submission with their
//! passes ([`time_fit_iteration`]); the fit loop at 1 and [`FIT_BATCH`] iterations per
//! submission ([`time_fit_loop`]); and the record of a fitting scene's [`Shape`].

use std::time::Instant;

use super::forward::{Timing, summary};
use super::{BenchOptions, BenchRecord, FIT_BATCH};
use crate::error::Result;
use crate::fit::driver::{Fit, Fitter};
use crate::gpu::{Context, PassTime, Timer};
use crate::raster::gpu::{Method, PairCounts};

/// The fit loop: [`FIT_BATCH`] iterations of `fitter`, `k` per submission, from `it`. Wall and
/// GPU time per iteration (means), and as the one pass the `host overhead`, wall minus GPU
/// (recording, submission, fence, the gate's status read), which is what batching cuts; on a
/// shared CPU device the GPU time itself moves with the load. Says so through `progress`.
pub(super) fn time_fit_loop(
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
