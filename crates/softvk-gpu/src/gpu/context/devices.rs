//! The physical devices: which are usable (a compute queue, the required extensions), how they
//! rank, which one a context picks, and what it reports of the picked one ([`DeviceInfo`]).

use std::ffi::CStr;

use ash::vk;

use super::{DeviceInfo, PUSH_DESCRIPTOR_EXTENSION, REQUIRED_DEVICE_EXTENSIONS};
use crate::error::{Error, Result, VkContext};

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
pub(super) fn has_device_extension(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    name: &CStr,
) -> bool {
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

pub(super) fn pick_device(
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

pub(super) fn query_info(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    family: u32,
) -> DeviceInfo {
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
