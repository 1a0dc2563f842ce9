//! What every criterion benchmark here shares: the device, and timing a recorded submission by
//! the wall clock or the GPU's timestamps.

use std::time::{Duration, Instant};

use softvk::gpu::{Context, ContextOptions, Recorded, Timer};

/// The device the benchmarks run on (`SOFTVK_DEVICE` and the rest of the environment).
pub fn context() -> Context {
    Context::new(&ContextOptions::from_env()).expect("benchmarks need a Vulkan device")
}

/// Times `recorded` both ways for criterion's `iters`.
pub fn time(
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
