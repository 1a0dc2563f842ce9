//! softvk inside a wgpu application: wgpu owns the device, the queue and the buffers; softvk
//! records into a wgpu encoder's raw command buffer between wgpu's own passes, all in one
//! `queue.submit` per frame. GPU tests as softvk's own: they fail without a Vulkan device unless
//! `SOFTVK_NO_GPU=1`, and validate unless `SOFTVK_VALIDATION=0`, here with synchronization
//! validation, within and between command buffers.

use std::process::Command;

use softvk_wgpu_host::validation::Message;
use softvk_wgpu_host::{
    App, Barriers, Host, cpu, layer_enables_with_submit_time_sync_validation, no_gpu,
    submit_time_sync_validation_requested, validation_wanted,
};

/// Marks the child process of [`run_here`].
const CHILD: &str = "SOFTVK_WGPU_HOST_TEST_CHILD";

/// Whether the test body should run in this process. With validation on and the layer's
/// submit-time synchronization validation not yet asked for, it cannot be switched on from
/// inside a process that may already have threads (the layer reads `VK_LAYER_ENABLES` when it
/// loads, and setting the environment while other threads may read it is unsound), so this runs
/// the test `name` again in a child process of this test binary with it set, fails if the child
/// fails, and returns false.
fn run_here(name: &str) -> bool {
    if !validation_wanted()
        || std::env::var_os(CHILD).is_some()
        || submit_time_sync_validation_requested()
    {
        return true;
    }
    let output = Command::new(std::env::current_exe().expect("this test binary"))
        .args([name, "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD, "1")
        .env(
            "VK_LAYER_ENABLES",
            layer_enables_with_submit_time_sync_validation(),
        )
        // As softvk's own contexts do (src/gpu/context/create.rs): the layer's on-disk shader
        // validation cache is rewritten without locking by every device, and parallel tests
        // can crash the layer on a half-written one.
        .env(
            "VK_LAYER_DISABLES",
            "VK_VALIDATION_FEATURE_DISABLE_SHADER_VALIDATION_CACHE_EXT",
        )
        .output()
        .expect("run this test binary again");
    let stdout = String::from_utf8_lossy(&output.stdout);
    eprintln!("{stdout}{}", String::from_utf8_lossy(&output.stderr));
    assert!(
        output.status.success(),
        "`{name}` failed with submit-time synchronization validation (output above)"
    );
    assert!(
        stdout.contains("1 passed"),
        "the child ran no test named `{name}`"
    );
    false
}

/// The app, or `None` (after saying so) when `SOFTVK_NO_GPU=1`.
fn app(validation: bool) -> Option<App> {
    if no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return None;
    }
    let app = App::new(validation).unwrap_or_else(|e| {
        panic!(
            "cannot set up the wgpu host ({e}); set SOFTVK_NO_GPU=1 to skip GPU tests explicitly"
        )
    });
    assert_eq!(app.host().validation_enabled(), validation);
    assert_eq!(app.host().submit_time_sync_validation(), validation);
    Some(app)
}

/// One frame against the twins: alpha within 1e-4, gradients within 1e-3 of their scale.
fn check(what: &str, got: &softvk_wgpu_host::FrameResult, want: &(Vec<f64>, Vec<[f64; 3]>)) {
    let (alpha, grads) = cpu::distance(got, want);
    assert!(alpha <= 1e-4, "{what}: alpha differs by {alpha:.2e}");
    assert!(
        grads <= 1e-3,
        "{what}: gradients differ by {grads:.2e} of their scale"
    );
    eprintln!("{what}: alpha within {alpha:.1e}, gradients within {grads:.1e} of their scale");
}

fn listing(messages: &[Message]) -> String {
    messages
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn wgpu_frames_run_softvk_between_wgsl_passes_with_no_softvk_submission() {
    if no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    if !run_here("wgpu_frames_run_softvk_between_wgsl_passes_with_no_softvk_submission") {
        return;
    }
    let validation = validation_wanted();
    let Some(app) = app(validation) else { return };
    let host = app.host();
    // wgpu's setup, the device opened through wgpu-hal with softvk's extensions, and softvk's
    // adoption say nothing...
    let setup = host.take_validation_messages();
    assert!(setup.is_empty(), "during setup:\n{}", listing(&setup));
    if validation {
        // ... and the capture is live: a deliberate, harmless violation is reported.
        host.provoke_harmless_violation().unwrap();
        let caught = host.take_validation_messages();
        assert!(
            caught
                .iter()
                .any(|m| m.id_name.contains("VUID-VkBufferCreateInfo-usage")),
            "the validation layer is not listening; it said:\n{}",
            listing(&caught)
        );
    }

    let before = app.softvk_counters();
    let mut frames = Vec::new();
    for frame in 0..4 {
        let got = app.frame(frame, Barriers::Both).unwrap();
        let want = cpu::frame(frame);
        assert!(
            want.0.iter().any(|&a| a > 0.5),
            "frame {frame}: nothing drawn"
        );
        check(&format!("frame {frame}"), &got, &want);
        frames.push(got);
    }
    assert!(frames[0] != frames[1], "the frames do not move");
    let after = app.softvk_counters();
    assert!(app.capacity_held().unwrap(), "the gate stopped a frame");
    assert_eq!(
        after, before,
        "softvk submitted or staged on its own during the frames"
    );
    eprintln!("softvk counters before the frames {before:?}, after {after:?}");

    let during = host.take_validation_messages();
    assert!(
        during.is_empty(),
        "validation during the frames ({} message(s)):\n{}",
        during.len(),
        listing(&during)
    );
}

/// Negative control: the same frame without softvk's entry barrier is a read-after-write hazard
/// between the producer's command buffer and softvk's, reported at `vkQueueSubmit`. The
/// producer is a host's raw Vulkan command here, not the WGSL deform pass: layer 1.3.239 reports
/// hazards between raw-recorded command buffers (softvk's push-descriptor dispatches included),
/// but it reported none against accesses recorded by wgpu's own passes, whichever barrier was
/// left out (README, "softvk in a wgpu application").
#[test]
fn missing_entry_barrier_is_a_sync_hazard() {
    if no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    if !validation_wanted() {
        eprintln!("SOFTVK_VALIDATION=0: the negative control needs the validation layer; skipping");
        return;
    }
    if !run_here("missing_entry_barrier_is_a_sync_hazard") {
        return;
    }
    let Some(app) = app(true) else { return };
    let host = app.host();
    // Every coordinate 0.25: all vertices at one point, every face degenerate, nothing drawn.
    let value = 0.25f32;
    let want = cpu::softvk(&vec![[value; 3]; app.len() as usize]);
    // The correct frame first: the only difference below is softvk's entry barrier.
    let got = app
        .frame_from_raw_producer(value.to_bits(), Barriers::Both)
        .unwrap();
    check("raw producer", &got, &want);
    let clean = host.take_validation_messages();
    assert!(clean.is_empty(), "a correct frame:\n{}", listing(&clean));

    app.frame_from_raw_producer(0.5f32.to_bits(), Barriers::OmitEntry)
        .unwrap();
    let messages = host.take_validation_messages();
    let hazard = messages
        .iter()
        .find(|m| m.is_hazard("READ-AFTER-WRITE"))
        .unwrap_or_else(|| {
            panic!(
                "no SYNC-HAZARD-READ-AFTER-WRITE without softvk's entry barrier; the layer said:\n{}",
                listing(&messages)
            )
        });
    eprintln!("negative control, as expected: {hazard}");
}

/// Why a frame is three command buffers and not one encoder: wgpu 30 refuses to mix its passes
/// and raw recording in one encoder. If this starts failing, wgpu allows it again and softvk's
/// recording can move into the passes' encoder.
#[test]
fn one_encoder_cannot_mix_wgpu_passes_and_raw_recording() {
    if no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let host = Host::new(false).unwrap_or_else(|e| {
        panic!(
            "cannot set up the wgpu host ({e}); set SOFTVK_NO_GPU=1 to skip GPU tests explicitly"
        )
    });
    let mut encoder = host
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
    drop(encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default()));
    eprintln!("a panic message about mixing encoding APIs is expected next");
    let mixed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        // SAFETY: nothing is recorded; the callback only looks at the encoder.
        unsafe {
            encoder.as_hal_mut::<wgpu::hal::api::Vulkan, _, _>(|hal| hal.is_some());
        }
    }));
    let message = mixed.expect_err("wgpu let raw recording follow a pass in one encoder");
    let text = message
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| message.downcast_ref::<String>().cloned())
        .unwrap_or_default();
    assert!(text.contains("Mixing the wgpu encoding API"), "{text}");
}
