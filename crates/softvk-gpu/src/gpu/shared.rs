//! The device state the context shares with every object it makes ([`Shared`]): instance and
//! device, the allocator, the pipeline cache, debug naming and the validation log, and the
//! caches a dropped buffer or kernel must evict from (descriptor sets, texel views). A
//! [`Buffer`] or [`Kernel`] holds an `Arc` of it, so it frees itself on drop and the device
//! outlives it; the [`Context`] holds one too. It sits below everything else of the GPU core
//! (as wgpu-hal's `DeviceShared` does): it names no buffer, kernel or context, so each of
//! those imports it and none of them is imported back.
//!
//! [`Buffer`]: super::Buffer
//! [`Kernel`]: super::Kernel
//! [`Context`]: super::Context

use std::ffi::{CStr, CString, c_void};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::Allocator;

use super::descriptors::DescriptorCache;
use super::texel_views::TexelViews;
use crate::error::{Error, Result};

/// Validation messages collected by the debug messenger. Boxed so its address is stable for the
/// callback's user-data pointer.
#[derive(Default)]
pub(crate) struct ValidationLog {
    messages: Mutex<Vec<String>>,
}

impl ValidationLog {
    /// Every message collected so far, oldest first; the log is left empty.
    pub(super) fn take(&self) -> Vec<String> {
        self.messages
            .lock()
            .map(|mut m| std::mem::take(&mut *m))
            .unwrap_or_default()
    }
}

/// State shared by the context and every object it creates, so a buffer can free itself on drop
/// and the device outlives all of them.
pub(crate) struct Shared {
    pub(crate) instance: ash::Instance,
    pub(crate) device: ash::Device,
    pub(crate) allocator: std::mem::ManuallyDrop<Arc<Mutex<Allocator>>>,
    pub(crate) debug_device: Option<ash::ext::debug_utils::Device>,
    pub(super) messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    pub(super) validation_log: Option<Box<ValidationLog>>,
    /// True when softvk created the instance and device (and so destroys them).
    pub(super) owns_device: bool,
    /// Every pipeline softvk builds goes through this cache; saved to `cache_path`, if any, on
    /// drop.
    pub(crate) pipeline_cache: vk::PipelineCache,
    pub(super) cache_path: Option<PathBuf>,
    /// The descriptor sets dispatches bind in [`DescriptorMode::Sets`]; `None` in
    /// [`DescriptorMode::Push`]. Here rather than in [`Context`] because a dropped [`Buffer`]
    /// or [`Kernel`] (which hold only this state) must evict the sets that name it.
    ///
    /// [`DescriptorMode::Sets`]: super::DescriptorMode::Sets
    /// [`DescriptorMode::Push`]: super::DescriptorMode::Push
    /// [`Context`]: super::Context
    /// [`Buffer`]: super::Buffer
    /// [`Kernel`]: super::Kernel
    pub(crate) descriptor_sets: Option<DescriptorCache>,
    /// The buffer views of texel bindings, made on first use and kept until their buffer
    /// drops (here for the same reason as `descriptor_sets`).
    pub(crate) texel_views: TexelViews,
    pub(super) _entry: ash::Entry,
}

/// A pipeline cache primed from `path` when it holds one (the driver ignores a foreign header).
pub(super) fn create_pipeline_cache(
    device: &ash::Device,
    path: Option<&Path>,
) -> vk::PipelineCache {
    let data = path.and_then(|p| std::fs::read(p).ok()).unwrap_or_default();
    let primed = vk::PipelineCacheCreateInfo::default().initial_data(&data);
    // SAFETY: valid device; the initial data is only read during the call.
    let cache = unsafe { device.create_pipeline_cache(&primed, None) };
    cache
        .or_else(|_| {
            // SAFETY: as above, with no initial data.
            unsafe { device.create_pipeline_cache(&vk::PipelineCacheCreateInfo::default(), None) }
        })
        .unwrap_or(vk::PipelineCache::null())
}

/// Writes the cache's data to `path` through a temporary file and a rename, so a reader never
/// sees half a file. Best effort: a cache that cannot be saved is only slower next time.
fn save_pipeline_cache(device: &ash::Device, cache: vk::PipelineCache, path: &Path) {
    // SAFETY: `cache` is a live cache of `device`.
    let Ok(data) = (unsafe { device.get_pipeline_cache_data(cache) }) else {
        return;
    };
    if data.is_empty() || std::fs::read(path).is_ok_and(|old| old == data) {
        return;
    }
    if let Some(dir) = path.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    // Unique per write: several contexts of one process may save at once.
    static WRITES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = WRITES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("tmp{}-{n}", std::process::id()));
    if std::fs::write(&tmp, &data).is_ok() && std::fs::rename(&tmp, path).is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
}

