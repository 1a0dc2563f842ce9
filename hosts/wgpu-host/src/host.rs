//! The wgpu application's side: a headless wgpu instance, adapter, device and queue on the
//! Vulkan backend, with the device opened through wgpu-hal so that it carries softvk's device
//! extensions, and the raw handles softvk adopts.

use std::ffi::CStr;

use ash::vk;
use softvk::gpu::{Context, PUSH_DESCRIPTOR_EXTENSION, REQUIRED_DEVICE_EXTENSIONS, RawHandles};
use wgpu::hal::api::Vulkan;
use wgpu::hal::vulkan as hal_vk;

use crate::validation::{Capture, Message};

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Why the host could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum HostError {
    /// No Vulkan adapter (no loader, no driver).
    #[error(
        "no Vulkan adapter (on a machine without a GPU: apt-get install mesa-vulkan-drivers); \
         set SOFTVK_NO_GPU=1 to skip GPU tests explicitly"
    )]
    NoAdapter,
    /// Validation was asked for but the Khronos layer is not installed.
    #[error(
        "validation asked for but VK_LAYER_KHRONOS_validation is missing \
         (apt-get install vulkan-validationlayers, or SOFTVK_VALIDATION=0)"
    )]
    ValidationLayerMissing,
    /// The layer cannot take `VkValidationFeaturesEXT`, so synchronization validation is off.
    #[error(
        "VK_LAYER_KHRONOS_validation does not offer VK_EXT_validation_features: wgpu-hal cannot \
         turn synchronization validation on"
    )]
    NoSyncValidation,
    /// The adapter lacks a device extension softvk needs.
    #[error("{adapter} lacks the device extension {extension}, which softvk needs")]
    MissingExtension {
        /// The adapter's name.
        adapter: String,
        /// The extension.
        extension: String,
    },
    /// Something wgpu-specific went wrong (not the Vulkan backend, device creation, mapping).
    #[error("wgpu: {0}")]
    Wgpu(String),
    /// A Vulkan call of ours failed.
    #[error("{call}: {result}")]
    Vulkan {
        /// The call.
        call: &'static str,
        /// Its result.
        result: vk::Result,
    },
    /// softvk refused.
    #[error(transparent)]
    Softvk(#[from] softvk::Error),
}

/// The wgpu application's own objects. Fields drop in order: device and queue first (so their
/// teardown is still validated), then our messenger, then adapter and instance.
pub struct Host {
    /// wgpu's device (it owns the `VkDevice`).
    pub device: wgpu::Device,
    /// wgpu's queue (it owns the `VkQueue`).
    pub queue: wgpu::Queue,
    capture: Option<Capture>,
    /// Whether the layer was loaded with [`crate::LAYER_ENABLES`]'s submit-time switch.
    submit_time_sync_validation: bool,
    /// Whether the device was opened with `VK_KHR_push_descriptor` (softvk's faster binding
    /// path; without it softvk binds cached descriptor sets).
    push_descriptor: bool,
    /// The adapter the device was opened on.
    pub adapter: wgpu::Adapter,
    /// wgpu's instance (it owns the `VkInstance`).
    pub instance: wgpu::Instance,
}

/// Order of preference among device types, as softvk's own `Context::new` ranks them.
fn rank(device_type: wgpu::DeviceType) -> u8 {
    match device_type {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    }
}

