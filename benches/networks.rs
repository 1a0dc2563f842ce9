//! The networks' kernels: the MLP field's evaluation and backward per point (`mlp/...`), and the
//! reconstruction network's forward and backward at batch 16 (`nn/...`). Each case is recorded
//! once; an iteration is one submit + wait. Two series per case, as in `primitives.rs`: `wall`
//! (submit to fence, host clock) and `gpu` (GPU timestamps around the work); the MLP's
//! throughput is points per second (ns per point: 1e9 / the rate).
//!
//! Run: `cargo bench --bench networks` (device from `SOFTVK_DEVICE`), or one case with a filter:
//! `cargo bench --bench networks -- "mlp/3x32 f3"`, `cargo bench --bench networks -- nn/`.
//! Before timing, each case prints to stderr what identifies its results (the MLP's checksum
//! Σ|dL/dθ|, the same on every binary that computes the same bits) or its parts (the network's
//! GPU time per layer, one submission).
//!
//! - MLP shapes (hidden layers × width, frequencies): 3 × 32, 3 (`recon::field`'s default);
//!   2 × 32, 3; 4 × 64, 4 (`field_study field=mlp`'s); 4 × 64, 3. 32 768 points spread through
//!   the cube, dL/dφ a wave.
//! - The network: `NetShape::default()`, the one `softvk train-recon` trains, with its mesh head
//!   and colour generator (SoftRas §4.2's encoder and decoder: conv 4→16, 16→32, 32→64, kernel
//!   5, stride 2, padding 2, 64² → 8²; linear 4096→256→256, then 256→512→9113).
//!
//! Whole workloads (render scenes, fits, training iterations) are `softvk bench`'s.

mod common;

use std::time::Duration;

use common::{context, time};
use criterion::{
    BenchmarkId, Criterion, SamplingMode, Throughput, criterion_group, criterion_main,
};
use softvk::field::{Cube, Field, FieldKind};
use softvk::gpu::{MemoryKind, Timer};
use softvk::nn::Sequential;
use softvk::recon::NetShape;

/// Points per MLP case.
const POINTS: u32 = 32_768;

/// (hidden layers, width, frequencies) of the MLP cases.
const MLP_SHAPES: [(u32, u32, u32); 4] = [(3, 32, 3), (2, 32, 3), (4, 64, 4), (4, 64, 3)];

fn mlp(c: &mut Criterion) {
    let ctx = context();
    let cube = Cube {
        center: [0.0; 3],
        half: 1.0,
    };
    // Points spread through the cube (a fixed low-discrepancy walk), dL/dφ a wave.
    let pts: Vec<[f32; 4]> = (0..POINTS)
        .map(|i| {
            let t = i as f32;
            [
                (t * 0.618_034).fract() * 2.0 - 1.0,
                (t * 0.754_877_7).fract() * 2.0 - 1.0,
                (t * 0.569_840_3).fract() * 2.0 - 1.0,
                1.0,
            ]
        })
        .collect();
    let d: Vec<f32> = (0..POINTS).map(|i| (i as f32 * 0.37).sin()).collect();
    let pts = ctx.upload_buffer("points", &pts).unwrap();
    let d_phi = ctx.upload_buffer("d_phi", &d).unwrap();
    let phi = ctx
        .create_buffer("phi", 4 * u64::from(POINTS), MemoryKind::Device)
        .unwrap();
    for (layers, width, freqs) in MLP_SHAPES {
        let kind = FieldKind::Mlp {
            hidden_layers: layers,
            width,
            frequencies: freqs,
        };
        let field = Field::new(&ctx, kind, cube, 7).unwrap();
        let d_params = ctx
            .create_buffer(
                "d_params",
                4 * field.param_count() as u64,
                MemoryKind::Device,
            )
            .unwrap();
        let mut eval_timer = Timer::new(&ctx, 16).unwrap();
        let mut backward_timer = Timer::new(&ctx, 16).unwrap();
        let eval = ctx
            .record(Some(&mut eval_timer), |rec| {
                rec.pass("eval", |rec| {
                    field.record_eval(rec, pts.whole(), POINTS, phi.whole())
                })
            })
            .unwrap();
        let backward = ctx
            .record(Some(&mut backward_timer), |rec| {
                rec.pass("backward", |rec| {
                    field.record_backward(rec, pts.whole(), POINTS, d_phi.whole(), d_params.whole())
                })
            })
            .unwrap();
        backward.submit_and_wait().unwrap();
        let checksum: f64 = ctx
            .read_buffer::<f32>(&d_params, 0, field.param_count())
            .unwrap()
            .iter()
            .map(|&x| f64::from(x).abs())
            .sum();
        let label = format!("{layers}x{width} f{freqs}");
        eprintln!(
            "mlp {label}: {} parameters, {POINTS} points; checksum Σ|dL/dθ| {checksum:.6e}",
            field.param_count()
        );
        let mut group = c.benchmark_group(format!("mlp/{label}/{}", ctx.info().name));
        // The larger networks' backward takes about a second per submission on lavapipe.
        group
            .sample_size(10)
            .sampling_mode(SamplingMode::Flat)
            .measurement_time(Duration::from_secs(5))
            .throughput(Throughput::Elements(u64::from(POINTS)));
        for (name, recorded, timer) in [
            ("eval", &eval, &eval_timer),
            ("backward", &backward, &backward_timer),
        ] {
            for (clock, gpu_clock) in [("wall", false), ("gpu", true)] {
                group.bench_function(BenchmarkId::new(clock, name), |b| {
                    b.iter_custom(|iters| time(recorded, timer, &ctx, gpu_clock, iters))
                });
            }
        }
        group.finish();
    }
}

