//! Making a [`Context`]: an owned headless one ([`Context::new`]: instance, device, queue,
//! allocator) or one adopted from a host engine ([`Context::from_raw`]), both assembled the
//! same way.

use std::collections::HashMap;
use std::ffi::c_void;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use super::devices::{has_device_extension, pick_device, query_info};
use super::{
    Context, ContextOptions, CounterCells, PUSH_DESCRIPTOR_EXTENSION, REQUIRED_DEVICE_EXTENSIONS,
    RawHandles, VALIDATION_LAYER,
};
use crate::error::{Error, Result, VkContext};
use crate::gpu::descriptors::DescriptorCache;
use crate::gpu::shared::{Shared, ValidationLog, create_pipeline_cache, on_validation_message};
use crate::gpu::texel_views::TexelViews;

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
}
