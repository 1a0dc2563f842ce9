//! softvk inside a wgpu application, headless.
//!
//! The wgpu application owns the Vulkan instance, device, queue and buffers. softvk adopts the
//! raw handles ([`Host::softvk_context`]), borrows the application's buffers
//! ([`softvk::gpu::Context::import_buffer`]) and records its kernels into a wgpu command
//! encoder's raw Vulkan command buffer ([`App::encode_softvk`]); wgpu submits.
//!
//! One frame is one `queue.submit` of three command buffers, in this order:
//! 1. a WGSL compute pass that writes the data ("deform the vertices");
//! 2. softvk's work ([`SoftvkStage::record`]), between two [`softvk::gpu::Recorder::full_barrier`]s;
//! 3. a WGSL render pass that draws one point per vertex with softvk's output as a vertex
//!    attribute, into an image that is copied to a readback buffer.
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
//! exit barrier makes softvk's writes visible to the draw pass: wgpu sees `scanned` go from
//! "vertex buffer" last frame to "vertex buffer" this frame and records no barrier for it, and
//! softvk's own barriers after each dispatch reach compute and transfer work only, not the
//! vertex-input stage.
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

use softvk::gpu::{Context, Counters, Recorder};
use wgpu::hal::api::Vulkan;

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
    /// Negative control: softvk's writes are not made visible to the draw pass.
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
    /// Sets everything up for buffers of `n` `u32`s. All setup (wgpu's buffer initialization,
    /// softvk's pipelines and scratch) is done when this returns.
    pub fn new(n: u32, validation: bool) -> Result<Self, HostError> {
        let host = Host::new(validation)?;
        let scene = Scene::new(&host.device, n);
        // SAFETY: `App` drops the context (and the stage made from it) before the host (field
        // order), after waiting for the device (`Drop for App`); softvk's conveniences that
        // submit are never called.
        let ctx = unsafe { host.softvk_context() }?;
        // SAFETY: `ctx` was adopted from the device `scene` was made on; the scene outlives the
        // stage (field order) and every frame waits for its work.
        let stage = unsafe { SoftvkStage::new(&ctx, &scene) }?;
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

    /// Elements per frame.
    pub fn len(&self) -> u32 {
        self.scene.len()
    }

    /// Whether a frame has no element.
    pub fn is_empty(&self) -> bool {
        self.scene.is_empty()
    }

    /// softvk's own submissions and staging copies so far.
    pub fn softvk_counters(&self) -> Counters {
        self.ctx.counters()
    }

    /// Runs frame `frame`: deform (wgpu) → softvk → draw (wgpu), in one `queue.submit`, then
    /// waits and returns the drawn value of every vertex.
    pub fn frame(&self, frame: u32, barriers: Barriers) -> Result<Vec<u32>, HostError> {
        let device = &self.host.device;
        self.scene.set_frame(&self.host.queue, frame);
        let deform = self.scene.encode_deform(device);
        let softvk = self.encode_softvk(barriers)?;
        let draw = self.scene.encode_draw(device);
        self.host.queue.submit([deform, softvk, draw]);
        self.scene.read_result(device)
    }

    /// A frame whose producer is a host's own raw Vulkan command instead of the WGSL deform
    /// pass: `vkCmdFillBuffer` sets every element of `deformed` to `value`, recorded into a wgpu
    /// encoder's raw command buffer; then softvk and the draw pass as in [`App::frame`], in one
    /// `queue.submit`. It exists for the negative control: the validation layer of Debian 12
    /// (1.3.239) reports hazards between raw-recorded command buffers and softvk's, but in every
    /// variant tried it reported none against accesses recorded by wgpu's own passes (README,
    /// "softvk in a wgpu application").
    pub fn frame_from_raw_producer(
        &self,
        value: u32,
        barriers: Barriers,
    ) -> Result<Vec<u32>, HostError> {
        let device = &self.host.device;
        // The draw pass reads the vertex count and image size from the frame's parameters.
        self.scene.set_frame(&self.host.queue, 0);
        let mut producer = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("raw producer"),
        });
        let deformed = self.scene.raw_deformed()?;
        let bytes = 4 * u64::from(self.scene.len());
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
                    .cmd_fill_buffer(cmd, deformed, 0, bytes, value);
                Ok(())
            })
        }?;
        let softvk = self.encode_softvk(barriers)?;
        let draw = self.scene.encode_draw(device);
        self.host.queue.submit([producer.finish(), softvk, draw]);
        self.scene.read_result(device)
    }

    /// softvk's command buffer: a wgpu encoder used only through its raw Vulkan command buffer,
    /// with softvk's work ([`SoftvkStage::record`]) between two full barriers.
    pub fn encode_softvk(&self, barriers: Barriers) -> Result<wgpu::CommandBuffer, HostError> {
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
                self.stage.record(&mut rec)?;
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

/// The CPU twin of a frame.
pub mod cpu {
    /// The deform pass (`shaders/deform.wgsl`).
    pub fn deform(n: u32, frame: u32) -> Vec<u32> {
        (0..n)
            .map(|i| (i.wrapping_mul(2_654_435_761) ^ frame.wrapping_mul(2_654_435_769)) >> 20)
            .collect()
    }

    /// softvk's work: an exclusive prefix sum, wrapping.
    pub fn softvk(deformed: &[u32]) -> Vec<u32> {
        deformed
            .iter()
            .scan(0u32, |acc, &v| {
                let before = *acc;
                *acc = acc.wrapping_add(v);
                Some(before)
            })
            .collect()
    }

    /// The draw pass (`shaders/draw.wgsl`): the value drawn for each vertex.
    pub fn draw(deformed: &[u32], scanned: &[u32]) -> Vec<u32> {
        deformed
            .iter()
            .zip(scanned)
            .map(|(&d, &s)| s.wrapping_mul(2).wrapping_add(d))
            .collect()
    }

    /// The whole frame.
    pub fn frame(n: u32, frame: u32) -> Vec<u32> {
        let deformed = deform(n, frame);
        draw(&deformed, &softvk(&deformed))
    }
}
