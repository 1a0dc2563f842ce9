//! The record-only public pipeline: a fit iteration's forward, loss and backward recorded into
//! one command buffer the caller allocated, begun and submits, over buffers the caller owns
//! (imported without ownership), with softvk making no submission and no staging copy of its
//! own — and the same bits as the submit-and-wait conveniences.

mod common;

use ash::vk;
use softvk::camera::{Camera, Projection};
use softvk::fit::{GradOut, SilhouetteLoss};
use softvk::gpu::gate::IterationGate;
use softvk::gpu::{Buffer, Context, MemoryKind, Recorder};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::backward::{GradBuffers, GradIo};
use softvk::raster::gpu::{GpuScene, Method, Renderer};
use softvk::raster::settings::{RasterSettings, Rgb};
use softvk::raster::setup::VertexLayout;

const TILE: u32 = 8;

fn cameras() -> Vec<Camera> {
    [10.0, 100.0, 220.0]
        .iter()
        .map(|&az| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(2.732, 25.0, az)
        })
        .collect()
}

fn settings() -> RasterSettings {
    RasterSettings {
        width: 24,
        height: 24,
        rgb: Rgb::Hard,
        ..RasterSettings::default()
    }
}

/// The mesh rendered (an icosphere moved off-centre) and the target silhouettes (a box).
fn inputs(ctx: &Context) -> (Mesh, Vec<f32>) {
    let mut mesh = Mesh::icosphere(1);
    for p in &mut mesh.positions {
        *p = [0.45 * p[0] + 0.05, 0.4 * p[1] - 0.03, 0.5 * p[2]];
    }
    let targets = Renderer::new(ctx)
        .unwrap()
        .render_silhouettes(
            ctx,
            &Mesh::cuboid([0.35, 0.25, 0.3]),
            &cameras(),
            &settings(),
            Method::Brute,
        )
        .unwrap();
    (mesh, targets)
}

/// A command buffer of the caller's own pool, begun.
struct HostCommands<'a> {
    ctx: &'a Context,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
}

impl<'a> HostCommands<'a> {
    fn begin(ctx: &'a Context) -> Self {
        let device = ctx.device();
        let (_, family) = ctx.queue();
        // SAFETY: plain object creation on the context's device.
        unsafe {
            let pool = device
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default().queue_family_index(family),
                    None,
                )
                .unwrap();
            let cmd = device
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(pool)
                        .command_buffer_count(1),
                )
                .unwrap()[0];
            device
                .begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())
                .unwrap();
            let fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .unwrap();
            Self {
                ctx,
                pool,
                cmd,
                fence,
            }
        }
    }

    /// Ends, submits on the context's queue (the caller's submission, not softvk's) and waits.
    fn submit_and_wait(&self) {
        let device = self.ctx.device();
        let (queue, _) = self.ctx.queue();
        // SAFETY: the command buffer was begun above and recorded by this thread only; the
        // host-read barrier makes the results visible to the read-backs below.
        unsafe {
            let barrier = [vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
                .dst_access_mask(vk::AccessFlags::HOST_READ | vk::AccessFlags::MEMORY_READ)];
            device.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS | vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &barrier,
                &[],
                &[],
            );
            device.end_command_buffer(self.cmd).unwrap();
            let cmds = [self.cmd];
            device
                .queue_submit(
                    queue,
                    &[vk::SubmitInfo::default().command_buffers(&cmds)],
                    self.fence,
                )
                .unwrap();
            device
                .wait_for_fences(&[self.fence], true, u64::MAX)
                .unwrap();
        }
    }
}

impl Drop for HostCommands<'_> {
    fn drop(&mut self) {
        // SAFETY: waited for above (or never submitted).
        unsafe {
            self.ctx.device().destroy_fence(self.fence, None);
            self.ctx.device().destroy_command_pool(self.pool, None);
        }
    }
}

/// The host's own buffer (made here with ash, as an engine would) and softvk's borrowed view
/// of it. softvk never frees it; the returned guard destroys it after the `Buffer` is gone.
struct HostBuffer<'a> {
    ctx: &'a Context,
    raw: vk::Buffer,
    memory: vk::DeviceMemory,
    borrowed: Option<Buffer>,
}

