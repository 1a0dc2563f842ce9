//! A headless wgpu application that runs softvk inside its frames:
//!
//! ```sh
//! cargo run --release -p softvk-wgpu-host --example frames -- [FRAMES] [--negative-control]
//! ```
//!
//! Each frame is one `queue.submit`: a WGSL compute pass deforms a mesh into the application's
//! vertex buffer, softvk records the silhouettes of those vertices and their backward into a
//! wgpu encoder's raw Vulkan command buffer, a WGSL compute pass reads softvk's silhouettes and
//! gradients. Every frame is checked against softvk's f64 twins; softvk's own submissions and
//! staging copies are
//! counted, and the validation layer (with synchronization validation within and between
//! command buffers; `SOFTVK_VALIDATION=0` turns it off) is listened to. `--negative-control`
//! adds frames without one of softvk's barriers and prints what the layer says about each.

use std::process::ExitCode;

use softvk_wgpu_host::{
    App, Barriers, cpu, layer_enables_with_submit_time_sync_validation,
    submit_time_sync_validation_requested, validation_wanted,
};

fn main() -> ExitCode {
    let validation = validation_wanted();
    if validation && !submit_time_sync_validation_requested() {
        // SAFETY: the start of `main`, before anything that starts a thread: no other thread exists
        // that could read the environment, and the layer reads it when the first instance is made.
        unsafe {
            std::env::set_var(
                "VK_LAYER_ENABLES",
                layer_enables_with_submit_time_sync_validation(),
            )
        };
    }
    let mut frames = 5u32;
    let mut negative_control = false;
    for arg in std::env::args().skip(1) {
        match arg.as_str() {
            "--negative-control" => negative_control = true,
            n => match n.parse() {
                Ok(n) => frames = n,
                Err(_) => {
                    eprintln!("usage: frames [FRAMES] [--negative-control]");
                    return ExitCode::from(2);
                }
            },
        }
    }
    let app = match App::new(validation) {
        Ok(app) => app,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let info = app.host().adapter.get_info();
    println!(
        "wgpu {} on {} ({}), validation {}",
        info.backend,
        info.name,
        info.driver_info,
        match (validation, app.host().submit_time_sync_validation()) {
            (true, true) => "on (synchronization validation within and between command buffers)",
            (true, false) => "on (synchronization validation within command buffers only)",
            (false, _) => "off",
        }
    );
    let setup = app.host().take_validation_messages();
    let before = app.softvk_counters();
    let mut ok = setup.is_empty();
    for m in &setup {
        println!("validation during setup: {m}");
    }
    for frame in 0..frames {
        match app.frame(frame, Barriers::Both) {
            Ok(got) => {
                let (alpha, grads) = cpu::distance(&got, &cpu::frame(frame));
                let same = alpha <= 1e-4 && grads <= 1e-3;
                ok &= same;
                println!(
                    "frame {frame}: {} pixels, {} vertex gradients; alpha within {alpha:.1e} and \
                     gradients within {grads:.1e} of the f64 twins' ({})",
                    got.0.len(),
                    got.1.len(),
                    if same { "match" } else { "DIFFER" }
                );
            }
            Err(e) => {
                eprintln!("frame {frame}: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    let after = app.softvk_counters();
    println!(
        "softvk during the frames: {} submission(s), {} staging cop(ies)",
        after.submissions - before.submissions,
        after.staging_copies - before.staging_copies
    );
    ok &= after == before;
    let during = app.host().take_validation_messages();
    println!("validation messages during the frames: {}", during.len());
    for m in &during {
        println!("  {m}");
    }
    ok &= during.is_empty();

    if negative_control {
        // Each case after a correct frame, so that only the one barrier differs.
        let cases = [
            (
                "raw producer, no entry barrier",
                Some(0.5f32.to_bits()),
                Barriers::OmitEntry,
            ),
            ("WGSL deform, no entry barrier", None, Barriers::OmitEntry),
            ("WGSL deform, no exit barrier", None, Barriers::OmitExit),
        ];
        for (label, raw_value, barriers) in cases {
            let run = |barriers| match raw_value {
                Some(value) => app.frame_from_raw_producer(value, barriers),
                None => app.frame(frames, barriers),
            };
            if let Err(e) = run(Barriers::Both).and_then(|_| {
                app.host().take_validation_messages();
                run(barriers)
            }) {
                eprintln!("negative control ({label}): {e}");
                return ExitCode::FAILURE;
            }
            let said = app.host().take_validation_messages();
            println!("negative control ({label}): {} message(s)", said.len());
            for m in &said {
                println!("  {m}");
            }
        }
    }
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