impl Shared {
    /// Gives a Vulkan object a debug name (no-op without `VK_EXT_debug_utils`).
    pub(crate) fn name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Some(debug) = &self.debug_device else {
            return;
        };
        let Ok(name) = CString::new(name) else {
            return;
        };
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(handle)
            .object_name(&name);
        // SAFETY: `handle` is a live object of `self.device`; naming has no other effect.
        // A failure to name is harmless, so the result is ignored.
        let _ = unsafe { debug.set_debug_utils_object_name(&info) };
    }
}

impl Drop for Shared {
    fn drop(&mut self) {
        // SAFETY: this runs when the last context, buffer or kernel is gone, so nothing of ours is
        // still in use on the GPU (every submit path waits). The descriptor pools go first
        // (every buffer and kernel has evicted its sets by now; destroying a pool frees whatever
        // is left), then the allocator, before the device they belong to; instance and device
        // are destroyed only if we created them.
        unsafe {
            if let Some(cache) = &mut self.descriptor_sets {
                cache.destroy(&self.device);
            }
            self.texel_views.destroy(&self.device);
            if let Some(path) = &self.cache_path {
                save_pipeline_cache(&self.device, self.pipeline_cache, path);
            }
            self.device
                .destroy_pipeline_cache(self.pipeline_cache, None);
            std::mem::ManuallyDrop::drop(&mut self.allocator);
            if self.owns_device {
                let _ = self.device.device_wait_idle();
                self.device.destroy_device(None);
                if let Some((loader, messenger)) = self.messenger.take() {
                    loader.destroy_debug_utils_messenger(messenger, None);
                }
                self.instance.destroy_instance(None);
            }
        }
    }
}

/// The debug messenger's callback: adds warnings and errors to the [`ValidationLog`] that
/// `user` points to.
pub(super) unsafe extern "system" fn on_validation_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
            | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
    ) && !user.is_null()
        && !data.is_null()
    {
        // SAFETY: `user` is the `ValidationLog` boxed in `Shared`, alive as long as the messenger;
        // `data` and its message pointer are valid for the duration of the callback.
        let (log, message) = unsafe {
            let data = &*data;
            let message = if data.p_message.is_null() {
                String::from("(no message)")
            } else {
                CStr::from_ptr(data.p_message)
                    .to_string_lossy()
                    .into_owned()
            };
            (&*(user as *const ValidationLog), message)
        };
        if let Ok(mut messages) = log.messages.lock() {
            messages.push(message);
        }
    }
    vk::FALSE
}

impl Shared {
    /// The descriptor set that binds `ranges` (buffer, offset, size, in binding order) to the
    /// bindings of set layout `layout`, written with `writes` if it is new
    /// ([`DescriptorCache::set`]). Only in [`DescriptorMode::Sets`] (a context that pushes its
    /// descriptors keeps no cache, and says so).
    ///
    /// [`DescriptorMode::Sets`]: super::DescriptorMode::Sets
    pub(crate) fn descriptor_set(
        &self,
        layout: vk::DescriptorSetLayout,
        ranges: Vec<(vk::Buffer, u64, u64)>,
        writes: &[vk::WriteDescriptorSet<'_>],
    ) -> Result<vk::DescriptorSet> {
        let Some(cache) = &self.descriptor_sets else {
            return Err(Error::Limit(
                "descriptor sets asked of a context that pushes its descriptors".into(),
            ));
        };
        cache.set(
            &self.device,
            |pool, name| self.name(pool, name),
            layout,
            ranges,
            writes,
        )
    }

    /// Forgets `buffer`, which is being dropped: frees the cached descriptor sets that name it
    /// and destroys its texel views (its handle value may come back with a new buffer, which
    /// must find neither).
    pub(crate) fn evict_buffer(&self, buffer: vk::Buffer) {
        // The sets first: they may name the buffer's texel views.
        if let Some(cache) = &self.descriptor_sets {
            cache.evict_buffer(&self.device, buffer);
        }
        self.texel_views.evict_buffer(&self.device, buffer);
    }

    /// Frees the cached descriptor sets of set layout `layout`, whose kernel is being dropped.
    pub(crate) fn evict_layout(&self, layout: vk::DescriptorSetLayout) {
        if let Some(cache) = &self.descriptor_sets {
            cache.evict_layout(&self.device, layout);
        }
    }
}
