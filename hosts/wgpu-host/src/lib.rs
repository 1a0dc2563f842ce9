//! softvk inside a wgpu application, headless.
//!
//! The wgpu application owns the Vulkan instance, device, queue and buffers. softvk adopts the
//! raw handles ([`Host::softvk_context`]), borrows the application's buffers
//! ([`softvk::gpu::Context::import_buffer`]) and records its kernels into a wgpu command
//! encoder's raw Vulkan command buffer ([`App::encode_softvk`]); wgpu submits.
//!
//! One frame is one `queue.submit` of three command buffers, in this order:
//! 1. a WGSL compute pass that deforms the mesh into the application's vertex buffer;
//! 2. softvk's work ([`SoftvkStage::record`]), between two [`softvk::gpu::Recorder::full_barrier`]s:
//!    the silhouettes of those vertices (guarded binning, no read-back) and their backward
//!    against the application's upstream gradient, into the application's buffers;
//! 3. a WGSL compute pass that reads softvk's silhouettes and gradients, and a copy of what it
//!    wrote to a readback buffer.
//!
//! Why three encoders and not one: wgpu 30 refuses to mix its own encoding API with raw
//! encoding (`CommandEncoder::as_hal_mut`) in one encoder; it panics with "Mixing the wgpu
//! encoding API with the raw encoding API is not permitted" (wgpu-core `EncodingApi::set`,
//! gfx-rs/wgpu#8373, since wgpu 28): since gfx-rs/wgpu#8220 wgpu encodes passes only when the
//! encoder finishes, so raw commands could not land between them anyway. Command buffers of one
//! submission run in submission order, so softvk's commands still sit between the two passes.
//!
//! Why softvk brackets itself with full barriers: wgpu inserts barriers only for the uses it
//! tracks, and a raw encoder's uses are invisible to it. The entry barrier makes the deform
//! pass's writes visible to softvk (and orders softvk's writes after last frame's reads). The
//! exit barrier makes softvk's writes visible to the consume pass (wgpu sees `image` and
//! `d_positions` only as read-only storage, frame after frame, and records no barrier for them).
//!
//! Synchronization validation: wgpu-hal 30 turns the layer's synchronization validation on
//! (`VkValidationFeaturesEXT`) whenever it enables the layer. The Khronos layer of Debian 12
//! (1.3.239) then checks hazards inside each command buffer only; hazards between command
//! buffers and between submissions, which is where softvk meets wgpu here, are checked only with
//! its `VALIDATION_CHECK_ENABLE_SYNCHRONIZATION_VALIDATION_QUEUE_SUBMIT` switch, which
//! `VkValidationFeaturesEXT` cannot express and wgpu does not set: it is read from
//! `VK_LAYER_ENABLES` ([`LAYER_ENABLES`]) when the layer loads.

mod host;
mod scene;
mod stage;
pub mod validation;

pub use host::{Host, HostError};
pub use scene::Scene;
pub use stage::SoftvkStage;

use softvk::camera::{Camera, Projection};
use softvk::gpu::{Context, Counters, Recorder};
use softvk::mesh::Mesh;
use softvk::raster::settings::RasterSettings;
use wgpu::hal::api::Vulkan;

/// The mesh the application deforms: an icosphere(2) of radius 0.5 (162 vertices, 320 faces).
pub fn rest_mesh() -> Mesh {
    let mut mesh = Mesh::icosphere(2);
    for p in &mut mesh.positions {
        *p = p.map(|c| 0.5 * c);
    }
    mesh
}

/// The two views softvk renders.
pub fn cameras() -> Vec<Camera> {
    [(25.0, 30.0), (-10.0, 150.0)]
        .iter()
        .map(|&(elevation, azimuth)| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(2.732, elevation, azimuth)
        })
        .collect()
}

/// Silhouettes of 32×32 pixels, SoftRas's default σ.
pub fn settings() -> RasterSettings {
    RasterSettings {
        width: 32,
        height: 32,
        ..RasterSettings::default()
    }
}

/// The application's dL/d(image): RGBA per pixel of every view, alpha only (silhouettes).
pub fn upstream() -> Vec<[f32; 4]> {
    let s = settings();
    (0..(s.width * s.height) as usize * cameras().len())
        .map(|i| [0.0, 0.0, 0.0, (i * 7 % 11) as f32 / 11.0 - 0.4])
        .collect()
}