impl<'a> HostBuffer<'a> {
    fn new(ctx: &'a Context, name: &str, bytes: u64) -> Self {
        let device = ctx.device();
        // SAFETY: plain buffer and memory creation on the context's device.
        unsafe {
            let raw = device
                .create_buffer(
                    &vk::BufferCreateInfo::default().size(bytes).usage(
                        vk::BufferUsageFlags::STORAGE_BUFFER
                            | vk::BufferUsageFlags::TRANSFER_SRC
                            | vk::BufferUsageFlags::TRANSFER_DST,
                    ),
                    None,
                )
                .unwrap();
            let req = device.get_buffer_memory_requirements(raw);
            let props = ctx
                .instance()
                .get_physical_device_memory_properties(ctx.physical_device());
            let type_index = (0..props.memory_type_count)
                .find(|&i| {
                    req.memory_type_bits & (1 << i) != 0
                        && props.memory_types[i as usize]
                            .property_flags
                            .contains(vk::MemoryPropertyFlags::DEVICE_LOCAL)
                })
                .unwrap();
            let memory = device
                .allocate_memory(
                    &vk::MemoryAllocateInfo::default()
                        .allocation_size(req.size)
                        .memory_type_index(type_index),
                    None,
                )
                .unwrap();
            device.bind_buffer_memory(raw, memory, 0).unwrap();
            let borrowed = Some(ctx.import_buffer(raw, bytes, name));
            Self {
                ctx,
                raw,
                memory,
                borrowed,
            }
        }
    }

    fn take(&mut self) -> Buffer {
        self.borrowed.take().expect("taken once")
    }

    fn buffer(&self) -> &Buffer {
        self.borrowed.as_ref().expect("not taken")
    }
}

impl Drop for HostBuffer<'_> {
    fn drop(&mut self) {
        drop(self.borrowed.take());
        // SAFETY: every submission using it was waited for; softvk's view is gone.
        unsafe {
            self.ctx.device().destroy_buffer(self.raw, None);
            self.ctx.device().free_memory(self.memory, None);
        }
    }
}

/// One iteration through the conveniences: forward (exact count, its own submissions), the
/// loss's upstream read back, backward. The reference for the recorded iteration.
fn convenience_iteration(
    ctx: &Context,
    renderer: &Renderer,
    scene: &mut GpuScene,
    sil: &SilhouetteLoss,
    targets: &Buffer,
) -> (f32, Vec<[f64; 3]>) {
    let binned = renderer
        .run(ctx, scene, Method::Tiled { tile: TILE })
        .unwrap()
        .binned();
    let scene = binned.scene();
    let mut gb = GradBuffers::new(ctx, &binned).unwrap();
    gb.set_alpha_only(true);
    ctx.submit_and_wait(|rec| {
        sil.record(
            rec,
            scene.output().whole(),
            targets.whole(),
            Some(GradOut::write(gb.io().upstream)),
        )
    })
    .unwrap();
    let loss = sil.read_loss(ctx).unwrap();
    ctx.submit_and_wait(|rec| renderer.grad_kernels().record(rec, &binned, &gb, &gb.io()))
        .unwrap();
    let g = renderer
        .grad_kernels()
        .finish(ctx, scene, &gb, &gb.io(), false)
        .unwrap();
    (loss, g.positions)
}

