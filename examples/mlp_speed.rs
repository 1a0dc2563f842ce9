//! Times the MLP field's evaluation and backward per point (the work of a conditioned-field
//! iteration: `recon::field`'s default 3 × 32 MLP with 3 frequencies, or any shape), GPU
//! timestamps per pass, medians over the runs.
//!
//! Run: `cargo run --release --example mlp_speed [-- LAYERS WIDTH FREQS POINTS REPEATS]`
//! (defaults 3 32 3 32768 5).

use softvk::field::{Cube, Field, FieldKind};
use softvk::gpu::{Context, ContextOptions, MemoryKind, Timer};

fn main() -> softvk::Result<()> {
    let args: Vec<u32> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("a number"))
        .collect();
    let arg = |i: usize, d: u32| args.get(i).copied().unwrap_or(d);
    let (layers, width, freqs) = (arg(0, 3), arg(1, 32), arg(2, 3));
    let (points, repeats) = (arg(3, 32768), arg(4, 5));
    let ctx = Context::new(&ContextOptions::from_env())?;
    let cube = Cube {
        center: [0.0; 3],
        half: 1.0,
    };
    let kind = FieldKind::Mlp {
        hidden_layers: layers,
        width,
        frequencies: freqs,
    };
    let field = Field::new(&ctx, kind, cube, 7)?;
    // Points spread through the cube (a fixed low-discrepancy walk), dL/dφ a wave.
    let pts: Vec<[f32; 4]> = (0..points)
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
    let d: Vec<f32> = (0..points).map(|i| (i as f32 * 0.37).sin()).collect();
    let pts = ctx.upload_buffer("points", &pts)?;
    let d_phi = ctx.upload_buffer("d_phi", &d)?;
    let phi = ctx.create_buffer("phi", 4 * u64::from(points), MemoryKind::Device)?;
    let d_params = ctx.create_buffer(
        "d_params",
        4 * field.param_count() as u64,
        MemoryKind::Device,
    )?;
    println!(
        "{} on {}: MLP {layers} × {width}, {freqs} frequencies ({} parameters), {points} points",
        env!("CARGO_PKG_NAME"),
        ctx.info().name,
        field.param_count()
    );
    let mut timer = Timer::new(&ctx, 16)?;
    let recorded = ctx.record(Some(&mut timer), |rec| {
        rec.pass("eval", |rec| {
            field.record_eval(rec, pts.whole(), points, phi.whole())
        })?;
        rec.pass("backward", |rec| {
            field.record_backward(rec, pts.whole(), points, d_phi.whole(), d_params.whole())
        })
    })?;
    recorded.submit_and_wait()?; // warm-up
    let mut ms: Vec<(f64, f64)> = Vec::new();
    for _ in 0..repeats {
        recorded.submit_and_wait()?;
        let r = timer.results(&ctx)?;
        let get = |n: &str| r.iter().find(|p| p.name == n).map_or(f64::NAN, |p| p.ms);
        ms.push((get("eval"), get("backward")));
    }
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let eval = median(ms.iter().map(|m| m.0).collect());
    let backward = median(ms.iter().map(|m| m.1).collect());
    let per = |x: f64| 1e6 * x / f64::from(points);
    println!(
        "eval {eval:.2} ms ({:.0} ns/point), backward {backward:.2} ms ({:.0} ns/point); \
         medians of {repeats}; load {}",
        per(eval),
        per(backward),
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .trim()
    );
    let sum: f64 = ctx
        .read_buffer::<f32>(&d_params, 0, field.param_count())?
        .iter()
        .map(|&x| f64::from(x).abs())
        .sum();
    println!("checksum Σ|dL/dθ| {sum:.6e}");
    Ok(())
}