/// Samples per network case.
const BATCH: u32 = 16;

fn nn(c: &mut Criterion) {
    let ctx = context();
    let shape = NetShape::default();
    let layers = shape
        .layers(softvk::recon::train::head_outputs(&shape))
        .unwrap();
    let net = Sequential::new(&ctx, &layers, BATCH).unwrap();
    let params = ctx.upload_buffer("params", &net.init(1)).unwrap();
    let n_in = (u64::from(BATCH) * net.input_len()) as usize;
    let n_out = (u64::from(BATCH) * net.output_len()) as usize;
    let wave = |n: usize, f: f32| (0..n).map(|i| (i as f32 * f).sin()).collect::<Vec<f32>>();
    let input = ctx.upload_buffer("input", &wave(n_in, 0.37)).unwrap();
    let d_output = ctx.upload_buffer("d_output", &wave(n_out, 0.11)).unwrap();
    let d_params = ctx
        .create_buffer("d_params", 4 * net.param_count(), MemoryKind::Device)
        .unwrap();
    let mut forward_timer = Timer::new(&ctx, 128).unwrap();
    let mut backward_timer = Timer::new(&ctx, 128).unwrap();
    let forward = ctx
        .record(Some(&mut forward_timer), |rec| {
            rec.pass("forward", |rec| {
                net.record_forward(rec, params.whole(), input.whole(), BATCH)
            })
        })
        .unwrap();
    let backward = ctx
        .record(Some(&mut backward_timer), |rec| {
            rec.pass("backward", |rec| {
                net.record_backward(
                    rec,
                    params.whole(),
                    input.whole(),
                    d_output.whole(),
                    d_params.whole(),
                    None,
                    BATCH,
                )
            })
        })
        .unwrap();
    eprintln!(
        "nn: the reconstruction network, {} parameters, batch {BATCH}",
        net.param_count()
    );
    let mut group = c.benchmark_group(format!("nn/{}", ctx.info().name));
    group
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .measurement_time(Duration::from_secs(5));
    for (name, recorded, timer) in [
        ("forward", &forward, &forward_timer),
        ("backward", &backward, &backward_timer),
    ] {
        // The parts of one submission (after a warm-up), GPU ms per layer.
        recorded.submit_and_wait().unwrap();
        recorded.submit_and_wait().unwrap();
        for pass in timer.results(&ctx).unwrap() {
            eprintln!("  {:<24} {:8.2} ms GPU", pass.indented(), pass.ms);
        }
        for (clock, gpu_clock) in [("wall", false), ("gpu", true)] {
            group.bench_function(BenchmarkId::new(clock, name), |b| {
                b.iter_custom(|iters| time(recorded, timer, &ctx, gpu_clock, iters))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, mlp, nn);
criterion_main!(benches);
