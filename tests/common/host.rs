//! A host engine's own Vulkan objects, made with ash as an engine would (none of them softvk's):
//! instance with its own validation listener, device (with or without
//! `VK_KHR_push_descriptor`), queue, command pool and buffer, fence and `gpu-allocator`.
//! Tests adopt it with `Context::from_raw` and check that softvk leaves it intact.

use std::ffi::{CStr, c_void};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use softvk::gpu::{Context, PUSH_DESCRIPTOR_EXTENSION, REQUIRED_DEVICE_EXTENSIONS, RawHandles};

/// What the host's own validation listener heard (warnings and errors).
static HOST_MESSAGES: Mutex<Vec<String>> = Mutex::new(Vec::new());

unsafe extern "system" fn host_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    _: *mut c_void,
) -> vk::Bool32 {
    if severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
            | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
    ) {
        // SAFETY: the layer passes valid callback data for the duration of the call.
        let message = unsafe { CStr::from_ptr((*data).p_message) }
            .to_string_lossy()
            .into_owned();
        HOST_MESSAGES.lock().unwrap().push(message);
    }
    vk::FALSE
}

/// The host's objects. Torn down by [`HostDevice::finish`], after softvk let go of them.
pub struct HostDevice {
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    debug: ash::ext::debug_utils::Instance,
    messenger: vk::DebugUtilsMessengerEXT,
    pub physical_device: vk::PhysicalDevice,
    pub device: ash::Device,
    pub queue: vk::Queue,
    pub family: u32,
    pub pool: vk::CommandPool,
    pub cmd: vk::CommandBuffer,
    fence: vk::Fence,
    pub allocator: Arc<Mutex<Allocator>>,
    /// Whether the device was made with `VK_KHR_push_descriptor`.
    pub push_descriptor: bool,
}