impl Host {
    /// A headless wgpu host on the Vulkan backend.
    ///
    /// With `validation`, wgpu enables `VK_LAYER_KHRONOS_validation`
    /// ([`wgpu::InstanceFlags::VALIDATION`]). wgpu-hal 30 also chains `VkValidationFeaturesEXT`
    /// with `SYNCHRONIZATION_VALIDATION` into `vkCreateInstance` whenever the layer offers
    /// `VK_EXT_validation_features`, so synchronization validation is on with it; this checks
    /// that the layer offers it and fails otherwise. Hazards between command buffers and
    /// submissions are checked too only when `VK_LAYER_ENABLES` says so
    /// ([`crate::LAYER_ENABLES`], [`Host::submit_time_sync_validation`]). Every warning and
    /// error of the layer is kept for [`Host::take_validation_messages`].
    pub fn new(validation: bool) -> Result<Self, HostError> {
        if validation {
            check_layer()?;
        }
        // DEBUG enables VK_EXT_debug_utils on the instance: our messenger and softvk's object
        // names need it.
        let mut flags = wgpu::InstanceFlags::DEBUG;
        if validation {
            flags |= wgpu::InstanceFlags::VALIDATION;
        }
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN,
            flags,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapter = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN))
            .into_iter()
            .min_by_key(|a| rank(a.get_info().device_type))
            .ok_or(HostError::NoAdapter)?;

        let capture = if validation {
            // SAFETY: the hal instance is alive as long as `instance`, which `Host` drops after
            // the capture (field order); DEBUG enabled debug_utils, checked here.
            let hal = unsafe { instance.as_hal::<Vulkan>() }
                .ok_or_else(|| HostError::Wgpu("the instance is not on Vulkan".into()))?;
            let shared = hal.shared_instance();
            if !shared.extensions().contains(&ash::ext::debug_utils::NAME) {
                return Err(HostError::Wgpu(
                    "the instance has no VK_EXT_debug_utils to listen to the layer".into(),
                ));
            }
            // SAFETY: as above.
            Some(
                unsafe { Capture::new(shared.entry(), shared.raw_instance()) }.map_err(
                    |result| HostError::Vulkan {
                        call: "vkCreateDebugUtilsMessengerEXT",
                        result,
                    },
                )?,
            )
        } else {
            None
        };

        let (device, queue, push_descriptor) = open_device(&adapter)?;
        Ok(Self {
            device,
            queue,
            submit_time_sync_validation: capture.is_some()
                && crate::submit_time_sync_validation_requested(),
            capture,
            push_descriptor,
            adapter,
            instance,
        })
    }

    /// Whether the validation layer is on and listened to.
    pub fn validation_enabled(&self) -> bool {
        self.capture.is_some()
    }

    /// Whether synchronization validation also checks hazards between command buffers and
    /// between submissions (validation on, and `VK_LAYER_ENABLES` holding
    /// [`crate::LAYER_ENABLES`]'s switch when the host was made). Without it, layer 1.3.239
    /// checks within each command buffer only.
    pub fn submit_time_sync_validation(&self) -> bool {
        self.submit_time_sync_validation
    }

    /// Every message of the validation layer since the last call (none without validation).
    pub fn take_validation_messages(&self) -> Vec<Message> {
        self.capture.as_ref().map(Capture::take).unwrap_or_default()
    }

    /// Adopts wgpu's instance, physical device, device and queue as a softvk [`Context`]. softvk
    /// destroys none of them; it makes its own allocator and command pool on wgpu's device
    /// (wgpu-hal's allocator is private to it).
    ///
    /// # Safety
    /// The context and everything made from it are dropped before this host, and never used
    /// after the GPU work recorded with them is submitted unless that work has completed before
    /// they are dropped. softvk's own submit-and-wait conveniences use wgpu's queue: call them
    /// only from the thread that drives wgpu, never while wgpu may be submitting.
    pub unsafe fn softvk_context(&self) -> Result<Context, HostError> {
        let not_vulkan = || HostError::Wgpu("not on the Vulkan backend".into());
        // SAFETY: the guards only borrow wgpu's objects for this function; the handles cloned out
        // of them stay valid as long as the host (the caller's contract).
        unsafe {
            let instance = self.instance.as_hal::<Vulkan>().ok_or_else(not_vulkan)?;
            let device = self.device.as_hal::<Vulkan>().ok_or_else(not_vulkan)?;
            let queue = self.queue.as_hal::<Vulkan>().ok_or_else(not_vulkan)?;
            let shared = instance.shared_instance();
            let raw = RawHandles {
                entry: shared.entry().clone(),
                instance: shared.raw_instance().clone(),
                physical_device: device.raw_physical_device(),
                device: device.raw_device().clone(),
                queue: queue.as_raw(),
                queue_family_index: device.queue_family_index(),
                allocator: None,
                debug_utils: shared.extensions().contains(&ash::ext::debug_utils::NAME),
                push_descriptor: self.push_descriptor,
            };
            // Instance 1.3 (wgpu-hal asks for it when the loader has 1.1+), device created with
            // REQUIRED_DEVICE_EXTENSIONS by `open_device`, queue of a compute-capable family
            // (wgpu's queue family 0 supports graphics and compute).
            Ok(Context::from_raw(raw)?)
        }
    }

    /// A deliberate, harmless violation on wgpu's device: a buffer with no usage flags
    /// (`VUID-VkBufferCreateInfo-usage-requiredbitmask`), created and destroyed at once. The
    /// layer must report it; that proves the capture is live.
    pub fn provoke_harmless_violation(&self) -> Result<(), HostError> {
        // SAFETY: the guard borrows wgpu's device for this call only; the buffer is ours and
        // destroyed before the call returns, unused.
        unsafe {
            let device = self
                .device
                .as_hal::<Vulkan>()
                .ok_or_else(|| HostError::Wgpu("not on the Vulkan backend".into()))?;
            let raw = device.raw_device();
            let buffer = raw
                .create_buffer(&vk::BufferCreateInfo::default().size(64), None)
                .map_err(|result| HostError::Vulkan {
                    call: "vkCreateBuffer",
                    result,
                })?;
            raw.destroy_buffer(buffer, None);
        }
        Ok(())
    }
}

