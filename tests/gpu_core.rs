//! The Vulkan core: validation capture, device info, buffers, kernel interface checks, timers.

mod common;

use ash::vk;
use common::all_kernels;
use softvk::Error;
use softvk::gpu::{MemoryKind, Timer, specs};
use softvk::raster::specs as raster_specs;
use softvk::specs as top_specs;

use softvk::primitives::{Scan, ScanScratch};

#[test]
fn validation_check_fails_on_deliberate_misuse() {
    let Some(gpu) = common::gpu() else { return };
    if !common::validation_wanted() {
        eprintln!("SOFTVK_VALIDATION=0: the validation check cannot be exercised");
        return;
    }
    gpu.check_validation().expect("clean before the misuse");
    // A buffer with no usage flags violates VUID-VkBufferCreateInfo-usage-requiredbitmask.
    let info = vk::BufferCreateInfo::default()
        .size(64)
        .usage(vk::BufferUsageFlags::empty());
    // SAFETY: deliberate misuse the driver tolerates; the buffer is destroyed right away.
    unsafe {
        let buffer = gpu.device().create_buffer(&info, None).unwrap();
        gpu.device().destroy_buffer(buffer, None);
    }
    match gpu.check_validation() {
        Err(Error::Validation { count, first }) => {
            assert!(count >= 1);
            assert!(first.contains("usage"), "unexpected message: {first}");
        }
        other => panic!("the misuse went unnoticed: {other:?}"),
    }
    // The check consumed the messages, so the log is clean again.
    gpu.check_validation().unwrap();
}

#[test]
fn device_info_reports_vulkan_1_2_and_sane_limits() {
    let Some(gpu) = common::gpu() else { return };
    let info = gpu.info();
    assert!(info.api_version >= (1, 2, 0), "{:?}", info.api_version);
    assert!(!info.name.is_empty() && !info.driver.is_empty());
    assert!(info.subgroup_size >= 1);
    assert!(info.buffer_alignment().is_power_of_two());
    assert!(info.limits.max_compute_work_group_invocations >= 256);
    assert!(info.limits.max_compute_shared_memory_size >= 16384);
}

#[test]
fn buffers_round_sizes_and_round_trip_data() {
    let Some(gpu) = common::gpu() else { return };
    let align = gpu.info().buffer_alignment();
    let buffer = gpu
        .create_buffer("round trip", 13, MemoryKind::Device)
        .unwrap();
    assert_eq!(buffer.size() % align, 0);
    assert!(buffer.size() >= 13);
    let data: Vec<u32> = (0..1000).map(|i| i * 7 + 1).collect();
    let buffer = gpu.upload_buffer("round trip data", &data).unwrap();
    assert_eq!(
        gpu.read_buffer::<u32>(&buffer, 0, data.len()).unwrap(),
        data
    );
    assert_eq!(
        gpu.read_buffer::<u32>(&buffer, 40, 3).unwrap(),
        vec![71, 78, 85]
    );
    // Out-of-bounds reads and writes are errors, not corruption.
    let too_far = gpu.read_buffer::<u32>(&buffer, 0, 5000);
    assert!(matches!(too_far, Err(Error::Limit(_))), "{too_far:?}");
    let too_far = gpu.write_buffer(&buffer, buffer.size() - 4, &[1u32, 2]);
    assert!(matches!(too_far, Err(Error::Limit(_))), "{too_far:?}");
}

