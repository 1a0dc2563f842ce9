//! Times the forward and the backward of the reconstruction network's size (SoftRas §4.2's
//! encoder and decoder) at batch 16: conv 4→16, 16→32, 32→64 (kernel 5, stride 2, padding 2,
//! 64² → 8²), linear 4096→256→256, then 256→512→9113 (3·642 + 3 for the mesh head, 8 · (256 +
//! 642) for the colour generator): `NetShape::default()`. Each is recorded once and only
//! submit + wait is timed (wall clock), with GPU timestamps per layer beside it.
//!
//! Run: `cargo run --release --example nn_speed [-- REPEATS]`.

use softvk::gpu::{Context, ContextOptions, MemoryKind, Timer};
use softvk::nn::Sequential;
use softvk::recon::NetShape;

const BATCH: u32 = 16;

fn main() -> softvk::Result<()> {
    let repeats: u32 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(5);
    let ctx = Context::new(&ContextOptions::from_env())?;
    // The network `softvk train-recon` trains by default, with its mesh head and colour
    // generator.
    let shape = NetShape::default();
    let layers = shape.layers(softvk::recon::train::head_outputs(&shape))?;
    let net = Sequential::new(&ctx, &layers, BATCH)?;
    let params = ctx.upload_buffer("params", &net.init(1))?;
    let n_in = (u64::from(BATCH) * net.input_len()) as usize;
    let n_out = (u64::from(BATCH) * net.output_len()) as usize;
    let wave = |n: usize, f: f32| (0..n).map(|i| (i as f32 * f).sin()).collect::<Vec<f32>>();
    let input = ctx.upload_buffer("input", &wave(n_in, 0.37))?;
    let d_output = ctx.upload_buffer("d_output", &wave(n_out, 0.11))?;
    let d_params = ctx.create_buffer("d_params", 4 * net.param_count(), MemoryKind::Device)?;
    println!(
        "{} on {}: {} parameters, batch {BATCH}",
        env!("CARGO_PKG_NAME"),
        ctx.info().name,
        net.param_count()
    );

    let mut forward_timer = Timer::new(&ctx, 64)?;
    let mut backward_timer = Timer::new(&ctx, 64)?;
    let forward = ctx.record(Some(&mut forward_timer), |rec| {
        net.record_forward(rec, params.whole(), input.whole(), BATCH)
    })?;
    let backward = ctx.record(Some(&mut backward_timer), |rec| {
        net.record_backward(
            rec,
            params.whole(),
            input.whole(),
            d_output.whole(),
            d_params.whole(),
            None,
            BATCH,
        )
    })?;
    for (name, recorded, timer) in [
        ("forward", &forward, &forward_timer),
        ("backward", &backward, &backward_timer),
    ] {
        recorded.submit_and_wait()?; // warm-up
        let mut wall = Vec::new();
        for _ in 0..repeats {
            let t = std::time::Instant::now();
            recorded.submit_and_wait()?;
            wall.push(t.elapsed().as_secs_f64() * 1e3);
        }
        wall.sort_by(f64::total_cmp);
        println!(
            "{name}: median {:.1} ms wall (min {:.1}, max {:.1}, {repeats} runs)",
            wall[wall.len() / 2],
            wall[0],
            wall[wall.len() - 1]
        );
        for pass in timer.results(&ctx)? {
            println!("  {:<24} {:8.2} ms GPU", pass.indented(), pass.ms);
        }
    }
    Ok(())
}
