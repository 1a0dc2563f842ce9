//! Buffer views for [`BindingKind::Texels`] bindings.
//!
//! A texel-buffer descriptor names a `VkBufferView` (buffer, offset, size, format), not a
//! range. Kernels take [`BufferRange`]s like any other binding, so the views are made here on
//! first use and kept, one per range, until their buffer is dropped: a fitting loop binds the
//! same ranges every iteration and makes no view after the first. A view must outlive every
//! command buffer that binds it, and a [`Buffer`]'s drop already requires that no pending work
//! uses the buffer, so destroying its views then is as safe as destroying the buffer.
//!
//! [`BindingKind::Texels`]: super::BindingKind::Texels
//! [`BufferRange`]: super::BufferRange
//! [`Buffer`]: super::Buffer

use std::collections::HashMap;
use std::sync::Mutex;

use ash::vk;

use crate::error::{Result, VkContext};

/// The format of every [`BindingKind::Texels`](super::BindingKind::Texels) binding, and so of
/// every view made here: four 32-bit words a texel, read as `uvec4` and reinterpreted by the
/// kernel (`uintBitsToFloat`), so no device converts or flushes a float on the way.
pub const TEXEL_FORMAT: vk::Format = vk::Format::R32G32B32A32_UINT;

/// Bytes of one [`TEXEL_FORMAT`] texel.
pub const TEXEL_BYTES: u64 = 16;

/// The views made so far, by (buffer, offset, size).
#[derive(Default)]
pub(crate) struct TexelViews {
    views: Mutex<HashMap<(vk::Buffer, u64, u64), vk::BufferView>>,
}

impl TexelViews {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<(vk::Buffer, u64, u64), vk::BufferView>> {
        // The map stays consistent across a panic (each step completes or is not taken).
        self.views.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The view of `size` bytes of `buffer` from `offset`, in [`TEXEL_FORMAT`]: the one made
    /// before, or a new one. The caller checked the range against the device's texel limits.
    pub(crate) fn view(
        &self,
        device: &ash::Device,
        buffer: vk::Buffer,
        offset: u64,
        size: u64,
    ) -> Result<vk::BufferView> {
        let mut views = self.lock();
        if let Some(&view) = views.get(&(buffer, offset, size)) {
            return Ok(view);
        }
        let info = vk::BufferViewCreateInfo::default()
            .buffer(buffer)
            .format(TEXEL_FORMAT)
            .offset(offset)
            .range(size);
        // SAFETY: a live buffer of this device (borrowed by the caller's range), made with
        // STORAGE_TEXEL_BUFFER usage (softvk's buffers; an imported one by its contract); the
        // range was checked against the texel limits.
        let view = unsafe { device.create_buffer_view(&info, None) }.vk("vkCreateBufferView")?;
        views.insert((buffer, offset, size), view);
        Ok(view)
    }

    /// Destroys the views of `buffer`, which is being dropped (no pending work uses it).
    pub(crate) fn evict_buffer(&self, device: &ash::Device, buffer: vk::Buffer) {
        self.lock().retain(|&(b, _, _), view| {
            if b == buffer {
                // SAFETY: no pending command buffer binds it (the buffer's drop contract).
                unsafe { device.destroy_buffer_view(*view, None) };
            }
            b != buffer
        });
    }

    /// Destroys every view.
    ///
    /// # Safety
    /// No pending command buffer binds one of them, and none is recorded again.
    pub(crate) unsafe fn destroy(&mut self, device: &ash::Device) {
        let views = self.views.get_mut().unwrap_or_else(|e| e.into_inner());
        for (_, view) in views.drain() {
            // SAFETY: the caller's contract.
            unsafe { device.destroy_buffer_view(view, None) };
        }
    }
}
