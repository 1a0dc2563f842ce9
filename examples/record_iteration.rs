//! A fitting loop as a host engine would write it with softvk's public, record-only stages:
//! each submission is one command buffer that *this program* allocates, begins, ends and
//! submits; softvk only records into it. Every iteration recorded in it deforms an icosphere,
//! renders its silhouettes with guarded binning (no read-back: the count gates the rest on the
//! GPU), takes the silhouette loss, runs the backward and steps Adam. Losses are read once per
//! submission of `K` iterations, and softvk's own submission counter shows it made none.
//!
//! Run: `cargo run --release --example record_iteration`.

use ash::vk;
use softvk::camera::{Camera, Projection};
use softvk::fit::{Adam, AdamOptions, Deform, GradOut, SilhouetteLoss};
use softvk::gpu::gate::IterationGate;
use softvk::gpu::{Context, ContextOptions, MemoryKind, Recorder};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::backward::GradBuffers;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::{Alpha, Dist, RasterSettings};

/// Iterations per submission, and submissions.
const K: u32 = 10;
const SUBMISSIONS: u32 = 5;
const TILE: u32 = 8;

fn main() -> softvk::Result<()> {
    let ctx = Context::new(&ContextOptions::from_env())?;
    let cams: Vec<Camera> = (0..8)
        .map(|i| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(2.732, 30.0, 45.0 * f64::from(i))
        })
        .collect();
    let settings = RasterSettings {
        width: 32,
        height: 32,
        sigma: 1e-4,
        ..RasterSettings::default()
    };
    let renderer = Renderer::new(&ctx)?;
    // The target: a box's hard silhouettes.
    let hard = RasterSettings {
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..settings
    };
    let target = Mesh::cuboid([0.35, 0.25, 0.3]);
    let targets = renderer.render_silhouettes(&ctx, &target, &cams, &hard, Method::Brute)?;

    // Setup (conveniences are fine here: nothing runs per frame yet).
    // The deformation needs every template coordinate nonzero: turn the sphere a little.
    let mut template = Mesh::icosphere(2);
    let turn = glam::Mat3::from_euler(glam::EulerRot::XYZ, 0.31, 0.47, 0.13);
    for p in &mut template.positions {
        *p = (turn * glam::Vec3::from(*p) * 0.5).to_array();
    }
    let mut scene = renderer.prepare(&ctx, &template, &cams, &Lighting::unlit(), &settings)?;
    scene.set_silhouette_only(true);
    let deform = Deform::new(&ctx, &template.positions)?;
    let params = ctx.create_buffer("params", 4 * deform.param_count(), MemoryKind::Device)?;
    let d_params = ctx.create_buffer("d_params", 4 * deform.param_count(), MemoryKind::Device)?;
    let adam = Adam::new(
        &ctx,
        deform.param_count(),
        AdamOptions {
            lr: 0.01,
            betas: (0.5, 0.99),
            ..AdamOptions::default()
        },
    )?;
    let views = cams.len() as u32;
    let sil = SilhouetteLoss::new(&ctx, views, settings.width, settings.height)?;
    let target_buf = ctx.upload_buffer("targets", &targets)?;
    ctx.submit_and_wait(|rec| {
        rec.fill(params.whole(), 0);
        adam.record_reset(rec);
        deform.record_forward(rec, params.whole(), scene.positions().whole())
    })?;
    // The capacity: the template's entries and room to grow.
    let total = renderer.count_entries(&ctx, &scene, TILE)?;
    let bins = renderer.reserve_guarded(&ctx, &scene, TILE, 2 * total)?;
    let mut grads = GradBuffers::guarded(&ctx, &scene, &bins)?;
    grads.set_alpha_only(true);
    let io = grads.io();
    let mut gate = IterationGate::new(&ctx)?;

    // The host's command pool and fence.
    let device = ctx.device();
    let (queue, family) = ctx.queue();
    // SAFETY: plain object creation on the context's device; destroyed at the end.
    let (pool, fence) = unsafe {
        (
            device
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(family)
                        .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER),
                    None,
                )
                .expect("command pool"),
            device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .expect("fence"),
        )
    };
    // SAFETY: one primary command buffer of that pool.
    let cmd = unsafe {
        device.allocate_command_buffers(
            &vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .command_buffer_count(1),
        )
    }
    .expect("command buffer")[0];

    for submission in 0..SUBMISSIONS {
        let before = ctx.counters();
        // SAFETY: the command buffer is not pending (the last submission was waited for).
        unsafe {
            device
                .begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())
                .expect("begin");
        }
        {
            // SAFETY: `cmd` is begun, of the context's queue family, recorded only here.
            let mut rec = unsafe { Recorder::new(&ctx, cmd) };
            gate.reset();
            for it in submission * K + 1..=(submission + 1) * K {
                deform.record_forward(&mut rec, params.whole(), scene.positions().whole())?;
                renderer.record_forward_guarded(
                    &mut rec,
                    &scene,
                    &bins,
                    &mut gate,
                    it,
                    |rec, binned| {
                        sil.record(
                            rec,
                            scene.output().whole(),
                            target_buf.whole(),
                            Some(GradOut::write(io.upstream)),
                        )?;
                        renderer.grad_kernels().record(rec, &binned, &grads, &io)?;
                        deform.record_backward(
                            rec,
                            params.whole(),
                            io.positions,
                            d_params.whole(),
                        )?;
                        adam.record_step(rec, params.whole(), d_params.whole(), it)
                    },
                )?;
            }
            // The host reads the loss after the fence: make the writes visible to it.
            rec.full_barrier();
        }
        // SAFETY: recorded above; the fence is unsignalled (reset after every wait).
        unsafe {
            device.end_command_buffer(cmd).expect("end");
            let cmds = [cmd];
            device
                .queue_submit(
                    queue,
                    &[vk::SubmitInfo::default().command_buffers(&cmds)],
                    fence,
                )
                .expect("submit");
            device
                .wait_for_fences(&[fence], true, u64::MAX)
                .expect("wait");
            device.reset_fences(&[fence]).expect("reset fence");
        }
        let during = ctx.counters();
        // Reading the status and the loss: softvk's convenience read-backs, once per K.
        let status = gate.read(&ctx)?;
        if let Some((it, total)) = status.stopped {
            // A real loop would reserve `total` with headroom and re-run from `it`.
            eprintln!("iteration {it} needed {total} entries; grow the capacity and re-run");
            break;
        }
        println!(
            "iterations {:>3}: 1 - IoU {:.4}, {} entries; softvk's own submissions while \
             recording and running them: {}",
            (submission + 1) * K,
            sil.read_loss(&ctx)?,
            status.last_total,
            during.submissions - before.submissions,
        );
    }
    // SAFETY: the last submission was waited for.
    unsafe {
        device.destroy_fence(fence, None);
        device.destroy_command_pool(pool, None);
    }
    // With SOFTVK_VALIDATION=1, any message of the validation layer is an error here.
    ctx.check_validation()
}
