//! The Vulkan context: instance, physical device, device, one compute queue and the memory
//! allocator. Either owned (headless, for the CLI, tests and benches) or adopted from a host engine
//! with [`Context::from_raw`], in which case softvk destroys only what it created itself.

mod create;
mod devices;

pub use devices::{PhysicalDeviceEntry, list_devices};

use std::collections::HashMap;
use std::ffi::CStr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::Allocator;

use super::descriptors::DescriptorCache;
use super::shared::Shared;
use super::{Kernel, KernelSpec};
use crate::error::{Error, Result};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Device extensions softvk cannot run without: none. A device (or a host's device) without
/// [`PUSH_DESCRIPTOR_EXTENSION`] binds buffers through cached descriptor sets instead
/// ([`DescriptorMode::Sets`]).
pub const REQUIRED_DEVICE_EXTENSIONS: &[&CStr] = &[];

/// `VK_KHR_push_descriptor`, which softvk uses where the device has it: a dispatch then carries
/// its buffer bindings inside the command buffer, so recording never allocates a descriptor set
/// ([`DescriptorMode::Push`]). An owned context enables it when the device supports it (unless
/// [`ContextOptions::descriptor_sets`] says otherwise); a host says whether it enabled it with
/// [`RawHandles::push_descriptor`].
pub const PUSH_DESCRIPTOR_EXTENSION: &CStr = ash::khr::push_descriptor::NAME;

/// How a [`Context`] binds the storage buffers of a dispatch, decided once when it is made
/// ([`Context::descriptor_mode`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DescriptorMode {
    /// `vkCmdPushDescriptorSetKHR` ([`PUSH_DESCRIPTOR_EXTENSION`]): the bindings live in the
    /// command buffer, nothing outlives the recording.
    Push,
    /// Ordinary descriptor sets, for devices without the extension. A command buffer outlives
    /// the recording by however long its host likes, so each set must outlive it too: the
    /// context keeps one immutable set per kernel and list of bound ranges, made on first use
    /// and freed when a buffer it names (or its kernel) is dropped. A loop that records the same
    /// bindings every iteration reuses the same sets.
    Sets,
}

impl DescriptorMode {
    /// `push` or `sets`, as `SOFTVK_DESCRIPTORS` spells them.
    pub fn as_str(self) -> &'static str {
        match self {
            DescriptorMode::Push => "push",
            DescriptorMode::Sets => "sets",
        }
    }
}

/// A pipeline's key in the context's cache: the kernel's name and its specialization
/// constants.
type KernelKey = (&'static str, Vec<u32>);

/// How to create an owned context.
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Enable `VK_LAYER_KHRONOS_validation` and collect every message it emits.
    pub validation: bool,
    /// Pick a device by index (as `softvk info` lists them) or by a substring of its name.
    pub device: Option<String>,
    /// A file that keeps the compiled pipelines (a `VkPipelineCache`) between runs: read when
    /// the context is made (a missing, unreadable or foreign file is ignored: the driver checks
    /// the header) and written back, atomically, when the last object of the context is gone (a
    /// failure to write is ignored). `None`: an in-memory cache only.
    pub pipeline_cache: Option<PathBuf>,
    /// Bind buffers through descriptor sets ([`DescriptorMode::Sets`]) even where the device has
    /// [`PUSH_DESCRIPTOR_EXTENSION`] (which is then not enabled), as on a host device without
    /// it: the way to exercise that path on any device. `false`: push descriptors where the
    /// device has them, sets elsewhere.
    pub descriptor_sets: bool,
    /// Shape the kernels' workgroups as for a GPU even on a CPU device
    /// ([`Context::cpu_workgroups`] false): the way to exercise a GPU's shapes on any device.
    /// `false`: a CPU device gets the shapes made for it.
    pub gpu_workgroups: bool,
}

