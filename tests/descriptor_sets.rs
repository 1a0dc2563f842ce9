//! The fallback for devices without `VK_KHR_push_descriptor`: dispatches bind cached descriptor
//! sets instead of pushing their bindings. Both paths must compute the same bits; the sets must
//! be reused while their buffers live and freed when they go (a dropped buffer's handle value
//! can come back with a new buffer); a host device made without the extension runs softvk.
//!
//! `SOFTVK_DESCRIPTORS=sets` runs every other test file in the fallback mode; this one picks each
//! mode itself, whatever the environment says.

mod common;

use ash::vk;
use common::host::HostDevice;
use rand::RngExt;
use softvk::camera::Camera;
use softvk::gpu::{
    Context, DescriptorMode, PUSH_DESCRIPTOR_EXTENSION, REQUIRED_DEVICE_EXTENSIONS, Recorder,
};
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::primitives::{Scan, ScanScratch, scan};
use softvk::raster::gpu::{Frames, Method, Renderer};
use softvk::raster::reference_grad::Gradients;
use softvk::raster::settings::RasterSettings;

fn lighting() -> Lighting {
    Lighting {
        ambient_intensity: 0.4,
        ambient_color: [1.0, 0.9, 0.8],
        directionals: vec![Directional {
            intensity: 0.6,
            color: [1.0, 1.0, 0.9],
            direction: [0.3, 0.5, -0.8],
        }],
    }
}

fn random_colors(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = common::rng(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(0.1..0.9)))
        .collect()
}

/// A jittered icosphere(1) (80 faces) with random texels (resolution 2) and vertex colours.
fn scene() -> Mesh {
    let mut rng = common::rng(3);
    let ico = Mesh::icosphere(1);
    let positions: Vec<[f32; 3]> = ico
        .positions
        .iter()
        .map(|p| p.map(|c| c * 0.6 + rng.random_range(-0.03..0.03)))
        .collect();
    let mut mesh = Mesh::new(positions, ico.faces.clone(), 2).unwrap();
    mesh.textures = random_colors(mesh.textures.len(), 4);
    mesh.vertex_colors = Some(random_colors(mesh.vertex_count(), 5));
    mesh
}

fn settings() -> RasterSettings {
    RasterSettings {
        width: 24,
        height: 16,
        sigma: 2e-2,
        gamma: 5e-2,
        near: 0.5,
        far: 10.0,
        ..RasterSettings::default()
    }
}

fn cameras() -> [Camera; 2] {
    [
        Camera::from_angles(2.732, 15.0, 20.0),
        Camera::from_angles(2.732, 30.0, 140.0),
    ]
}

/// Bit patterns of frames (images and aux), so -0.0 vs 0.0 counts as a difference.
fn frame_bits(f: &Frames) -> Vec<u32> {
    f.images
        .iter()
        .flatten()
        .map(|c| c.to_bits())
        .chain(f.aux.iter().flat_map(|a| {
            [
                a.softmax_ref_depth.to_bits(),
                a.softmax_sum.to_bits(),
                a.alpha_acc.to_bits(),
                a.alpha_zeros,
                a.hard_face,
            ]
        }))
        .collect()
}

fn grad_bits(g: &Gradients) -> Vec<u64> {
    g.positions
        .iter()
        .chain(&g.colors)
        .chain(g.cameras.iter().flat_map(|c| [&c.eye, &c.at, &c.up]))
        .flatten()
        .map(|x| x.to_bits())
        .collect()
}

/// The bits of one method's frames and gradients.
type Bits = (Vec<u32>, Vec<u64>);