#[test]
fn a_fit_iteration_records_into_the_callers_command_buffer_over_the_callers_buffers() {
    let Some(gpu) = common::gpu() else { return };
    let ctx: &Context = &gpu;
    let renderer = Renderer::new(ctx).unwrap();
    let (mesh, target_alphas) = inputs(ctx);
    let s = settings();
    let cams = cameras();
    let views = cams.len() as u32;
    let targets = ctx.upload_buffer("targets", &target_alphas).unwrap();
    let sil = SilhouetteLoss::new(ctx, views, s.width, s.height).unwrap();

    // The reference: the conveniences on an ordinary scene.
    let mut reference = renderer
        .prepare(ctx, &mesh, &cams, &Lighting::unlit(), &s)
        .unwrap();
    reference.set_silhouette_only(true);
    let (want_loss, want_grads) =
        convenience_iteration(ctx, &renderer, &mut reference, &sil, &targets);
    assert!(want_loss > 0.0 && want_grads.iter().flatten().any(|&g| g != 0.0));

    // The host's vertex buffer: interleaved position + normal (6 floats), after a 2-float
    // header, as an engine's would be; and the host's gradient outputs.
    let layout = VertexLayout {
        offset: 2,
        stride: 6,
    };
    let nv = mesh.vertex_count();
    let mut interleaved = vec![0.0f32; 2 + 6 * nv];
    for (v, p) in mesh.positions.iter().enumerate() {
        interleaved[2 + 6 * v..2 + 6 * v + 3].copy_from_slice(p);
        interleaved[2 + 6 * v + 3..2 + 6 * v + 6].copy_from_slice(&[9.0, -9.0, 9.0]);
    }
    let mut host_vertices = HostBuffer::new(ctx, "host vertices", 4 * interleaved.len() as u64);
    ctx.write_buffer(host_vertices.buffer(), 0, &interleaved)
        .unwrap();
    let mut scene = renderer
        .prepare(ctx, &mesh, &cams, &Lighting::unlit(), &s)
        .unwrap();
    scene.set_silhouette_only(true);
    scene.bind_positions(host_vertices.take(), layout).unwrap();
    assert!(!scene.positions().is_owned());
    let [upstream_bytes, position_bytes, color_bytes] = GradIo::sizes(&scene);
    let host_upstream = HostBuffer::new(ctx, "host upstream", upstream_bytes);
    let host_positions = HostBuffer::new(ctx, "host d_positions", position_bytes);
    let host_colors = HostBuffer::new(ctx, "host d_colors", color_bytes);

    // Sizing: the capacity from one count (a convenience, before the frames).
    let total = renderer.count_entries(ctx, &scene, TILE).unwrap();
    let bins = renderer
        .reserve_guarded(ctx, &scene, TILE, total + total / 4)
        .unwrap();
    let mut gb = GradBuffers::guarded(ctx, &scene, &bins).unwrap();
    gb.set_alpha_only(true);
    let mut gate = IterationGate::new(ctx).unwrap();
    let io = GradIo {
        upstream: host_upstream.buffer().whole(),
        positions: host_positions.buffer().whole(),
        colors: host_colors.buffer().whole(),
    };

    // The iteration, recorded into the caller's command buffer and submitted by the caller.
    let before = ctx.counters();
    let commands = HostCommands::begin(ctx);
    {
        // SAFETY: `commands.cmd` is a begun primary command buffer of the context's queue
        // family, recorded only here.
        let mut rec = unsafe { Recorder::new(ctx, commands.cmd) };
        gate.reset();
        renderer
            .record_forward_guarded(&mut rec, &scene, &bins, &mut gate, 1, |rec, binned| {
                sil.record(
                    rec,
                    scene.output().whole(),
                    targets.whole(),
                    Some(GradOut::write(io.upstream)),
                )?;
                renderer.grad_kernels().record(rec, &binned, &gb, &io)
            })
            .unwrap();
    }
    commands.submit_and_wait();
    let after = ctx.counters();
    assert_eq!(
        (after.submissions, after.staging_copies),
        (before.submissions, before.staging_copies),
        "softvk submitted or copied through staging while recording"
    );

    // The same bits as the conveniences, read from the host's buffers.
    let status = gate.read(ctx).unwrap();
    assert_eq!(status.stopped, None, "the capacity holds the entries");
    assert_eq!(status.last_total, total);
    assert_eq!(sil.read_loss(ctx).unwrap().to_bits(), want_loss.to_bits());
    let got: Vec<[f32; 3]> = ctx.read_buffer(host_positions.buffer(), 0, nv).unwrap();
    let got: Vec<[f64; 3]> = got.iter().map(|g| g.map(f64::from)).collect();
    assert!(got == want_grads, "the recorded backward differs");
    drop(scene);
}