/// A buffer beyond the device's heaps (or its largest allocation) is one error naming the buffer,
/// the size and the limit, before any Vulkan call: no panic (an aligned `u64::MAX` used to wrap
/// to 0), no device loss, no validation message, and the context still works afterwards.
#[test]
fn absurd_buffers_are_one_clear_error_naming_the_buffer_and_the_size() {
    let Some(gpu) = common::gpu() else { return };
    for kind in [MemoryKind::Device, MemoryKind::Upload, MemoryKind::Readback] {
        let (limit, what) = gpu.max_buffer_size(kind);
        assert!(
            limit > 0 && limit < 1 << 50,
            "{kind:?}: limit {limit} ({what})"
        );
        let heaps = &gpu.info().memory.memory_heaps[..gpu.info().memory.memory_heap_count as usize];
        assert!(
            limit <= heaps.iter().map(|h| h.size).max().unwrap(),
            "{kind:?}: {limit} is more than every heap"
        );
        for size in [1u64 << 50, u64::MAX, u64::MAX - 3, limit + 1] {
            let err = match gpu.create_buffer("absurd scene", size, kind) {
                Err(e) => e,
                Ok(b) => panic!(
                    "{kind:?}: a buffer of {size} bytes was created ({} bytes)",
                    b.size()
                ),
            };
            let message = err.to_string();
            match err {
                Error::BufferTooLarge {
                    name,
                    size: asked,
                    limit: l,
                    what: w,
                } => {
                    assert_eq!(
                        (name.as_str(), asked, l, w),
                        ("absurd scene", size, limit, what)
                    );
                }
                other => panic!("{kind:?}, {size} bytes: not BufferTooLarge: {other:?}"),
            }
            assert!(!message.contains('\n'), "{message}");
            for needle in [
                "`absurd scene`",
                &size.to_string(),
                &limit.to_string(),
                what,
            ] {
                assert!(
                    message.contains(needle),
                    "`{needle}` missing from: {message}"
                );
            }
        }
    }
    // Still a working device: a small buffer round-trips.
    let buffer = gpu.upload_buffer("after", &[1u32, 2, 3]).unwrap();
    assert_eq!(gpu.read_buffer::<u32>(&buffer, 0, 3).unwrap(), [1, 2, 3]);
    // Reads and writes whose ends overflow u64 are refused too, not wrapped.
    assert!(matches!(
        gpu.read_buffer::<u32>(&buffer, u64::MAX - 3, 2),
        Err(Error::Limit(_))
    ));
    assert!(matches!(
        gpu.write_buffer(&buffer, u64::MAX - 3, &[0u32; 2]),
        Err(Error::Limit(_))
    ));
    gpu.check_validation().unwrap();
}

/// The context's pipeline cache knows a kernel by its name, so no two crates may name two
/// kernels alike.
#[test]
fn kernel_names_are_unique_across_the_crates() {
    let mut names: Vec<&str> = all_kernels().map(|k| k.name).collect();
    let count = names.len();
    names.sort_unstable();
    names.dedup();
    assert_eq!(names.len(), count, "two kernels share a name");
}

#[test]
fn every_generated_kernel_builds_a_pipeline() {
    let Some(gpu) = common::gpu() else { return };
    for list in [
        specs::ALL,
        raster_specs::ALL,
        softvk_fit::specs::ALL,
        softvk_field::specs::ALL,
        top_specs::ALL,
    ] {
        assert!(list.len() >= 4);
    }
    for spec in all_kernels() {
        assert!(
            !spec.spirv.is_empty() && spec.spirv[0] == 0x0723_0203,
            "{}",
            spec.name
        );
        assert!(spec.workgroup_size.iter().all(|&s| s >= 1), "{}", spec.name);
        gpu.kernel(spec, &[])
            .unwrap_or_else(|e| panic!("{}: {e}", spec.name));
    }
}

#[test]
fn the_contexts_kernels_are_built_once_per_specialization_and_shared() {
    let Some(gpu) = common::gpu() else { return };
    let a = gpu.kernel(&specs::SCAN_BLOCK, &[]).unwrap();
    let b = gpu.kernel(&specs::SCAN_BLOCK, &[]).unwrap();
    assert!(std::sync::Arc::ptr_eq(&a, &b), "asked twice, built twice");
    let other = gpu.kernel(&specs::SCAN_REDUCE, &[]).unwrap();
    assert!(!std::sync::Arc::ptr_eq(&a, &other));
    assert_eq!(other.name(), "scan_reduce");
    // Another specialization of one kernel is another pipeline (constants: activation, slope,
    // K, S, P).
    let conv = &top_specs::NN_CONV_FORWARD4;
    let slope = 0.2f32.to_bits();
    let k3 = gpu.kernel(conv, &[0, slope, 3, 1, 1]).unwrap();
    let k3_again = gpu.kernel(conv, &[0, slope, 3, 1, 1]).unwrap();
    let k4 = gpu.kernel(conv, &[0, slope, 4, 2, 1]).unwrap();
    assert!(std::sync::Arc::ptr_eq(&k3, &k3_again));
    assert!(!std::sync::Arc::ptr_eq(&k3, &k4));
    gpu.check_validation().unwrap();
}

