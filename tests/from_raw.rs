//! A host engine's own device, queue and command buffer, adopted with `Context::from_raw`:
//! softvk records into the host's command buffer, the host submits, and softvk destroys none of
//! the host's objects.

mod common;

use common::host::HostDevice;
use softvk::gpu::{DescriptorMode, Recorder};
use softvk::primitives::{Scan, ScanScratch, scan};

#[test]
fn host_device_and_command_buffer_run_a_softvk_kernel() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    // SAFETY: the whole test is host-side Vulkan setup, torn down in reverse order at the end.
    unsafe {
        // The host's setup, none of it softvk's; this host enables push descriptors where the
        // device has them (tests/descriptor_sets.rs has one that never does).
        let host = HostDevice::new(common::validation_wanted(), true);
        let ctx = host.adopt();
        assert_eq!(
            ctx.descriptor_mode(),
            if host.push_descriptor {
                DescriptorMode::Push
            } else {
                DescriptorMode::Sets
            }
        );
        let scan = Scan::new(&ctx).unwrap();
        let data: Vec<u32> = (0..5000u32).map(|i| i % 17).collect();
        let buffer = ctx.upload_buffer("host scan", &data).unwrap();
        let scratch = ScanScratch::new(&ctx, data.len() as u64).unwrap();

        // The host records softvk's kernel into its own command buffer and submits it itself.
        host.begin();
        {
            let mut rec = Recorder::new(&ctx, host.cmd);
            let range = buffer.whole();
            scan.record(&mut rec, &scratch, range, range, data.len() as u64)
                .unwrap();
        }
        host.end_submit_and_wait();

        let out: Vec<u32> = ctx.read_buffer(&buffer, 0, data.len()).unwrap();
        assert_eq!(out, scan::cpu::exclusive_scan(&data).0);
        let total: Vec<u32> = ctx.read_buffer(scratch.total(), 0, 1).unwrap();
        assert_eq!(total[0], data.iter().sum::<u32>());

        // softvk lets go of everything it made; the host's objects must all still be alive.
        drop((buffer, scratch, scan, ctx));
        host.finish();
    }
}