/// What the consume pass read of one frame: every pixel's alpha (view-major), and
/// dL/d(vertex positions).
pub type FrameResult = (Vec<f32>, Vec<[f32; 3]>);

/// True when the environment says explicitly that there is no Vulkan device (`SOFTVK_NO_GPU=1`),
/// as in softvk's own GPU tests: then GPU tests skip, and say so; otherwise a missing device
/// fails them.
pub fn no_gpu() -> bool {
    std::env::var("SOFTVK_NO_GPU").is_ok_and(|v| v == "1")
}

/// Validation is on unless `SOFTVK_VALIDATION=0`, as in softvk's own tests.
pub fn validation_wanted() -> bool {
    std::env::var("SOFTVK_VALIDATION").map_or(true, |v| v.trim() != "0")
}

/// `VK_LAYER_ENABLES` that turns on the Khronos layer's synchronization validation between
/// command buffers and submissions (`VALIDATION_CHECK_ENABLE_SYNCHRONIZATION_VALIDATION_QUEUE_SUBMIT`,
/// off by default in layer 1.3.239) besides synchronization validation itself. The layer reads it
/// once, when it loads, so it must be in the environment before the first Vulkan instance:
/// set it outside the process, or at the start of `main` before any thread exists.
pub const LAYER_ENABLES: &str = if cfg!(windows) {
    "VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT;VALIDATION_CHECK_ENABLE_SYNCHRONIZATION_VALIDATION_QUEUE_SUBMIT"
} else {
    "VK_VALIDATION_FEATURE_ENABLE_SYNCHRONIZATION_VALIDATION_EXT:VALIDATION_CHECK_ENABLE_SYNCHRONIZATION_VALIDATION_QUEUE_SUBMIT"
};

/// Whether `VK_LAYER_ENABLES` asks for synchronization validation between command buffers and
/// submissions ([`LAYER_ENABLES`]).
pub fn submit_time_sync_validation_requested() -> bool {
    std::env::var("VK_LAYER_ENABLES").is_ok_and(|v| {
        v.contains("VALIDATION_CHECK_ENABLE_SYNCHRONIZATION_VALIDATION_QUEUE_SUBMIT")
    })
}

/// `VK_LAYER_ENABLES` as it is, with [`LAYER_ENABLES`] added.
pub fn layer_enables_with_submit_time_sync_validation() -> String {
    match std::env::var("VK_LAYER_ENABLES") {
        Ok(v) if !v.trim().is_empty() => format!(
            "{v}{}{LAYER_ENABLES}",
            if cfg!(windows) { ";" } else { ":" }
        ),
        _ => LAYER_ENABLES.to_string(),
    }
}

/// Which of softvk's two bracketing barriers a frame records. Leaving one out is wrong: it
/// exists only for negative controls that show what synchronization validation reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Barriers {
    /// The correct frame: a full barrier before softvk's work and one after it.
    Both,
    /// Negative control: the producer's writes are not made visible to softvk.
    OmitEntry,
    /// Negative control: softvk's writes are not made visible to the consume pass.
    OmitExit,
}

/// The whole application: wgpu host, the application's scene, softvk adopted on wgpu's device.
/// Fields drop in order: softvk's objects, then softvk's context, then wgpu's buffers, then
/// wgpu's device and instance.
pub struct App {
    stage: SoftvkStage,
    ctx: Context,
    scene: Scene,
    host: Host,
}