/// Forward and backward of [`scene`], brute force and tiled, three times over the same prepared
/// scene (a fitting loop's shape). Returns the bits of the last iteration's frames and
/// gradients per method, and the context's cached set count after each iteration.
fn render_and_differentiate(gpu: &Context) -> (Vec<Bits>, Vec<usize>) {
    let r = Renderer::new(gpu).unwrap();
    let mesh = scene();
    let cams = cameras();
    let s = settings();
    let mut rng = common::rng(9);
    let w: Vec<[f32; 4]> = (0..(s.width * s.height) as usize * cams.len())
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect();
    let mut results = Vec::new();
    let mut cached = Vec::new();
    for method in [Method::Brute, Method::Tiled { tile: 8 }] {
        let mut prepared = r.prepare(gpu, &mesh, &cams, &lighting(), &s).unwrap();
        let mut last = None;
        for _ in 0..3 {
            let binned = r.run(gpu, &mut prepared, method).unwrap().binned();
            let frames = binned.scene().read_frames(gpu).unwrap();
            let grads = r.backward(gpu, &binned, &w, true).unwrap();
            let bits = (frame_bits(&frames), grad_bits(&grads));
            if let Some(previous) = &last {
                assert!(previous == &bits, "{method:?}: iterations differ");
            }
            last = Some(bits);
            cached.push(gpu.cached_descriptor_sets());
        }
        results.extend(last);
    }
    drop(r);
    // Every set names a buffer, and every buffer is gone (scenes, gradients, the renderer's).
    assert_eq!(
        gpu.cached_descriptor_sets(),
        0,
        "sets outlived their buffers"
    );
    (results, cached)
}

/// The renderer's forward and backward give the same bits with push descriptors and with
/// descriptor sets; each context reports its mode; the sets of a repeated iteration are found
/// in the cache instead of piling up, and all are gone with the buffers.
#[test]
fn push_descriptors_and_descriptor_sets_render_and_differentiate_bit_identically() {
    let Some(push) = common::gpu_descriptors(false) else {
        return;
    };
    let Some(sets) = common::gpu_descriptors(true) else {
        return;
    };
    assert_eq!(sets.descriptor_mode(), DescriptorMode::Sets);
    let want_push = if push.info().push_descriptor {
        DescriptorMode::Push
    } else {
        DescriptorMode::Sets
    };
    assert_eq!(push.descriptor_mode(), want_push);

    let (with_push, push_cached) = render_and_differentiate(&push);
    if want_push == DescriptorMode::Push {
        assert!(push_cached.iter().all(|&n| n == 0), "{push_cached:?}");
        assert_eq!(push.counters().descriptor_sets, 0);
    }
    let (with_sets, sets_cached) = render_and_differentiate(&sets);
    assert!(with_push == with_sets, "the two descriptor paths differ");

    // Per method: the first iteration fills the cache; later ones bind the same scene buffers
    // again and drop their per-call gradient buffers, so the count comes back to where it was.
    assert!(sets_cached.iter().all(|&n| n > 0), "{sets_cached:?}");
    for per_method in sets_cached.chunks(3) {
        assert!(
            per_method.windows(2).all(|w| w[0] == w[1]),
            "the cache grows every iteration: {sets_cached:?}"
        );
    }
    assert!(sets.counters().descriptor_sets > 0);
}