impl ContextOptions {
    /// Reads `SOFTVK_VALIDATION` (`1`/`true` turns validation on), `SOFTVK_DEVICE`,
    /// `SOFTVK_PIPELINE_CACHE` (a file, or `off`; default `softvk/pipelines.bin` under
    /// `$XDG_CACHE_HOME`, else `$HOME/.cache`), `SOFTVK_DESCRIPTORS` (`sets` sets
    /// [`ContextOptions::descriptor_sets`]; anything else, `push` say, leaves the default) and
    /// `SOFTVK_WORKGROUPS` (`gpu` sets [`ContextOptions::gpu_workgroups`]).
    pub fn from_env() -> Self {
        let validation = std::env::var("SOFTVK_VALIDATION")
            .map(|v| matches!(v.trim(), "1" | "true" | "yes" | "on"))
            .unwrap_or(false);
        let device = std::env::var("SOFTVK_DEVICE")
            .ok()
            .filter(|s| !s.trim().is_empty());
        let pipeline_cache = match std::env::var_os("SOFTVK_PIPELINE_CACHE") {
            Some(v) if v == "off" || v == "0" || v.is_empty() => None,
            Some(v) => Some(PathBuf::from(v)),
            None => std::env::var_os("XDG_CACHE_HOME")
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
                .or_else(|| {
                    std::env::var_os("HOME")
                        .filter(|v| !v.is_empty())
                        .map(|h| PathBuf::from(h).join(".cache"))
                })
                .map(|dir| dir.join("softvk").join("pipelines.bin")),
        };
        let descriptor_sets = std::env::var("SOFTVK_DESCRIPTORS")
            .is_ok_and(|v| v.trim().eq_ignore_ascii_case(DescriptorMode::Sets.as_str()));
        let gpu_workgroups =
            std::env::var("SOFTVK_WORKGROUPS").is_ok_and(|v| v.trim().eq_ignore_ascii_case("gpu"));
        Self {
            validation,
            device,
            pipeline_cache,
            descriptor_sets,
            gpu_workgroups,
        }
    }
}

/// Handles a host engine gives to [`Context::from_raw`].
pub struct RawHandles {
    /// The loader the host's instance came from.
    pub entry: ash::Entry,
    /// The host's instance (Vulkan 1.2 or newer).
    pub instance: ash::Instance,
    /// The physical device behind `device`.
    pub physical_device: vk::PhysicalDevice,
    /// The host's device, created with [`REQUIRED_DEVICE_EXTENSIONS`] (and, if the host likes,
    /// [`PUSH_DESCRIPTOR_EXTENSION`]: see `push_descriptor`).
    pub device: ash::Device,
    /// A queue with compute support, used only by softvk's convenience submits.
    pub queue: vk::Queue,
    /// The family of `queue`.
    pub queue_family_index: u32,
    /// Share the host's allocator; `None` makes softvk create its own on the host's device.
    pub allocator: Option<Arc<Mutex<Allocator>>>,
    /// Whether the host enabled `VK_EXT_debug_utils` on its instance (then softvk names objects).
    pub debug_utils: bool,
    /// Whether the host enabled [`PUSH_DESCRIPTOR_EXTENSION`] on `device`. Vulkan cannot be asked
    /// which extensions a device was created with, so the host says: `true` makes softvk push
    /// its bindings ([`DescriptorMode::Push`]), `false` makes it use descriptor sets of its own
    /// ([`DescriptorMode::Sets`]).
    pub push_descriptor: bool,
}

/// What softvk learned about its device; printed by `softvk info`.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// Device name, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`.
    pub name: String,
    /// Discrete, integrated, virtual or CPU.
    pub device_type: vk::PhysicalDeviceType,
    /// Driver name and info string.
    pub driver: String,
    /// The device's Vulkan version, as `major.minor.patch`.
    pub api_version: (u32, u32, u32),
    /// Default subgroup size.
    pub subgroup_size: u32,
    /// The limits softvk reads.
    pub limits: vk::PhysicalDeviceLimits,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period_ns: f32,
    /// Valid bits of timestamps on the queue softvk uses (0: no timestamps).
    pub timestamp_valid_bits: u32,
    /// Device supports `shaderInt64`.
    pub shader_int64: bool,
    /// Device supports `VK_EXT_shader_atomic_float` (softvk does not need it).
    pub atomic_float: bool,
    /// Device supports [`PUSH_DESCRIPTOR_EXTENSION`] (whether softvk uses it is
    /// [`Context::descriptor_mode`]).
    pub push_descriptor: bool,
    /// `maxMemoryAllocationSize` (Vulkan 1.1): the largest single allocation, so the largest
    /// buffer (each buffer is one allocation).
    pub max_memory_allocation_size: u64,
    /// The device's memory types and heaps.
    pub memory: vk::PhysicalDeviceMemoryProperties,
}