impl App {
    /// Sets everything up: wgpu's buffers (the rest mesh, the upstream gradient) and passes,
    /// softvk's pipelines and buffers. All setup is done when this returns.
    pub fn new(validation: bool) -> Result<Self, HostError> {
        let host = Host::new(validation)?;
        let mesh = rest_mesh();
        let scene = Scene::new(&host.device, &mesh.positions, &upstream())?;
        // SAFETY: `App` drops the context (and the stage made from it) before the host (field
        // order), after waiting for the device (`Drop for App`); softvk's conveniences submit
        // only during `SoftvkStage::new` (its uploads), from this thread, before any frame.
        let ctx = unsafe { host.softvk_context() }?;
        // SAFETY: `ctx` was adopted from the device `scene` was made on; nothing else submits
        // meanwhile; the scene outlives the stage (field order) and every frame waits for its
        // work.
        let stage = unsafe { SoftvkStage::new(&ctx, &scene, &mesh, &cameras(), &settings()) }?;
        // Flush wgpu's own setup (the zero-fills of `mapped_at_creation`) before any frame.
        host.queue.submit([]);
        host.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| HostError::Wgpu(format!("waiting for setup: {e}")))?;
        Ok(Self {
            stage,
            ctx,
            scene,
            host,
        })
    }

    /// The wgpu host.
    pub fn host(&self) -> &Host {
        &self.host
    }

    /// softvk's context (adopted from wgpu).
    pub fn softvk(&self) -> &Context {
        &self.ctx
    }

    /// Vertices per frame.
    pub fn len(&self) -> u32 {
        self.scene.len()
    }

    /// Whether a frame has no vertex.
    pub fn is_empty(&self) -> bool {
        self.scene.is_empty()
    }

    /// Whether every frame's (face, tile) entries fitted softvk's capacity (a read-back through
    /// softvk's conveniences: after the frames).
    pub fn capacity_held(&self) -> Result<bool, HostError> {
        self.stage.capacity_held(&self.ctx)
    }

    /// softvk's own submissions and staging copies so far.
    pub fn softvk_counters(&self) -> Counters {
        self.ctx.counters()
    }

    /// Runs frame `frame`: deform (wgpu) → softvk → consume (wgpu), in one `queue.submit`,
    /// then waits and returns what the consume pass read.
    pub fn frame(&self, frame: u32, barriers: Barriers) -> Result<FrameResult, HostError> {
        let device = &self.host.device;
        self.scene.set_frame(&self.host.queue, frame);
        let deform = self.scene.encode_deform(device);
        let softvk = self.encode_softvk(frame, barriers)?;
        let consume = self.scene.encode_consume(device);
        self.host.queue.submit([deform, softvk, consume]);
        self.scene.read_result(device)
    }

    /// A frame whose producer is a host's own raw Vulkan command instead of the WGSL deform
    /// pass: `vkCmdFillBuffer` sets every float of `vertices` to the bits `value`, recorded into
    /// a wgpu encoder's raw command buffer; then softvk and the consume pass as in
    /// [`App::frame`], in one `queue.submit`. It exists for the negative control: the validation layer of Debian 12
    /// (1.3.239) reports hazards between raw-recorded command buffers and softvk's, but in every
    /// variant tried it reported none against accesses recorded by wgpu's own passes (README,
    /// "softvk in a wgpu application").
    pub fn frame_from_raw_producer(
        &self,
        value: u32,
        barriers: Barriers,
    ) -> Result<FrameResult, HostError> {
        let device = &self.host.device;
        // The consume pass reads its sizes from the frame's parameters.
        self.scene.set_frame(&self.host.queue, 0);
        let mut producer = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("raw producer"),
        });
        let vertices = self.scene.raw_vertices()?;
        let bytes = 16 * u64::from(self.scene.len());
        // SAFETY: the raw command buffer is recording, of this device and of the queue family
        // `ctx` was adopted with, recorded only here; `deformed` is alive
        // (the scene outlives the frame, which waits) and has TRANSFER_DST usage (COPY_DST);
        // offset and size are multiples of 4 inside the buffer.
        unsafe {
            producer.as_hal_mut::<Vulkan, _, _>(|hal| -> Result<(), HostError> {
                let hal = hal.ok_or_else(|| {
                    HostError::Wgpu("the encoder has no Vulkan command buffer".into())
                })?;
                let cmd = hal.raw_handle();
                // Raw work is invisible to wgpu's barriers, so the producer orders itself after
                // earlier work (last frame's draw, wgpu's setup copies) as softvk does.
                Recorder::new(&self.ctx, cmd).full_barrier();
                self.ctx
                    .device()
                    .cmd_fill_buffer(cmd, vertices, 0, bytes, value);
                Ok(())
            })
        }?;
        let softvk = self.encode_softvk(0, barriers)?;
        let consume = self.scene.encode_consume(device);
        self.host.queue.submit([producer.finish(), softvk, consume]);
        self.scene.read_result(device)
    }

    /// softvk's command buffer: a wgpu encoder used only through its raw Vulkan command buffer,
    /// with softvk's work ([`SoftvkStage::record`]) between two full barriers.
    pub fn encode_softvk(
        &self,
        frame: u32,
        barriers: Barriers,
    ) -> Result<wgpu::CommandBuffer, HostError> {
        let mut encoder =
            self.host
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("softvk"),
                });
        // SAFETY: `as_hal_mut` hands us wgpu's open hal encoder; its raw command buffer is in the
        // recording state, of wgpu's queue family (which `ctx` was adopted with), and recorded
        // only here, on this thread. We leave it recording and outside any render pass, as we
        // found it. Everything softvk binds (its kernels, scratch, and the scene's buffers)
        // outlives the submission: `frame` waits for it.
        unsafe {
            encoder.as_hal_mut::<Vulkan, _, _>(|hal| -> Result<(), HostError> {
                let hal = hal.ok_or_else(|| {
                    HostError::Wgpu("the encoder has no Vulkan command buffer".into())
                })?;
                let mut rec = Recorder::new(&self.ctx, hal.raw_handle());
                if barriers != Barriers::OmitEntry {
                    rec.full_barrier();
                }
                self.stage.record(&mut rec, frame)?;
                if barriers != Barriers::OmitExit {
                    rec.full_barrier();
                }
                Ok(())
            })
        }?;
        Ok(encoder.finish())
    }
}