/// A scan recorded twice with the same buffers allocates its sets once; dropping a buffer
/// frees the sets that name it (and only those); dropping the kernels frees the rest.
#[test]
fn sets_are_reused_while_their_buffers_live_and_freed_with_them() {
    let Some(gpu) = common::gpu_descriptors(true) else {
        return;
    };
    let scan = Scan::new(&gpu).unwrap();
    // Two levels: block sums and the total live in the scratch, the data in its own buffer.
    let n = 3 * scan::SCAN_BLOCK as usize + 5;
    let data: Vec<u32> = (0..n as u32).map(|i| i % 13).collect();
    let scratch = ScanScratch::new(&gpu, n as u64).unwrap();
    let record = |buffer: &softvk::gpu::Buffer| {
        gpu.submit_and_wait(|rec| {
            scan.record(rec, &scratch, buffer.whole(), buffer.whole(), n as u64)
        })
        .unwrap();
    };
    assert_eq!(gpu.cached_descriptor_sets(), 0);
    let buffer = gpu.upload_buffer("scanned", &data).unwrap();
    record(&buffer);
    let cached = gpu.cached_descriptor_sets();
    let allocated = gpu.counters().descriptor_sets;
    assert!(
        cached > 0 && allocated == cached as u64,
        "{cached} {allocated}"
    );
    let out: Vec<u32> = gpu.read_buffer(&buffer, 0, n).unwrap();
    assert_eq!(out, scan::cpu::exclusive_scan(&data).0);

    // The same bindings again: nothing new.
    gpu.write_buffer(&buffer, 0, &data).unwrap();
    record(&buffer);
    assert_eq!(gpu.cached_descriptor_sets(), cached);
    assert_eq!(gpu.counters().descriptor_sets, allocated);
    assert_eq!(
        gpu.read_buffer::<u32>(&buffer, 0, n).unwrap(),
        scan::cpu::exclusive_scan(&data).0
    );

    // Dropping the data frees its sets; those of the scratch alone (the upper levels) stay.
    drop(buffer);
    let after_drop = gpu.cached_descriptor_sets();
    assert!(after_drop < cached, "{after_drop} of {cached} left");
    // A new buffer (which may reuse the old handle value) gets sets of its own, and right
    // results: the same number of sets as before the drop.
    let other: Vec<u32> = (0..n as u32).map(|i| (i * 7) % 11).collect();
    let buffer = gpu.upload_buffer("scanned again", &other).unwrap();
    record(&buffer);
    assert_eq!(gpu.cached_descriptor_sets(), cached);
    assert_eq!(
        gpu.read_buffer::<u32>(&buffer, 0, n).unwrap(),
        scan::cpu::exclusive_scan(&other).0
    );

    // The scratch's drop frees what its levels still had (the scan's pipelines are the
    // context's, shared: they outlive the scan).
    drop(buffer);
    assert!(gpu.cached_descriptor_sets() > 0);
    drop(scan);
    drop(scratch);
    assert_eq!(gpu.cached_descriptor_sets(), 0);
}

/// Buffers made, scanned and dropped over and over: each new buffer may reuse a dropped one's
/// handle value (lavapipe's handles are heap addresses), and must never see its stale sets.
/// Also without validation: the layer wraps handles in values it never reuses, which hides
/// exactly this hazard.
#[test]
fn a_reused_buffer_handle_never_finds_a_stale_set() {
    for validation in [false, common::validation_wanted()] {
        let Some(gpu) = common::gpu_with(|o| {
            o.descriptor_sets = true;
            o.validation = validation;
        }) else {
            return;
        };
        scan_in_fresh_buffers(&gpu);
    }
}

fn scan_in_fresh_buffers(gpu: &Context) {
    let scan = Scan::new(gpu).unwrap();
    let n = 1000usize;
    let scratch = ScanScratch::new(gpu, n as u64).unwrap();
    let mut handles = std::collections::HashSet::new();
    let mut reused = 0;
    for round in 0..12u32 {
        let data: Vec<u32> = (0..n as u32).map(|i| (i + round) % (round + 2)).collect();
        let buffer = gpu.upload_buffer("round", &data).unwrap();
        if !handles.insert(vk::Handle::as_raw(buffer.raw())) {
            reused += 1;
        }
        gpu.submit_and_wait(|rec| {
            scan.record(rec, &scratch, buffer.whole(), buffer.whole(), n as u64)
        })
        .unwrap();
        assert_eq!(
            gpu.read_buffer::<u32>(&buffer, 0, n).unwrap(),
            scan::cpu::exclusive_scan(&data).0,
            "round {round}"
        );
    }
    eprintln!(
        "validation {}: {reused} of 12 rounds reused an earlier buffer's handle",
        gpu.validation_enabled()
    );
    // Only the sets naming the scratch alone may remain (none: each scan binds the data).
    assert_eq!(gpu.cached_descriptor_sets(), 0);
}

