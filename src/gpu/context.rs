//! The Vulkan context: instance, physical device, device, one compute queue and the memory
//! allocator. Either owned (headless, for the CLI, tests and benches) or adopted from a host engine
//! with [`Context::from_raw`], in which case softvk destroys only what it created itself.

use std::collections::HashMap;
use std::ffi::{CStr, c_void};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::descriptors::DescriptorCache;
use super::shared::{Shared, ValidationLog, create_pipeline_cache, on_validation_message};
use super::texel_views::TexelViews;
use super::{Kernel, KernelSpec};
use crate::error::{Error, Result, VkContext};

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
    /// Creates an owned headless context as [`ContextOptions::from_env`] says.
    pub fn from_env() -> Result<Self> {
        Self::new(&ContextOptions::from_env())
    }

    /// Creates an owned headless context: instance, the best device (discrete > integrated >
    /// virtual > CPU, or the one `options.device` names), a compute queue and an allocator.
    pub fn new(options: &ContextOptions) -> Result<Self> {
        // SAFETY: loading the system's Vulkan loader; ash checks the library exports.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| Error::Loader(e.to_string()))?;

        // SAFETY: plain enumeration calls on a loaded entry.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }
            .vk("vkEnumerateInstanceLayerProperties")?;
        let extensions = unsafe { entry.enumerate_instance_extension_properties(None) }
            .vk("vkEnumerateInstanceExtensionProperties")?;
        let has_layer = layers
            .iter()
            .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER));
        let has_debug_utils = extensions
            .iter()
            .any(|e| e.extension_name_as_c_str() == Ok(ash::ext::debug_utils::NAME));
        if options.validation && !has_layer {
            return Err(Error::ValidationLayerMissing);
        }
        if options.validation && !has_debug_utils {
            return Err(Error::NoDevice(
                "validation needs VK_EXT_debug_utils, which this loader lacks".into(),
            ));
        }

        let app_name = c"softvk";
        let app = vk::ApplicationInfo::default()
            .application_name(app_name)
            .engine_name(app_name)
            .api_version(vk::API_VERSION_1_2);
        let layer_ptrs = if options.validation {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            vec![]
        };
        let mut ext_ptrs = if has_debug_utils {
            vec![ash::ext::debug_utils::NAME.as_ptr()]
        } else {
            vec![]
        };
        // The layer's shader validation cache is one file per user
        // (`~/.cache/shader_validation_cache-<uid>.bin`), loaded when a device is created and
        // rewritten in place when it is destroyed, with no locking: devices created and
        // destroyed at once in several threads or processes (a test suite) can read it half
        // written. Layer 1.3.239 crashed inside itself (SIGSEGV) three times in this project's
        // parallel tests, never in hundreds of reruns of one binary, and this is the likely
        // cause. The cache only saves re-validating SPIR-V, so it is turned off.
        let validation_features = options.validation
            // SAFETY: a plain enumeration call on a loaded entry.
            && unsafe { entry.enumerate_instance_extension_properties(Some(VALIDATION_LAYER)) }
                .is_ok_and(|exts| {
                    exts.iter().any(|e| {
                        e.extension_name_as_c_str() == Ok(ash::ext::validation_features::NAME)
                    })
                });
        if validation_features {
            ext_ptrs.push(ash::ext::validation_features::NAME.as_ptr());
        }
        let disabled = [vk::ValidationFeatureDisableEXT::SHADER_VALIDATION_CACHE];
        let mut features =
            vk::ValidationFeaturesEXT::default().disabled_validation_features(&disabled);
        let validation_log = options.validation.then(Box::<ValidationLog>::default);
        let user_data = validation_log.as_deref().map_or(std::ptr::null_mut(), |l| {
            l as *const ValidationLog as *mut c_void
        });
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(on_validation_message))
            .user_data(user_data);
        let mut create = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_ptrs)
            .enabled_extension_names(&ext_ptrs);
        if options.validation {
            // Chained so messages from instance creation itself are caught too.
            create = create.push_next(&mut messenger_info);
        }
        if validation_features {
            create = create.push_next(&mut features);
        }
        // SAFETY: the create info and everything it points to live until the call returns.
        let instance = unsafe { entry.create_instance(&create, None) }.map_err(|result| {
            if result == vk::Result::ERROR_INCOMPATIBLE_DRIVER {
                Error::NoDevice(
                    "no Vulkan driver is installed (without a GPU: apt-get install mesa-vulkan-drivers)"
                        .into(),
                )
            } else {
                Error::Vulkan {
                    call: "vkCreateInstance",
                    result,
                }
            }
        })?;

        let messenger = if options.validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            // SAFETY: valid instance with debug_utils enabled; `user_data` outlives the messenger
            // because both are owned by `Shared`, which destroys the messenger first.
            match unsafe { loader.create_debug_utils_messenger(&messenger_info, None) } {
                Ok(m) => Some((loader, m)),
                Err(result) => {
                    // SAFETY: nothing else was created from this instance yet.
                    unsafe { instance.destroy_instance(None) };
                    return Err(Error::Vulkan {
                        call: "vkCreateDebugUtilsMessengerEXT",
                        result,
                    });
                }
            }
        } else {
            None
        };

        // Undoes the instance-level objects when a later step fails.
        let destroy_instance = || {
            // SAFETY: nothing created from the instance outlives this call; reverse order.
            unsafe {
                if let Some((loader, m)) = &messenger {
                    loader.destroy_debug_utils_messenger(*m, None);
                }
                instance.destroy_instance(None);
            }
        };
        let (physical_device, queue_family_index) =
            match pick_device(&instance, options.device.as_deref()) {
                Ok(p) => p,
                Err(e) => {
                    destroy_instance();
                    return Err(e);
                }
            };

        let priorities = [1.0f32];
        let queue_info = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(queue_family_index)
            .queue_priorities(&priorities)];
        // Push descriptors where the device has them, unless asked for descriptor sets: then
        // the extension is not even enabled, as on a host device without it.
        let push_descriptor = !options.descriptor_sets
            && has_device_extension(&instance, physical_device, PUSH_DESCRIPTOR_EXTENSION);
        let ext_ptrs: Vec<_> = REQUIRED_DEVICE_EXTENSIONS
            .iter()
            .chain(push_descriptor.then_some(&PUSH_DESCRIPTOR_EXTENSION))
            .map(|e| e.as_ptr())
            .collect();
        let device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_info)
            .enabled_extension_names(&ext_ptrs);
        // SAFETY: the physical device was enumerated from this instance and supports the
        // extensions (the required ones checked in `pick_device`, push descriptors just above).
        let device = match unsafe { instance.create_device(physical_device, &device_info, None) } {
            Ok(d) => d,
            Err(result) => {
                destroy_instance();
                return Err(Error::Vulkan {
                    call: "vkCreateDevice",
                    result,
                });
            }
        };
        // SAFETY: family and index 0 were requested above.
        let queue = unsafe { device.get_device_queue(queue_family_index, 0) };

        let raw = RawHandles {
            entry,
            instance,
            physical_device,
            device,
            queue,
            queue_family_index,
            allocator: None,
            debug_utils: has_debug_utils,
            push_descriptor,
        };
        // SAFETY: we just created all of these with the required extensions (and push
        // descriptors exactly when `push_descriptor` says).
        let mut ctx = unsafe {
            Self::assemble(
                raw,
                true,
                messenger,
                validation_log,
                options.pipeline_cache.clone(),
            )
        }?;
        ctx.cpu_workgroups &= !options.gpu_workgroups;
        Ok(ctx)
    }

    /// Adopts a host engine's Vulkan objects without taking ownership of them.
    ///
    /// softvk creates its own pipelines, buffers, command pool and query pools on the host's
    /// device and destroys them when the context (and every buffer and kernel made from it) is
    /// dropped; it never destroys the instance, device or queue, nor a shared allocator.
    ///
    /// # Safety
    /// - `instance`, `physical_device`, `device` and `queue` are valid, belong together, and stay
    ///   valid until this context and everything created from it are dropped.
    /// - The instance was created for Vulkan 1.2 or newer, and the device with every extension in
    ///   [`REQUIRED_DEVICE_EXTENSIONS`] enabled, and with [`PUSH_DESCRIPTOR_EXTENSION`] enabled if
    ///   `push_descriptor` is true. (A device that does not support the extension at all is
    ///   caught: `push_descriptor: true` on it is an [`Error::NoDevice`].)
    /// - `queue_family_index` is `queue`'s family and supports compute. softvk submits to `queue`
    ///   only from [`Context::submit_and_wait`] and friends; the host must not use the queue from
    ///   another thread during those calls (Vulkan's external synchronization rule).
    /// - If `allocator` is given, it was created on this same device.
    /// - Work the host records with softvk's kernels and buffers has completed before the host
    ///   drops them (softvk never waits on the host's queue).
    /// - `debug_utils` is true only if the instance has `VK_EXT_debug_utils` enabled.
    pub unsafe fn from_raw(raw: RawHandles) -> Result<Self> {
        // SAFETY: forwarded to the caller's contract above.
        unsafe { Self::assemble(raw, false, None, None, None) }
    }

    /// # Safety
    /// As [`Context::from_raw`].
    unsafe fn assemble(
        raw: RawHandles,
        owns_device: bool,
        messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
        validation_log: Option<Box<ValidationLog>>,
        cache_path: Option<PathBuf>,
    ) -> Result<Self> {
        let RawHandles {
            entry,
            instance,
            physical_device,
            device,
            queue,
            queue_family_index,
            allocator,
            debug_utils,
            push_descriptor,
        } = raw;
        let info = query_info(&instance, physical_device, queue_family_index);
        if info.api_version < (1, 2, 0) {
            return Err(Error::NoDevice(format!(
                "{} supports Vulkan {} only; softvk needs 1.2",
                info.name,
                info.api_version_string()
            )));
        }
        if push_descriptor && !info.push_descriptor {
            return Err(Error::NoDevice(format!(
                "{} does not support {}, which the host says it enabled",
                info.name,
                PUSH_DESCRIPTOR_EXTENSION.to_string_lossy()
            )));
        }
        let allocator = match allocator {
            Some(a) => a,
            None => Arc::new(Mutex::new(
                Allocator::new(&AllocatorCreateDesc {
                    instance: instance.clone(),
                    device: device.clone(),
                    physical_device,
                    debug_settings: Default::default(),
                    buffer_device_address: false,
                    allocation_sizes: Default::default(),
                })
                .map_err(|source| Error::Allocation {
                    name: "allocator".into(),
                    size: 0,
                    source,
                })?,
            )),
        };
        let debug_device =
            debug_utils.then(|| ash::ext::debug_utils::Device::new(&instance, &device));
        let push_descriptor =
            push_descriptor.then(|| ash::khr::push_descriptor::Device::new(&instance, &device));
        let descriptor_sets = push_descriptor.is_none().then(DescriptorCache::default);
        let pipeline_cache = create_pipeline_cache(&device, cache_path.as_deref());
        let shared = Arc::new(Shared {
            instance,
            device,
            allocator: std::mem::ManuallyDrop::new(allocator),
            debug_device,
            messenger,
            validation_log,
            owns_device,
            pipeline_cache,
            cache_path,
            descriptor_sets,
            texel_views: TexelViews::default(),
            _entry: entry,
        });
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(queue_family_index)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid device; the pool is destroyed in `Drop for Context`.
        let command_pool = unsafe { shared.device.create_command_pool(&pool_info, None) }
            .vk("vkCreateCommandPool")?;
        shared.name(command_pool, "softvk command pool");
        Ok(Self {
            shared,
            physical_device,
            queue,
            queue_family_index,
            push_descriptor,
            command_pool,
            pool_lock: Mutex::new(()),
            counters: CounterCells::default(),
            cpu_workgroups: info.device_type == vk::PhysicalDeviceType::CPU,
            kernels: Mutex::new(HashMap::new()),
            info,
        })
    }

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