/// Checks, before the instance exists, that the Khronos layer is installed and offers
/// `VK_EXT_validation_features` (the switch wgpu-hal uses for synchronization validation).
fn check_layer() -> Result<(), HostError> {
    // SAFETY: loads the system loader; only enumeration calls follow.
    let entry = unsafe { ash::Entry::load() }.map_err(|_| HostError::NoAdapter)?;
    // SAFETY: plain enumeration on a loaded entry.
    let layers = unsafe { entry.enumerate_instance_layer_properties() }.map_err(|result| {
        HostError::Vulkan {
            call: "vkEnumerateInstanceLayerProperties",
            result,
        }
    })?;
    if !layers
        .iter()
        .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER))
    {
        return Err(HostError::ValidationLayerMissing);
    }
    // SAFETY: as above, for the layer's own extensions.
    let extensions =
        unsafe { entry.enumerate_instance_extension_properties(Some(VALIDATION_LAYER)) }.map_err(
            |result| HostError::Vulkan {
                call: "vkEnumerateInstanceExtensionProperties",
                result,
            },
        )?;
    if !extensions
        .iter()
        .any(|e| e.extension_name_as_c_str() == Ok(ash::ext::validation_features::NAME))
    {
        return Err(HostError::NoSyncValidation);
    }
    Ok(())
}

/// Opens the device through wgpu-hal so that it carries softvk's extensions
/// (`VK_KHR_push_descriptor`), which wgpu's own `request_device` would not enable, then hands it
/// to wgpu.
/// Whether the adapter's device offers `VK_KHR_push_descriptor`.
fn push_descriptor_supported(adapter: &wgpu::Adapter) -> Result<bool, HostError> {
    // SAFETY: the guard borrows the adapter for this call only.
    let hal = unsafe { adapter.as_hal::<Vulkan>() }
        .ok_or_else(|| HostError::Wgpu("the adapter is not on Vulkan".into()))?;
    Ok(hal
        .physical_device_capabilities()
        .supports_extension(PUSH_DESCRIPTOR_EXTENSION))
}

fn open_device(adapter: &wgpu::Adapter) -> Result<(wgpu::Device, wgpu::Queue, bool), HostError> {
    let features = wgpu::Features::empty();
    let limits = adapter.limits();
    let memory_hints = wgpu::MemoryHints::Performance;
    let open = {
        // SAFETY: the guard borrows the adapter for this block only.
        let hal = unsafe { adapter.as_hal::<Vulkan>() }
            .ok_or_else(|| HostError::Wgpu("the adapter is not on Vulkan".into()))?;
        for &extension in REQUIRED_DEVICE_EXTENSIONS {
            if !hal
                .physical_device_capabilities()
                .supports_extension(extension)
            {
                return Err(HostError::MissingExtension {
                    adapter: adapter.get_info().name,
                    extension: extension.to_string_lossy().into_owned(),
                });
            }
        }
        // Optional for softvk, and faster: enabled where the device has it.
        let push = hal
            .physical_device_capabilities()
            .supports_extension(PUSH_DESCRIPTOR_EXTENSION);
        let add_softvk_extensions: Box<hal_vk::CreateDeviceCallback<'_>> = Box::new(move |args| {
            let optional = push.then_some(PUSH_DESCRIPTOR_EXTENSION);
            for extension in REQUIRED_DEVICE_EXTENSIONS.iter().copied().chain(optional) {
                if !args.extensions.contains(&extension) {
                    args.extensions.push(extension);
                }
            }
        });
        // SAFETY: the callback only adds extensions the physical device supports (checked
        // above); it removes nothing and turns no feature off.
        unsafe {
            hal.open_with_callback(
                features,
                &limits,
                &memory_hints,
                Some(add_softvk_extensions),
            )
        }
        .map_err(|e| HostError::Wgpu(format!("opening the Vulkan device: {e}")))?
    };
    let push = push_descriptor_supported(adapter)?;
    // SAFETY: `open` was opened on this adapter's hal adapter with these features and limits.
    unsafe {
        adapter.create_device_from_hal(
            open,
            &wgpu::DeviceDescriptor {
                label: Some("softvk-wgpu-host"),
                required_features: features,
                required_limits: limits,
                memory_hints,
                ..Default::default()
            },
        )
    }
    .map(|(device, queue)| (device, queue, push))
    .map_err(|e| HostError::Wgpu(format!("adopting the Vulkan device: {e}")))
}