/// More sets than one pool holds (128): 300 scans of distinct 16-element ranges of one buffer,
/// recorded into one command buffer, make new pools as the old ones fill; all results right.
/// Done twice, so the second round allocates from pools whose sets were freed.
#[test]
fn pools_grow_on_demand() {
    let Some(gpu) = common::gpu_descriptors(true) else {
        return;
    };
    let scan = Scan::new(&gpu).unwrap();
    let segments = 300usize;
    let len = 16usize;
    let scratch = ScanScratch::new(&gpu, len as u64).unwrap();
    for round in 0..2u32 {
        let data: Vec<u32> = (0..(segments * len) as u32)
            .map(|i| (i * 31 + round) % 7)
            .collect();
        let buffer = gpu.upload_buffer("segments", &data).unwrap();
        gpu.submit_and_wait(|rec| {
            for i in 0..segments {
                let range = buffer.range((i * len * 4) as u64, (len * 4) as u64);
                scan.record(rec, &scratch, range, range, len as u64)?;
            }
            Ok(())
        })
        .unwrap();
        assert!(gpu.cached_descriptor_sets() >= segments);
        let out: Vec<u32> = gpu.read_buffer(&buffer, 0, data.len()).unwrap();
        let want: Vec<u32> = data
            .chunks(len)
            .flat_map(|c| scan::cpu::exclusive_scan(c).0)
            .collect();
        assert_eq!(out, want, "round {round}");
        drop(buffer);
        assert_eq!(gpu.cached_descriptor_sets(), 0);
    }
}

/// Threads that make, bind and drop buffers on one context at once (evictions racing cache
/// look-ups) all get right results.
#[test]
fn threads_share_the_cache() {
    let Some(gpu) = common::gpu_descriptors(true) else {
        return;
    };
    let scan = Scan::new(&gpu).unwrap();
    std::thread::scope(|s| {
        for t in 0..3u32 {
            let (gpu, scan) = (&*gpu, &scan);
            s.spawn(move || {
                for round in 0..4u32 {
                    let data: Vec<u32> = (0..700 + 100 * t).map(|i| (i ^ round) % 9).collect();
                    let (out, total) = scan.run(gpu, &data).unwrap();
                    let want = scan::cpu::exclusive_scan(&data);
                    assert_eq!((out, total), want, "thread {t} round {round}");
                }
            });
        }
    });
    assert_eq!(gpu.cached_descriptor_sets(), 0);
}

/// `SOFTVK_DESCRIPTORS` chooses the mode of contexts made from the environment, and
/// `softvk info` says which one it got. (A child process: this binary's threads read the
/// environment, so no test here may write it.)
#[test]
fn the_environment_chooses_the_mode_and_info_reports_it() {
    let Some(gpu) = common::gpu_descriptors(false) else {
        return;
    };
    let default = if gpu.info().push_descriptor {
        "push"
    } else {
        "sets"
    };
    for (value, want) in [
        ("sets", "sets"),
        ("SETS", "sets"),
        ("push", default),
        ("", default),
    ] {
        let out = common::softvk()
            .arg("info")
            .env("SOFTVK_DESCRIPTORS", value)
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{value:?}: {stdout}");
        let line = stdout
            .lines()
            .find(|l| l.starts_with("descriptors "))
            .unwrap_or_else(|| panic!("no descriptor mode in:\n{stdout}"));
        assert_eq!(
            line.split_whitespace().nth(1),
            Some(want),
            "SOFTVK_DESCRIPTORS={value:?}: {line}"
        );
    }
}