#[test]
fn dispatch_rejects_arguments_that_do_not_fit_the_kernel() {
    let Some(gpu) = common::gpu() else { return };
    let kernel = gpu.kernel(&specs::SCAN_REDUCE, &[]).unwrap();
    let buffer = gpu.create_buffer("args", 4096, MemoryKind::Device).unwrap();
    let result = gpu.submit_and_wait(|rec| rec.dispatch(&kernel, &[buffer.whole()], &[0u32; 2], 1));
    assert!(
        matches!(&result, Err(Error::Kernel { kernel: "scan_reduce", message }) if message.contains("2 buffer bindings")),
        "{result:?}"
    );
    let result = gpu.submit_and_wait(|rec| {
        rec.dispatch(&kernel, &[buffer.whole(), buffer.whole()], &[0u32; 3], 1)
    });
    assert!(
        matches!(&result, Err(Error::Kernel { message, .. }) if message.contains("push constants")),
        "{result:?}"
    );
    let result = gpu.submit_and_wait(|rec| {
        rec.dispatch(
            &kernel,
            &[buffer.range(4, 64), buffer.whole()],
            &[0u32; 2],
            1,
        )
    });
    if gpu.info().limits.min_storage_buffer_offset_alignment > 4 {
        assert!(
            matches!(&result, Err(Error::Kernel { message, .. }) if message.contains("misaligned")),
            "{result:?}"
        );
    }
}

/// The tiled fine passes read their per-lane inputs as texel buffers (branch-free gathers on
/// llvmpipe): the kinds are reflected from the kernels, and a range that is not whole texels at
/// an aligned offset is refused before anything is recorded.
#[test]
fn texel_bindings_are_reflected_and_checked() {
    use softvk::gpu::{BindingKind, TEXEL_BYTES};
    let kinds = |spec: &softvk::gpu::KernelSpec| -> Vec<(&str, BindingKind)> {
        spec.bindings.iter().map(|b| (b.name, b.kind)).collect()
    };
    let grad = kinds(&raster_specs::GRAD_TILED);
    for name in ["Setups", "Colors", "Image", "Aux"] {
        assert!(
            grad.contains(&(name, BindingKind::Texels)),
            "{name}: {grad:?}"
        );
    }
    // The upstream may be a host's buffer: storage, which needs no texel usage.
    for name in ["DImage", "Partials", "Pairs"] {
        assert!(
            grad.contains(&(name, BindingKind::Storage)),
            "{name}: {grad:?}"
        );
    }
    let tiled = kinds(&raster_specs::RASTER_TILED);
    assert!(
        tiled.contains(&("Setups", BindingKind::Texels)),
        "{tiled:?}"
    );
    assert!(
        tiled.contains(&("Image", BindingKind::Storage)),
        "{tiled:?}"
    );
    assert!(
        raster_specs::RASTER_BRUTE
            .bindings
            .iter()
            .all(|b| b.kind == BindingKind::Storage)
    );

    let Some(gpu) = common::gpu() else { return };
    let kernel = gpu.kernel(&raster_specs::RASTER_TILED, &[]).unwrap();
    let buffer = gpu
        .create_buffer("texels", 4096, MemoryKind::Device)
        .unwrap();
    const PUSH_WORDS: usize = raster_specs::RASTER_TILED.push_constant_size as usize / 4;
    let push = [0u32; PUSH_WORDS];
    let dispatch = |setups: softvk::gpu::BufferRange<'_>| {
        let b = raster_specs::RasterTiledBindings {
            setups,
            colors: buffer.range(0, 256),
            faces: buffer.whole(),
            image: buffer.whole(),
            aux: buffer.whole(),
            carry: buffer.whole(),
            pairs: buffer.whole(),
            pair_items: buffer.whole(),
            ranges: buffer.whole(),
        };
        gpu.submit_and_wait(|rec| rec.dispatch(&kernel, &b.for_kernel(&kernel)?, &push, 0))
    };
    assert!(dispatch(buffer.range(0, 8 * TEXEL_BYTES)).is_ok());
    let result = dispatch(buffer.range(0, 8 * TEXEL_BYTES + 4));
    assert!(
        matches!(&result, Err(Error::Kernel { kernel: "raster_tiled", message })
            if message.contains("Setups") && message.contains("texels")),
        "{result:?}"
    );
    let align = gpu.info().limits.min_texel_buffer_offset_alignment;
    if align > 4 {
        let result = dispatch(buffer.range(align / 2, 8 * TEXEL_BYTES));
        assert!(
            matches!(&result, Err(Error::Kernel { message, .. }) if message.contains("aligned")),
            "{result:?}"
        );
    }
}