impl HostDevice {
    /// The host's setup, validated when `validation` (with its listener proven live).
    /// `push_descriptor`: enable `VK_KHR_push_descriptor` where the device has it (true), or
    /// never (false).
    ///
    /// # Safety
    /// Plain Vulkan object creation; the caller tears it down with [`HostDevice::finish`].
    pub unsafe fn new(validation: bool, push_descriptor: bool) -> Self {
        // SAFETY: host-side Vulkan setup (the caller's contract).
        unsafe {
            let entry = ash::Entry::load().expect("Vulkan loader");
            let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_2);
            let layers = [c"VK_LAYER_KHRONOS_validation".as_ptr()];
            let extensions = [
                ash::ext::debug_utils::NAME.as_ptr(),
                ash::ext::validation_features::NAME.as_ptr(),
            ];
            // The layer's shader validation cache off, as softvk's own contexts have it
            // (src/gpu/context/create.rs: a file every device rewrites without locking).
            let disabled = [vk::ValidationFeatureDisableEXT::SHADER_VALIDATION_CACHE];
            let mut features =
                vk::ValidationFeaturesEXT::default().disabled_validation_features(&disabled);
            let mut instance_info = vk::InstanceCreateInfo::default()
                .application_info(&app)
                .enabled_extension_names(&extensions[..1]);
            if validation {
                instance_info = instance_info
                    .enabled_layer_names(&layers)
                    .enabled_extension_names(&extensions)
                    .push_next(&mut features);
            }
            let instance = entry
                .create_instance(&instance_info, None)
                .expect("host instance");
            let debug = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let messenger = debug
                .create_debug_utils_messenger(
                    &vk::DebugUtilsMessengerCreateInfoEXT::default()
                        .message_severity(
                            vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                                | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                        )
                        .message_type(
                            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                        )
                        .pfn_user_callback(Some(host_callback)),
                    None,
                )
                .unwrap();
            let physical_device = instance.enumerate_physical_devices().unwrap()[0];
            let family = instance
                .get_physical_device_queue_family_properties(physical_device)
                .iter()
                .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
                .expect("a compute queue") as u32;
            let priorities = [1.0];
            let queues = [vk::DeviceQueueCreateInfo::default()
                .queue_family_index(family)
                .queue_priorities(&priorities)];
            let push_descriptor = push_descriptor
                && instance
                    .enumerate_device_extension_properties(physical_device)
                    .unwrap()
                    .iter()
                    .any(|e| e.extension_name_as_c_str() == Ok(PUSH_DESCRIPTOR_EXTENSION));
            let device_extensions: Vec<_> = REQUIRED_DEVICE_EXTENSIONS
                .iter()
                .chain(push_descriptor.then_some(&PUSH_DESCRIPTOR_EXTENSION))
                .map(|e| e.as_ptr())
                .collect();
            let device = instance
                .create_device(
                    physical_device,
                    &vk::DeviceCreateInfo::default()
                        .queue_create_infos(&queues)
                        .enabled_extension_names(&device_extensions),
                    None,
                )
                .expect("host device");
            let queue = device.get_device_queue(family, 0);
            if validation {
                // Prove the host's listener is live: a usage-less buffer must be reported.
                let bad = vk::BufferCreateInfo::default().size(64);
                device.destroy_buffer(device.create_buffer(&bad, None).unwrap(), None);
                let caught = std::mem::take(&mut *HOST_MESSAGES.lock().unwrap());
                assert!(!caught.is_empty(), "the validation layer is not listening");
            }
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
            let fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .unwrap();
            let allocator = Arc::new(Mutex::new(
                Allocator::new(&AllocatorCreateDesc {
                    instance: instance.clone(),
                    device: device.clone(),
                    physical_device,
                    debug_settings: Default::default(),
                    buffer_device_address: false,
                    allocation_sizes: Default::default(),
                })
                .unwrap(),
            ));
            Self {
                entry,
                instance,
                debug,
                messenger,
                physical_device,
                device,
                queue,
                family,
                pool,
                cmd,
                fence,
                allocator,
                push_descriptor,
            }
        }
    }

    /// softvk adopts the host's objects, sharing its allocator.
    ///
    /// # Safety
    /// As [`Context::from_raw`]; the context is dropped before [`HostDevice::finish`].
    pub unsafe fn adopt(&self) -> Context {
        // SAFETY: the handles are this host's, made above (the caller's contract).
        unsafe {
            Context::from_raw(RawHandles {
                entry: self.entry.clone(),
                instance: self.instance.clone(),
                physical_device: self.physical_device,
                device: self.device.clone(),
                queue: self.queue,
                queue_family_index: self.family,
                allocator: Some(Arc::clone(&self.allocator)),
                debug_utils: true,
                push_descriptor: self.push_descriptor,
            })
        }
        .expect("adopt the host's device")
    }

    /// Begins the host's command buffer.
    ///
    /// # Safety
    /// The command buffer is not pending.
    pub unsafe fn begin(&self) {
        // SAFETY: the caller's contract.
        unsafe {
            self.device
                .begin_command_buffer(self.cmd, &vk::CommandBufferBeginInfo::default())
                .unwrap();
        }
    }

    /// Ends the host's command buffer, submits it (the host's submission) and waits.
    ///
    /// # Safety
    /// The command buffer was begun and recorded by this thread only.
    pub unsafe fn end_submit_and_wait(&self) {
        // SAFETY: the caller's contract; the fence is reset after every wait.
        unsafe {
            self.device.end_command_buffer(self.cmd).unwrap();
            self.device
                .queue_submit(
                    self.queue,
                    &[vk::SubmitInfo::default().command_buffers(&[self.cmd])],
                    self.fence,
                )
                .unwrap();
            self.device
                .wait_for_fences(&[self.fence], true, u64::MAX)
                .unwrap();
            self.device.reset_fences(&[self.fence]).unwrap();
        }
    }

    /// After softvk let go of everything (its context dropped): the host's objects must all
    /// still be alive and the allocator the host's alone; then the host tears them down and
    /// its listener must have heard nothing.
    ///
    /// # Safety
    /// Nothing of softvk's is alive; no host object is in use.
    pub unsafe fn finish(self) {
        assert_eq!(
            Arc::strong_count(&self.allocator),
            1,
            "softvk kept the host's allocator"
        );
        // SAFETY: the caller's contract; reverse order of creation.
        unsafe {
            self.device
                .device_wait_idle()
                .expect("host device still alive");
            drop(self.allocator);
            self.device.destroy_fence(self.fence, None);
            self.device.destroy_command_pool(self.pool, None);
            self.device.destroy_device(None);
            self.debug
                .destroy_debug_utils_messenger(self.messenger, None);
            self.instance.destroy_instance(None);
        }
        let messages = HOST_MESSAGES.lock().unwrap();
        assert!(
            messages.is_empty(),
            "validation messages:\n{}",
            messages.join("\n")
        );
    }
}