/// A host device created without `VK_KHR_push_descriptor` (as tests/from_raw.rs, minus the
/// extension): softvk adopts it in the descriptor-set mode, records a scan into the host's
/// command buffer, the host submits it, and validation (which knows the extension is not
/// enabled) stays silent through teardown.
#[test]
fn a_host_device_without_push_descriptors_runs_a_softvk_kernel() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    // SAFETY: the whole test is host-side Vulkan setup, torn down in reverse order at the end.
    unsafe {
        let host = HostDevice::new(common::validation_wanted(), false);
        assert!(!REQUIRED_DEVICE_EXTENSIONS.contains(&PUSH_DESCRIPTOR_EXTENSION));
        assert!(!host.push_descriptor);
        let device = &host.device;
        let ctx = host.adopt();
        assert_eq!(ctx.descriptor_mode(), DescriptorMode::Sets);
        let scan = Scan::new(&ctx).unwrap();
        let data: Vec<u32> = (0..5000u32).map(|i| i % 17).collect();
        let buffer = ctx.upload_buffer("host scan", &data).unwrap();
        let scratch = ScanScratch::new(&ctx, data.len() as u64).unwrap();
        assert_eq!(ctx.cached_descriptor_sets(), 0);

        // The host records softvk's kernel into its own command buffer, recording done before
        // it submits: the sets must outlive the recording.
        let before = ctx.counters();
        host.begin();
        {
            let mut rec = Recorder::new(&ctx, host.cmd);
            let range = buffer.whole();
            scan.record(&mut rec, &scratch, range, range, data.len() as u64)
                .unwrap();
        }
        let after = ctx.counters();
        assert_eq!(after.submissions, before.submissions);
        assert!(after.descriptor_sets > before.descriptor_sets);
        assert!(ctx.cached_descriptor_sets() > 0);
        host.end_submit_and_wait();

        let out: Vec<u32> = ctx.read_buffer(&buffer, 0, data.len()).unwrap();
        assert_eq!(out, scan::cpu::exclusive_scan(&data).0);

        // A host buffer softvk borrows: its sets go when the borrow is dropped, though the
        // host's buffer lives on.
        let host_buffer = device
            .create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(4 * data.len() as u64)
                    .usage(
                        vk::BufferUsageFlags::STORAGE_BUFFER
                            | vk::BufferUsageFlags::TRANSFER_SRC
                            | vk::BufferUsageFlags::TRANSFER_DST,
                    ),
                None,
            )
            .unwrap();
        let requirements = device.get_buffer_memory_requirements(host_buffer);
        let memory = host
            .allocator
            .lock()
            .unwrap()
            .allocate(&gpu_allocator::vulkan::AllocationCreateDesc {
                name: "host buffer",
                requirements,
                location: gpu_allocator::MemoryLocation::GpuOnly,
                linear: true,
                allocation_scheme: gpu_allocator::vulkan::AllocationScheme::GpuAllocatorManaged,
            })
            .unwrap();
        device
            .bind_buffer_memory(host_buffer, memory.memory(), memory.offset())
            .unwrap();
        let borrowed = ctx.import_buffer(host_buffer, 4 * data.len() as u64, "borrowed");
        ctx.write_buffer(&borrowed, 0, &data).unwrap();
        let cached = ctx.cached_descriptor_sets();
        ctx.submit_and_wait(|rec| {
            scan.record(
                rec,
                &scratch,
                borrowed.whole(),
                borrowed.whole(),
                data.len() as u64,
            )
        })
        .unwrap();
        assert!(ctx.cached_descriptor_sets() > cached);
        assert_eq!(
            ctx.read_buffer::<u32>(&borrowed, 0, data.len()).unwrap(),
            scan::cpu::exclusive_scan(&data).0
        );
        drop(borrowed);
        assert_eq!(ctx.cached_descriptor_sets(), cached);

        drop((buffer, scratch, scan, ctx));
        device.device_wait_idle().expect("host device still alive");
        device.destroy_buffer(host_buffer, None);
        host.allocator.lock().unwrap().free(memory).unwrap();
        host.finish();
    }
}