fn type_rank(t: vk::PhysicalDeviceType) -> u32 {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

/// A physical device as the loader reports it, and whether softvk can use it.
#[derive(Clone, Debug)]
pub struct PhysicalDeviceEntry {
    /// The handle.
    pub handle: vk::PhysicalDevice,
    /// The device name.
    pub name: String,
    /// The compute queue family softvk would use, or why the device is unusable.
    pub usable: Result<u32, String>,
}

/// The devices the loader reports, in enumeration order (the indices `SOFTVK_DEVICE` takes).
pub fn list_devices(instance: &ash::Instance) -> Result<Vec<PhysicalDeviceEntry>> {
    // SAFETY: plain enumeration on a valid instance.
    let devices =
        unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    Ok(devices
        .into_iter()
        .map(|handle| {
            // SAFETY: `handle` was just enumerated from `instance`.
            let props = unsafe { instance.get_physical_device_properties(handle) };
            let name = props
                .device_name_as_c_str()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            PhysicalDeviceEntry {
                handle,
                name,
                usable: usable(instance, handle),
            }
        })
        .collect())
}

/// Whether `pd` lists device extension `name`.
fn has_device_extension(instance: &ash::Instance, pd: vk::PhysicalDevice, name: &CStr) -> bool {
    // SAFETY: `pd` belongs to `instance`.
    unsafe { instance.enumerate_device_extension_properties(pd) }
        .unwrap_or_default()
        .iter()
        .any(|e| e.extension_name_as_c_str() == Ok(name))
}

/// The compute queue family softvk would use on `pd`, or why it cannot.
fn usable(instance: &ash::Instance, pd: vk::PhysicalDevice) -> Result<u32, String> {
    // SAFETY: `pd` belongs to `instance`.
    let props = unsafe { instance.get_physical_device_properties(pd) };
    if vk::api_version_major(props.api_version) == 1 && vk::api_version_minor(props.api_version) < 2
    {
        return Err("Vulkan 1.2 not supported".into());
    }
    // SAFETY: as above.
    let exts = unsafe { instance.enumerate_device_extension_properties(pd) }
        .map_err(|e| format!("cannot list extensions: {e}"))?;
    for needed in REQUIRED_DEVICE_EXTENSIONS {
        if !exts
            .iter()
            .any(|e| e.extension_name_as_c_str() == Ok(*needed))
        {
            return Err(format!("missing {}", needed.to_string_lossy()));
        }
    }
    // SAFETY: as above.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    // Prefer a compute family with timestamps; any compute family otherwise.
    let compute = |f: &vk::QueueFamilyProperties| f.queue_flags.contains(vk::QueueFlags::COMPUTE);
    families
        .iter()
        .position(|f| compute(f) && f.timestamp_valid_bits > 0)
        .or_else(|| families.iter().position(compute))
        .map(|i| i as u32)
        .ok_or_else(|| "no compute queue".into())
}

fn pick_device(
    instance: &ash::Instance,
    wanted: Option<&str>,
) -> Result<(vk::PhysicalDevice, u32)> {
    let devices = list_devices(instance)?;
    if devices.is_empty() {
        return Err(Error::NoDevice(
            "the Vulkan loader reports no physical device (install a driver, e.g. mesa-vulkan-drivers)"
                .into(),
        ));
    }
    if let Some(wanted) = wanted {
        let by_index = wanted.trim().parse::<usize>().ok();
        let lower = wanted.to_lowercase();
        let entry = devices
            .iter()
            .enumerate()
            .find(|(i, d)| match by_index {
                Some(index) => *i == index,
                None => d.name.to_lowercase().contains(&lower),
            })
            .map(|(_, d)| d)
            .ok_or_else(|| {
                let names: Vec<_> = devices
                    .iter()
                    .enumerate()
                    .map(|(i, d)| format!("{i}: {}", d.name))
                    .collect();
                Error::NoDevice(format!(
                    "SOFTVK_DEVICE={wanted} matches none of [{}]",
                    names.join(", ")
                ))
            })?;
        return match &entry.usable {
            Ok(family) => Ok((entry.handle, *family)),
            Err(why) => Err(Error::NoDevice(format!("{}: {why}", entry.name))),
        };
    }
    let mut best: Option<(u32, vk::PhysicalDevice, u32)> = None;
    let mut reasons = Vec::new();
    for entry in &devices {
        match &entry.usable {
            Ok(family) => {
                // SAFETY: `entry.handle` belongs to `instance`.
                let props = unsafe { instance.get_physical_device_properties(entry.handle) };
                let rank = type_rank(props.device_type);
                if best.is_none_or(|(r, _, _)| rank < r) {
                    best = Some((rank, entry.handle, *family));
                }
            }
            Err(why) => reasons.push(format!("{}: {why}", entry.name)),
        }
    }
    best.map(|(_, pd, family)| (pd, family))
        .ok_or_else(|| Error::NoDevice(reasons.join("; ")))
}

fn query_info(instance: &ash::Instance, pd: vk::PhysicalDevice, family: u32) -> DeviceInfo {
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut maintenance3 = vk::PhysicalDeviceMaintenance3Properties::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default()
        .push_next(&mut driver)
        .push_next(&mut subgroup)
        .push_next(&mut maintenance3);
    // SAFETY: `pd` belongs to `instance`, which is Vulkan 1.1+ (properties2 is core).
    unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
    let props = props2.properties;
    // SAFETY: as above.
    let features = unsafe { instance.get_physical_device_features(pd) };
    // SAFETY: as above.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    // SAFETY: as above.
    let memory = unsafe { instance.get_physical_device_memory_properties(pd) };
    // SAFETY: as above.
    let exts = unsafe { instance.enumerate_device_extension_properties(pd) }.unwrap_or_default();
    let cstr = |s: std::result::Result<&CStr, _>| {
        s.map(|s: &CStr| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    DeviceInfo {
        name: cstr(props.device_name_as_c_str()),
        device_type: props.device_type,
        driver: format!(
            "{} ({})",
            cstr(driver.driver_name_as_c_str()),
            cstr(driver.driver_info_as_c_str())
        ),
        api_version: (
            vk::api_version_major(props.api_version),
            vk::api_version_minor(props.api_version),
            vk::api_version_patch(props.api_version),
        ),
        subgroup_size: subgroup.subgroup_size,
        limits: props.limits,
        timestamp_period_ns: props.limits.timestamp_period,
        timestamp_valid_bits: families
            .get(family as usize)
            .map_or(0, |f| f.timestamp_valid_bits),
        shader_int64: features.shader_int64 == vk::TRUE,
        atomic_float: exts
            .iter()
            .any(|e| e.extension_name_as_c_str() == Ok(ash::ext::shader_atomic_float::NAME)),
        push_descriptor: exts
            .iter()
            .any(|e| e.extension_name_as_c_str() == Ok(PUSH_DESCRIPTOR_EXTENSION)),
        max_memory_allocation_size: maintenance3.max_memory_allocation_size,
        memory,
    }
}