impl DeviceInfo {
    /// `major.minor.patch` of the device's API version.
    pub fn api_version_string(&self) -> String {
        let (a, b, c) = self.api_version;
        format!("{a}.{b}.{c}")
    }

    /// Size that every storage buffer is rounded up to, and every bound offset aligned to: the
    /// larger of `minStorageBufferOffsetAlignment` and `nonCoherentAtomSize` (mapped ranges).
    pub fn buffer_alignment(&self) -> u64 {
        self.limits
            .min_storage_buffer_offset_alignment
            .max(self.limits.non_coherent_atom_size)
            .max(4)
    }

    /// The most loop iterations one shader invocation may run in all, on a driver known to cap
    /// them silently: llvmpipe (lavapipe) ends every loop of an invocation once 65 535
    /// iterations have run over all its loops (Mesa's `LP_MAX_TGSI_LOOP_ITERATIONS`), so a
    /// longer loop would quietly drop work. Kernels whose loops depend on the input check this
    /// on the host and refuse with [`crate::Error::Limit`] instead. `None`: no known cap.
    pub fn shader_loop_limit(&self) -> Option<u64> {
        (self.name.contains("llvmpipe") || self.driver.contains("llvmpipe")).then_some(65_535)
    }
}

/// A Vulkan device and compute queue that softvk records and (optionally) submits work on.
pub struct Context {
    pub(crate) shared: Arc<Shared>,
    pub(crate) physical_device: vk::PhysicalDevice,
    pub(crate) queue: vk::Queue,
    pub(crate) queue_family_index: u32,
    /// The extension's entry points in [`DescriptorMode::Push`]; `None` in
    /// [`DescriptorMode::Sets`] (then `shared.descriptor_sets` is `Some`).
    pub(crate) push_descriptor: Option<ash::khr::push_descriptor::Device>,
    pub(crate) command_pool: vk::CommandPool,
    /// Serializes use of `command_pool` and `queue` (both need external synchronization).
    pub(crate) pool_lock: Mutex<()>,
    /// What softvk did on its own behalf ([`Context::counters`]).
    pub(crate) counters: CounterCells,
    info: DeviceInfo,
    /// [`Context::cpu_workgroups`].
    cpu_workgroups: bool,
    /// [`Context::kernel`]'s pipelines, by kernel name and specialization constants.
    kernels: Mutex<HashMap<KernelKey, Arc<Kernel>>>,
}

/// The atomic cells behind [`Counters`].
#[derive(Default)]
pub(crate) struct CounterCells {
    pub(crate) submissions: AtomicU64,
    pub(crate) staging_copies: AtomicU64,
}

/// What a [`Context`] has done on its own behalf since it was made: a host engine that records
/// softvk into its own command buffers checks that these stay put during its frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Submissions to the context's queue (its submit-and-wait conveniences).
    pub submissions: u64,
    /// Staging copies between host and device memory ([`Context::write_buffer`],
    /// [`Context::read_buffer`], [`Context::upload_buffer`]).
    pub staging_copies: u64,
    /// Descriptor sets allocated by recording ([`DescriptorMode::Sets`] only): a recording whose
    /// kernel and buffer ranges were all recorded before reuses the cached sets and adds none.
    pub descriptor_sets: u64,
}

impl Context {
    /// Kernel `spec` specialized with `constants` (`constants[i]` the 32-bit value of its
    /// specialization constant `constant_id = i`; none: their defaults), built the first time
    /// any caller asks for it and shared from then on for the life of the context: **the one
    /// way to get a pipeline** (see [`crate::gpu`]). A pipeline costs a compile and, on
    /// lavapipe, its machine code in memory, whoever asks for it; here it costs that once per
    /// context, however many objects record it (one sampler per training object). With
    /// [`DescriptorMode::Sets`], its cached sets go with the buffers they name.
    pub fn kernel(&self, spec: &'static KernelSpec, constants: &[u32]) -> Result<Arc<Kernel>> {
        let mut kernels = self.kernels.lock().unwrap_or_else(|e| e.into_inner());
        let key = (spec.name, constants.to_vec());
        if let Some(kernel) = kernels.get(&key) {
            return Ok(Arc::clone(kernel));
        }
        let kernel = Arc::new(Kernel::specialized(self, spec, constants)?);
        kernels.insert(key, Arc::clone(&kernel));
        Ok(kernel)
    }

