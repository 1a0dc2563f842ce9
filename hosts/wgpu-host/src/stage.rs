//! softvk's part of a frame: the one place that decides what softvk records.
//!
//! Today it is softvk's public exclusive scan over the application's `deformed` buffer into its
//! `scanned` buffer, a stand-in until softvk's renderer can bind host buffers. Rendering the
//! silhouette of the deformed vertices later replaces [`SoftvkStage::new`] (what softvk builds
//! and imports) and [`SoftvkStage::record`] (what it records) and nothing else: the host side
//! (device, encoders, barriers around softvk, submission, validation) stays as it is.

use softvk::gpu::{Buffer, Context, Recorder};
use softvk::primitives::{Scan, ScanScratch};
use wgpu::hal::api::Vulkan;

use crate::HostError;
use crate::scene::Scene;

/// softvk's kernels, its own scratch, and the application's buffers it borrows.
pub struct SoftvkStage {
    scan: Scan,
    scratch: ScanScratch,
    /// `Scene::deformed`, imported: softvk reads it.
    deformed: Buffer,
    /// `Scene::scanned`, imported: softvk writes it.
    scanned: Buffer,
    n: u64,
}

/// The raw `VkBuffer` behind a wgpu buffer.
///
/// # Safety
/// The handle is used only while `buffer` is alive, and never destroyed by the caller.
unsafe fn raw_buffer(buffer: &wgpu::Buffer) -> Result<ash::vk::Buffer, HostError> {
    // SAFETY: the guard borrows the buffer for this call; the caller keeps it alive for as long
    // as it uses the handle.
    unsafe {
        buffer
            .as_hal::<Vulkan>()
            .map(|b| b.raw_handle())
            .ok_or_else(|| HostError::Wgpu("the buffer is not on the Vulkan backend".into()))
    }
}

impl SoftvkStage {
    /// Builds softvk's pipelines and scratch on `ctx` (setup: no submission, no copy) and
    /// imports the scene's buffers without taking ownership.
    ///
    /// # Safety
    /// `ctx` was adopted from the device `scene`'s buffers were made on, and `scene` outlives
    /// the stage and every frame recorded with it.
    pub unsafe fn new(ctx: &Context, scene: &Scene) -> Result<Self, HostError> {
        let n = u64::from(scene.len());
        // SAFETY: both wgpu buffers are storage buffers of `ctx`'s device with 4 n bytes bound
        // (Scene::new), and they outlive the stage (the caller's contract).
        let (deformed, scanned) = unsafe {
            (
                ctx.import_buffer(raw_buffer(&scene.deformed)?, 4 * n, "deformed (wgpu)"),
                ctx.import_buffer(raw_buffer(&scene.scanned)?, 4 * n, "scanned (wgpu)"),
            )
        };
        Ok(Self {
            scan: Scan::new(ctx)?,
            scratch: ScanScratch::new(ctx, n)?,
            deformed,
            scanned,
            n,
        })
    }

    /// Records softvk's work for one frame: reads the application's deformed data and writes
    /// softvk's output into the application's `scanned` buffer. The caller brackets it with
    /// [`Recorder::full_barrier`] (see `App::encode_softvk`), so this orders nothing against
    /// wgpu's passes itself.
    pub fn record(&self, rec: &mut Recorder<'_>) -> Result<(), HostError> {
        let bytes = 4 * self.n;
        self.scan.record(
            rec,
            &self.scratch,
            self.deformed.range(0, bytes),
            self.scanned.range(0, bytes),
            self.n,
        )?;
        Ok(())
    }
}