impl Drop for App {
    fn drop(&mut self) {
        // softvk's objects go first (field order); nothing of theirs may still be in flight.
        let _ = self.host.device.poll(wgpu::PollType::wait_indefinitely());
    }
}

/// The CPU twin of a frame: the deform pass in f32 as WGSL computes it, softvk's f64
/// reference renderer and backward (its twins) on the deformed vertices.
pub mod cpu {
    use softvk::lighting::Lighting;
    use softvk::raster::{reference, reference_grad};

    use super::{cameras, rest_mesh, settings, upstream};

    /// The deform pass (`shaders/deform.wgsl`).
    pub fn deform(rest: &[[f32; 3]], frame: u32) -> Vec<[f32; 3]> {
        let f = (frame % 4) as f32;
        let scale = [0.8 + 0.1 * f, 0.9, 0.85 - 0.05 * f];
        let shift = [0.04 * f, -0.03 * f, 0.0];
        rest.iter()
            .map(|p| std::array::from_fn(|k| p[k] * scale[k] + shift[k]))
            .collect()
    }

    /// softvk's work on `positions`: every pixel's alpha (view-major) and dL/d(positions).
    pub fn softvk(positions: &[[f32; 3]]) -> (Vec<f64>, Vec<[f64; 3]>) {
        let mut mesh = rest_mesh();
        mesh.positions = positions.to_vec();
        let s = settings();
        let alpha = cameras()
            .iter()
            .flat_map(|c| {
                reference::render(&mesh, c, &Lighting::unlit(), &s)
                    .expect("the twin renders")
                    .into_iter()
                    .map(|p| p[3])
            })
            .collect();
        let w: Vec<[f64; 4]> = upstream().iter().map(|p| p.map(f64::from)).collect();
        let grads = reference_grad::grad(&mesh, &cameras(), &Lighting::unlit(), &s, &w)
            .expect("the twin differentiates");
        (alpha, grads.positions)
    }

    /// The whole frame.
    pub fn frame(frame: u32) -> (Vec<f64>, Vec<[f64; 3]>) {
        softvk(&deform(&rest_mesh().positions, frame))
    }

    /// How far a frame's GPU result is from the twin's: the largest alpha difference, and the
    /// largest gradient difference relative to the twin's largest gradient (softvk's own tests
    /// hold f32 GPU results to 1e-3 of the f64 twin's scale).
    pub fn distance(got: &super::FrameResult, want: &(Vec<f64>, Vec<[f64; 3]>)) -> (f64, f64) {
        assert_eq!(got.0.len(), want.0.len(), "pixels");
        assert_eq!(got.1.len(), want.1.len(), "vertices");
        let alpha = got
            .0
            .iter()
            .zip(&want.0)
            .map(|(&g, &w)| (f64::from(g) - w).abs())
            .fold(0.0, f64::max);
        let scale = want.1.iter().flatten().fold(0.0f64, |m, w| m.max(w.abs()));
        let grads = got
            .1
            .iter()
            .flatten()
            .zip(want.1.iter().flatten())
            .map(|(&g, &w)| (f64::from(g) - w).abs())
            .fold(0.0, f64::max);
        (alpha, if scale > 0.0 { grads / scale } else { grads })
    }
}
