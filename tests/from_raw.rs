//! A host engine's own device, queue and command buffer, adopted with `Context::from_raw`:
//! softvk records into the host's command buffer, the host submits, and softvk destroys none of
//! the host's objects.

mod common;

use std::ffi::{CStr, c_void};
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use softvk::gpu::{
    Context, DescriptorMode, PUSH_DESCRIPTOR_EXTENSION, REQUIRED_DEVICE_EXTENSIONS, RawHandles,
    Recorder,
};
use softvk::primitives::{Scan, ScanScratch, scan};

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

#[test]
fn host_device_and_command_buffer_run_a_softvk_kernel() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let validation = common::validation_wanted();
    // SAFETY: the whole test is host-side Vulkan setup, torn down in reverse order at the end.
    unsafe {
        // --- The host engine's setup, none of it softvk's. ---
        let entry = ash::Entry::load().expect("Vulkan loader");
        let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_2);
        let layers = [c"VK_LAYER_KHRONOS_validation".as_ptr()];
        let extensions = [ash::ext::debug_utils::NAME.as_ptr()];
        let mut instance_info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_extension_names(&extensions);
        if validation {
            instance_info = instance_info.enabled_layer_names(&layers);
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
        // This host enables push descriptors where the device has them (tests/descriptor_sets.rs
        // has one that never does).
        let push_descriptor = instance
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
        // The host's allocator, shared with softvk.
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

        // --- softvk adopts it. ---
        let ctx = Context::from_raw(RawHandles {
            entry: entry.clone(),
            instance: instance.clone(),
            physical_device,
            device: device.clone(),
            queue,
            queue_family_index: family,
            allocator: Some(Arc::clone(&allocator)),
            debug_utils: true,
            push_descriptor,
        })
        .expect("adopt the host's device");
        assert_eq!(
            ctx.descriptor_mode(),
            if push_descriptor {
                DescriptorMode::Push
            } else {
                DescriptorMode::Sets
            }
        );
        let scan = Scan::new(&ctx).unwrap();
        let data: Vec<u32> = (0..5000u32).map(|i| i % 17).collect();
        let buffer = ctx.upload_buffer("host scan", &data).unwrap();
        let scratch = ScanScratch::new(&ctx, data.len() as u64).unwrap();

        // The host records softvk's kernel into its own command buffer and submits it itself.
        device
            .begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())
            .unwrap();
        {
            let mut rec = Recorder::new(&ctx, cmd);
            let range = buffer.whole();
            scan.record(&mut rec, &scratch, range, range, data.len() as u64)
                .unwrap();
        }
        device.end_command_buffer(cmd).unwrap();
        let fence = device
            .create_fence(&vk::FenceCreateInfo::default(), None)
            .unwrap();
        device
            .queue_submit(
                queue,
                &[vk::SubmitInfo::default().command_buffers(&[cmd])],
                fence,
            )
            .unwrap();
        device.wait_for_fences(&[fence], true, u64::MAX).unwrap();

        let out: Vec<u32> = ctx.read_buffer(&buffer, 0, data.len()).unwrap();
        assert_eq!(out, scan::cpu::exclusive_scan(&data).0);
        let total: Vec<u32> = ctx.read_buffer(scratch.total(), 0, 1).unwrap();
        assert_eq!(total[0], data.iter().sum::<u32>());

        // softvk lets go of everything it made; the host's objects must all still be alive.
        drop((buffer, scratch, scan, ctx));
        assert_eq!(
            Arc::strong_count(&allocator),
            1,
            "softvk kept the host's allocator"
        );
        device.device_wait_idle().expect("host device still alive");
        drop(allocator);
        device.destroy_fence(fence, None);
        device.destroy_command_pool(pool, None);
        device.destroy_device(None);
        debug.destroy_debug_utils_messenger(messenger, None);
        instance.destroy_instance(None);
    }
    let messages = HOST_MESSAGES.lock().unwrap();
    assert!(
        messages.is_empty(),
        "validation messages:\n{}",
        messages.join("\n")
    );
}