#[test]
fn scan_scratch_capacity_is_enforced() {
    let Some(gpu) = common::gpu() else { return };
    let scan = Scan::new(&gpu).unwrap();
    let scratch = ScanScratch::new(&gpu, 100).unwrap();
    let buffer = gpu
        .create_buffer("scan", 4 * 200, MemoryKind::Device)
        .unwrap();
    let result =
        gpu.submit_and_wait(|rec| scan.record(rec, &scratch, buffer.whole(), buffer.whole(), 200));
    assert!(matches!(result, Err(Error::Limit(_))), "{result:?}");
}

#[test]
fn timer_reports_each_named_pass() {
    let Some(gpu) = common::gpu() else { return };
    let scan = Scan::new(&gpu).unwrap();
    let n = 1u64 << 20;
    let buffer = gpu
        .upload_buffer("timed scan", &vec![1u32; n as usize])
        .unwrap();
    let scratch = ScanScratch::new(&gpu, n).unwrap();
    let mut timer = Timer::new(&gpu, 4).unwrap();
    gpu.submit_and_wait_timed(Some(&mut timer), |rec| {
        rec.pass("first", |rec| {
            scan.record(rec, &scratch, buffer.whole(), buffer.whole(), n)
        })?;
        rec.pass("second", |rec| {
            rec.pass("part", |rec| {
                scan.record(rec, &scratch, buffer.whole(), buffer.whole(), n)
            })
        })
    })
    .unwrap();
    let times = timer.results(&gpu).unwrap();
    let names: Vec<_> = times.iter().map(|t| t.indented()).collect();
    assert_eq!(names, ["first", "second", "  part"]);
    let depths: Vec<_> = times.iter().map(|t| t.depth).collect();
    assert_eq!(depths, [0, 0, 1]);
    assert!(
        times.iter().all(|t| t.ms > 0.0 && t.ms < 60_000.0),
        "{times:?}"
    );
    // The total counts the nested pass once, inside its parent.
    let total = timer.total_ms(&gpu).unwrap();
    assert_eq!(total, times[0].ms + times[1].ms);
    assert!(times[2].ms <= times[1].ms, "{times:?}");
    // Scanning the scan of ones gives 0, 0, 1, 3, 6, ...: (i - 1) i / 2.
    let out = gpu.read_buffer::<u32>(&buffer, 0, 5).unwrap();
    assert_eq!(out, vec![0, 0, 1, 3, 6]);
}

#[test]
fn gated_dispatches_run_with_their_grids_and_not_with_zero_grids() {
    let Some(gpu) = common::gpu() else { return };
    let scan = Scan::new(&gpu).unwrap();
    let n = 10_000u64; // three blocks: reduce, scan of sums, block scans
    let data: Vec<u32> = (0..n as u32).map(|i| i % 7).collect();
    let input = gpu.upload_buffer("gated input", &data).unwrap();
    let scratch = ScanScratch::new(&gpu, n).unwrap();
    let args = gpu
        .create_buffer("gated args", 64 * 12, MemoryKind::Device)
        .unwrap();
    let mut want = Vec::with_capacity(data.len());
    let mut sum = 0u32;
    for &d in &data {
        want.push(sum);
        sum += d;
    }
    let sentinel = vec![u32::MAX; data.len()];
    for run in [false, true] {
        let output = gpu.upload_buffer("gated output", &sentinel).unwrap();
        let mut grids = Vec::new();
        let recorded = gpu
            .record(None, |rec| {
                grids = rec.gated(args.whole(), |rec| {
                    scan.record(rec, &scratch, input.whole(), output.whole(), n)
                })?;
                Ok(())
            })
            .unwrap();
        assert!(grids.len() >= 3, "{grids:?}");
        assert!(grids.iter().all(|g| g[0] >= 1 && g[2] == 1));
        let words: Vec<u32> = if run {
            grids.iter().flatten().copied().collect()
        } else {
            vec![0; 3 * grids.len()]
        };
        gpu.write_buffer(&args, 0, &words).unwrap();
        recorded.submit_and_wait().unwrap();
        let got: Vec<u32> = gpu.read_buffer(&output, 0, data.len()).unwrap();
        assert_eq!(got, if run { want.clone() } else { sentinel.clone() });
    }
}