    /// The device this context runs on.
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// Whether the kernels' workgroups take the shapes made for a CPU driver: on a CPU device,
    /// unless [`ContextOptions::gpu_workgroups`]. llvmpipe runs a workgroup's subgroups one
    /// after another as coroutines, each with a set-up cost, where a GPU runs them side by
    /// side: the tiled fine passes then take one subgroup per workgroup, and the texel
    /// reduction one face per invocation (`raster::fine`, `raster::backward`). Results are the
    /// same bits either way.
    pub fn cpu_workgroups(&self) -> bool {
        self.cpu_workgroups
    }

    /// How dispatches bind their buffers on this context: push descriptors, or descriptor sets
    /// where the device (or the host's device) lacks [`PUSH_DESCRIPTOR_EXTENSION`] or
    /// [`ContextOptions::descriptor_sets`] asked for them.
    pub fn descriptor_mode(&self) -> DescriptorMode {
        if self.push_descriptor.is_some() {
            DescriptorMode::Push
        } else {
            DescriptorMode::Sets
        }
    }

    /// How many descriptor sets the context holds right now ([`DescriptorMode::Sets`]; always 0
    /// with push descriptors): one per kernel and list of bound ranges recorded since the
    /// buffers they name were made. A loop that records the same work every iteration keeps this
    /// constant; a count that grows with every iteration means buffers are made and bound anew
    /// each time (and freed only on drop).
    pub fn cached_descriptor_sets(&self) -> usize {
        self.shared
            .descriptor_sets
            .as_ref()
            .map_or(0, DescriptorCache::len)
    }

    /// The raw `ash` device, for hosts that mix softvk's recording with their own.
    pub fn device(&self) -> &ash::Device {
        &self.shared.device
    }

    /// The raw `ash` instance.
    pub fn instance(&self) -> &ash::Instance {
        &self.shared.instance
    }

    /// Submissions, staging copies and descriptor sets softvk has made so far ([`Counters`]).
    pub fn counters(&self) -> Counters {
        Counters {
            submissions: self.counters.submissions.load(Ordering::Relaxed),
            staging_copies: self.counters.staging_copies.load(Ordering::Relaxed),
            descriptor_sets: self
                .shared
                .descriptor_sets
                .as_ref()
                .map_or(0, DescriptorCache::allocated),
        }
    }

    /// The physical device.
    pub fn physical_device(&self) -> vk::PhysicalDevice {
        self.physical_device
    }

    /// The queue and its family index that convenience submits use.
    pub fn queue(&self) -> (vk::Queue, u32) {
        (self.queue, self.queue_family_index)
    }

    /// The allocator, shareable with a host engine.
    pub fn allocator(&self) -> Arc<Mutex<Allocator>> {
        Arc::clone(&self.shared.allocator)
    }

    /// Whether the validation layer is on and being listened to.
    pub fn validation_enabled(&self) -> bool {
        self.shared.validation_log.is_some()
    }

    /// Every validation message collected so far (warnings and errors), oldest first, and clears
    /// the log.
    pub fn take_validation_messages(&self) -> Vec<String> {
        self.shared
            .validation_log
            .as_ref()
            .map(|l| l.take())
            .unwrap_or_default()
    }

    /// `Ok` if the validation layer has said nothing since the last check; otherwise an
    /// [`Error::Validation`] with the first message. Clears the log either way.
    pub fn check_validation(&self) -> Result<()> {
        let messages = self.take_validation_messages();
        match messages.first() {
            None => Ok(()),
            Some(first) => Err(Error::Validation {
                count: messages.len(),
                first: first.clone(),
            }),
        }
    }

    pub(crate) fn name<H: vk::Handle>(&self, handle: H, name: &str) {
        self.shared.name(handle, name);
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: every submit path waits for its fence, so the pool's command buffers are idle.
        unsafe {
            self.shared
                .device
                .destroy_command_pool(self.command_pool, None);
        }
    }
}
