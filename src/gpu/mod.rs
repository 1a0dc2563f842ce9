//! The Vulkan compute core: context, memory, kernels and recording.

mod context;
mod kernel;
mod memory;
mod record;

pub use context::{
    list_devices, Context, ContextOptions, DeviceInfo, PhysicalDeviceEntry, RawHandles,
    REQUIRED_DEVICE_EXTENSIONS,
};
pub use kernel::{specs, BindingSpec, Kernel, KernelSpec};
pub use memory::{align_up, Buffer, BufferRange, MemoryKind};
pub use record::{PassTime, Recorded, Recorder, Timer};
