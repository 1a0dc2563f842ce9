//! The backward pass per scene (`softvk bench --backward`).

use super::forward::{Samples, per_pair_summary, summary};
use super::{BenchOptions, BenchRecord, Scene};
use crate::error::{Error, Result};
use crate::gpu::{Context, Timer};
use crate::raster::gpu::{Method, Renderer};

/// The backward benchmark: per scene of `opts` and method (brute force, each tile
/// size), the backward alone (`pass: "backward"`: per-face gradients, world chain, per-vertex
/// and per-texel sums; recorded once after a forward sized the bins) and forward + backward in
/// one recording (`"forward+backward"`), medians over `opts.repeat` submissions. The upstream
/// gradient is a fixed pattern over RGBA. A method the device cannot run (brute force past
/// llvmpipe's loop cap) is reported and skipped.
pub fn run_backward(
    ctx: &Context,
    opts: &BenchOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    use crate::raster::backward::GradBuffers;
    let names = opts.checked_scenes()?;
    let assets = opts.assets.clone().unwrap_or_else(crate::assets::dir);
    let renderer = Renderer::new(ctx)?;
    let mut records = Vec::new();
    for name in names {
        let mut scene = Scene::load(name, &assets)?;
        if let Some(rows) = opts.band {
            scene = scene.band(rows)?;
        }
        progress(&format!("{} (backward)", scene.description));
        let s = &scene.settings;
        let n = (s.width * s.height) as usize * scene.cameras.len();
        let d_image: Vec<[f32; 4]> = (0..n)
            .map(|i| {
                let t = i as f32 * 0.618_034;
                [t.sin(), (1.3 * t).cos(), (0.7 * t).sin(), (2.1 * t).cos()]
            })
            .collect();
        let mut methods: Vec<(Method, u32)> = opts
            .tiles
            .iter()
            .map(|&tile| (Method::Tiled { tile }, opts.repeat))
            .collect();
        if opts.brute {
            methods.insert(0, (Method::Brute, opts.brute_repeat.unwrap_or(opts.repeat)));
        }
        for (method, repeats) in methods {
            let label = match method {
                Method::Brute => "brute".to_string(),
                Method::Tiled { tile } => format!("tiled {tile}"),
            };
            let mut gpu = renderer.prepare(
                ctx,
                &scene.mesh,
                &scene.cameras,
                &scene.lighting,
                &scene.settings,
            )?;
            let prepared = renderer.run(ctx, &mut gpu, method).and_then(|run| {
                let gb = GradBuffers::new(ctx, &run.binned())?;
                gb.set_d_image(ctx, run.binned().scene(), &d_image)?;
                // A first, untimed backward: it also tells whether the device can run it.
                renderer.backward(ctx, &run.binned(), &d_image, false)?;
                Ok((run, gb))
            });
            let (run, gb) = match prepared {
                Ok(prepared) => prepared,
                Err(Error::Limit(why)) => {
                    progress(&format!("{} {label}: skipped: {why}", scene.name));
                    continue;
                }
                Err(e) => return Err(e),
            };
            let binned = run.binned();
            let gpu = binned.scene();
            let counts = binned.pair_counts(ctx)?;
            let entries = match method {
                Method::Tiled { .. } => Some(binned.entries()),
                Method::Brute => None,
            };
            for pass in ["backward", "forward+backward"] {
                let mut timer = if ctx.info().timestamp_valid_bits > 0 {
                    Some(Timer::new(ctx, 16 + 3 * binned.groups().len() as u32)?)
                } else {
                    None
                };
                let recorded = ctx.record(timer.as_mut(), |rec| {
                    let binned = if pass == "forward+backward" {
                        renderer.record_forward(rec, &run)?
                    } else {
                        binned
                    };
                    renderer.grad_kernels().record(rec, &binned, &gb, &gb.io())
                })?;
                let mut samples = Samples::default();
                for _ in 0..repeats {
                    samples.take(ctx, &recorded, timer.as_ref())?;
                }
                drop(recorded);
                let t = samples.timing();
                progress(&format!(
                    "{} {label} {pass}: {}{}",
                    scene.name,
                    summary(&t, repeats),
                    per_pair_summary(&t.passes, &counts)
                ));
                records.push(BenchRecord {
                    scene: scene.name.clone(),
                    method,
                    pass: if pass == "backward" {
                        "backward"
                    } else {
                        "forward+backward"
                    },
                    gpu_ms: t.gpu_ms,
                    wall_ms: t.wall_ms,
                    pairs: counts.binned,
                    counts: Some(counts),
                    device: ctx.info().name.clone(),
                    driver: ctx.info().driver.clone(),
                    repeats,
                    passes: t.passes,
                    views: gpu.view_count(),
                    faces: gpu.face_count(),
                    width: scene.settings.width,
                    height: scene.settings.height,
                    rows: scene.rows,
                    entries,
                    identical_to_brute: None,
                });
            }
        }
    }
    Ok(records)
}