/// Bindings are declared once, by the kernels: `build.rs` reflects each storage block's name and
/// access, and generates a struct per kernel whose fields are the blocks, so calls bind buffers
/// by name (a positional swap cannot be written). Every block is named, names are unique per
/// kernel, bindings are numbered 0.. in order, a generated struct hands its fields to
/// `dispatch` in binding order, read-only blocks are marked so, and a struct given to another
/// kernel's pipeline is an error.
#[test]
fn bindings_are_declared_by_the_kernels_and_bound_by_name() {
    for spec in all_kernels() {
        let mut names: Vec<&str> = spec.bindings.iter().map(|b| b.name).collect();
        assert!(
            names.iter().all(|n| !n.is_empty()),
            "{}: unnamed block",
            spec.name
        );
        for (i, b) in spec.bindings.iter().enumerate() {
            assert_eq!(
                b.binding as usize, i,
                "{}: bindings out of order",
                spec.name
            );
        }
        names.sort_unstable();
        names.dedup();
        assert_eq!(
            names.len(),
            spec.bindings.len(),
            "{}: repeated block",
            spec.name
        );
    }
    let access: Vec<(&str, bool)> = raster_specs::GRAD_TILED
        .bindings
        .iter()
        .map(|b| (b.name, b.writable))
        .collect();
    assert!(access.contains(&("Partials", true)) && access.contains(&("Setups", false)));

    let Some(gpu) = common::gpu() else { return };
    let buffers: Vec<_> = raster_specs::GRAD_TILED
        .bindings
        .iter()
        .map(|b| gpu.upload_buffer(b.name, &[0u32; 4]).unwrap())
        .collect();
    let by_name = |name: &str| {
        buffers
            .iter()
            .find(|b| b.name() == name)
            .expect("a buffer per block")
            .whole()
    };
    let bindings = raster_specs::GradTiledBindings {
        // Written out of binding order on purpose: names, not positions, decide.
        ranges: by_name("Ranges"),
        partials: by_name("Partials"),
        setups: by_name("Setups"),
        colors: by_name("Colors"),
        faces: by_name("Faces"),
        image: by_name("Image"),
        aux: by_name("Aux"),
        d_image: by_name("DImage"),
        pairs: by_name("Pairs"),
        pair_items: by_name("PairItems"),
    };
    let order: Vec<&str> = bindings.ranges().iter().map(|r| r.buffer.name()).collect();
    let want: Vec<&str> = raster_specs::GRAD_TILED
        .bindings
        .iter()
        .map(|b| b.name)
        .collect();
    assert_eq!(order, want);

    // A kernel given another kernel's buffers is caught before anything is recorded (the
    // library's dispatches all go through `for_kernel`).
    let sum = gpu.kernel(&specs::FIT_SUM, &[]).unwrap();
    let x = by_name("Partials");
    let mse = softvk_fit::specs::MseViewsBindings {
        images: x,
        targets: x,
        partials: x,
    };
    let err = mse.for_kernel(&sum).err().expect("a mismatch");
    assert!(
        matches!(
            err,
            Error::Kernel {
                kernel: "fit_sum",
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("mse_views"), "{err}");
    let fit_sum = specs::FitSumBindings {
        values: x,
        outputs: x,
    };
    assert!(fit_sum.for_kernel(&sum).is_ok());
    assert!(bindings.for_kernel(&sum).is_err());
}
