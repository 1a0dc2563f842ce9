//! The soft rasterizer's forward on the cheap `softvk bench` scenes (spot-256, sphere-64x120,
//! blurry-256): tiled at the default tile size against brute force. Each case is recorded once
//! ([`Renderer::record_forward`]); an iteration is one submit + wait of the whole forward. Two
//! series per case, `wall` (submit to fence, host clock) and `gpu` (sum of the passes' GPU
//! timestamps), with output pixels per second as the throughput.
//!
//! Run: `cargo bench --bench forward` (device from `SOFTVK_DEVICE`, meshes from `SOFTVK_ASSETS`).
//! `softvk bench` times every tile size and dense-1024 too, and checks the images.

use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use softvk::bench::Scene;
use softvk::gpu::{Context, ContextOptions, Recorded, Timer};
use softvk::raster::gpu::{DEFAULT_TILE, Method, Renderer};

fn context() -> Context {
    Context::new(&ContextOptions::from_env()).expect("benchmarks need a Vulkan device")
}

/// Times `recorded` both ways for criterion's `iters`.
fn time(
    recorded: &Recorded<'_>,
    timer: &Timer,
    ctx: &Context,
    gpu_clock: bool,
    iters: u64,
) -> Duration {
    let mut total = Duration::ZERO;
    for _ in 0..iters {
        let start = Instant::now();
        recorded.submit_and_wait().expect("submit");
        let wall = start.elapsed();
        total += if gpu_clock {
            let ms = timer.total_ms(ctx).expect("timestamps");
            Duration::from_secs_f64(ms * 1e-3)
        } else {
            wall
        };
    }
    total
}

fn forward(c: &mut Criterion) {
    let ctx = context();
    let renderer = Renderer::new(&ctx).unwrap();
    let assets = softvk::assets::dir();
    for name in ["spot-256", "sphere-64x120", "blurry-256"] {
        let scene = Scene::load(name, &assets).unwrap();
        let mut gpu = renderer
            .prepare(
                &ctx,
                &scene.mesh,
                &scene.cameras,
                &scene.lighting,
                &scene.settings,
            )
            .unwrap();
        let tiled = Method::Tiled { tile: DEFAULT_TILE };
        // Sizes the bins for the recording (record_forward re-bins into them on every submit).
        renderer.run(&ctx, &mut gpu, tiled).unwrap();
        let mut group = c.benchmark_group(format!("forward/{name}/{}", ctx.info().name));
        group
            .sample_size(10)
            .measurement_time(Duration::from_secs(5));
        let s = &scene.settings;
        group.throughput(Throughput::Elements(
            u64::from(s.width) * u64::from(s.height) * scene.cameras.len() as u64,
        ));
        for (label, method) in [
            (format!("tiled {DEFAULT_TILE}"), tiled),
            ("brute".into(), Method::Brute),
        ] {
            let mut timer = Timer::new(&ctx, 8).unwrap();
            let recorded = ctx
                .record(Some(&mut timer), |rec| {
                    renderer.record_forward(rec, &gpu, method).map(|_| ())
                })
                .unwrap();
            for (clock, gpu_clock) in [("wall", false), ("gpu", true)] {
                group.bench_function(BenchmarkId::new(clock, &label), |b| {
                    b.iter_custom(|iters| time(&recorded, &timer, &ctx, gpu_clock, iters))
                });
            }
        }
        group.finish();
    }
}

criterion_group!(benches, forward);
criterion_main!(benches);