#[test]
fn a_capacity_too_small_stops_the_gated_work_and_says_so() {
    let Some(gpu) = common::gpu() else { return };
    let ctx: &Context = &gpu;
    let renderer = Renderer::new(ctx).unwrap();
    let (mesh, _) = inputs(ctx);
    let scene = renderer
        .prepare(ctx, &mesh, &cameras(), &Lighting::unlit(), &settings())
        .unwrap();
    let total = renderer.count_entries(ctx, &scene, TILE).unwrap();
    let bins = renderer
        .reserve_guarded(ctx, &scene, TILE, total - 1)
        .unwrap();
    let mut gate = IterationGate::new(ctx).unwrap();
    // A marker the gated region would overwrite if it ran.
    let image = scene.output();
    let n = (image.size() / 16) as usize;
    ctx.write_buffer(image, 0, &vec![[7.0f32; 4]; n]).unwrap();
    let mut ran = false;
    ctx.submit_and_wait(|rec| {
        gate.reset();
        renderer.record_forward_guarded(rec, &scene, &bins, &mut gate, 5, |_, _| {
            ran = true; // recorded (and gated), not run
            Ok(())
        })
    })
    .unwrap();
    assert!(ran);
    let status = gate.read(ctx).unwrap();
    assert_eq!(status.stopped, Some((5, total)));
    let image: Vec<[f32; 4]> = ctx.read_buffer(scene.output(), 0, n).unwrap();
    assert!(image.iter().all(|p| *p == [7.0; 4]), "gated work ran");
    // Bins reserved for another scene's size are refused before anything is recorded (a
    // scene with no bins at all does not compile).
    let other = renderer
        .prepare(ctx, &mesh, &cameras()[..1], &Lighting::unlit(), &settings())
        .unwrap();
    let err = ctx
        .submit_and_wait(|rec| {
            renderer.record_forward_guarded(rec, &other, &bins, &mut gate, 1, |_, _| Ok(()))
        })
        .unwrap_err();
    assert!(matches!(err, softvk::Error::Input(_)), "{err}");
}

#[test]
fn positions_bound_with_a_stride_render_as_packed_ones() {
    let Some(gpu) = common::gpu() else { return };
    let ctx: &Context = &gpu;
    let renderer = Renderer::new(ctx).unwrap();
    let (mesh, _) = inputs(ctx);
    let s = RasterSettings {
        rgb: Rgb::Softmax,
        ..settings()
    };
    let light = Lighting::default();
    let method = Method::Tiled { tile: TILE };
    let mut packed = renderer
        .prepare(ctx, &mesh, &cameras(), &light, &s)
        .unwrap();
    let n = (s.width * s.height) as usize * cameras().len();
    let upstream: Vec<[f32; 4]> = (0..n)
        .map(|i| [0.3, -0.2, 0.1, if i % 3 == 0 { 1.0 } else { -0.5 }])
        .collect();
    let binned = renderer.run(ctx, &mut packed, method).unwrap().binned();
    let want_grads = renderer.backward(ctx, &binned, &upstream, true).unwrap();
    let want = packed.read_frames(ctx).unwrap();
    let layout = VertexLayout {
        offset: 4,
        stride: 5,
    };
    let mut floats = vec![f32::NAN; 4 + 5 * mesh.vertex_count()];
    for (v, p) in mesh.positions.iter().enumerate() {
        floats[4 + 5 * v..4 + 5 * v + 3].copy_from_slice(p);
    }
    let mut strided = renderer
        .prepare(ctx, &mesh, &cameras(), &light, &s)
        .unwrap();
    let buffer = ctx.upload_buffer("strided", &floats).unwrap();
    strided.bind_positions(buffer, layout).unwrap();
    let binned = renderer.run(ctx, &mut strided, method).unwrap().binned();
    let got_grads = renderer.backward(ctx, &binned, &upstream, true).unwrap();
    assert!(
        got_grads == want_grads,
        "a strided vertex buffer differentiates differently"
    );
    let got = strided.read_frames(ctx).unwrap();
    assert!(got == want, "a strided vertex buffer renders differently");
    // Too small for the layout, or a stride without room for xyz: refused, nothing changed.
    let small = ctx.create_buffer("small", 64, MemoryKind::Device).unwrap();
    let err = strided.bind_positions(small, layout).unwrap_err();
    assert!(matches!(err, softvk::Error::BufferTooSmall { .. }), "{err}");
    let two = ctx
        .create_buffer("two", 1 << 16, MemoryKind::Device)
        .unwrap();
    let err = strided
        .bind_positions(
            two,
            VertexLayout {
                offset: 0,
                stride: 2,
            },
        )
        .unwrap_err();
    assert!(matches!(err, softvk::Error::Input(_)), "{err}");
    assert_eq!(strided.position_layout(), layout);
}
