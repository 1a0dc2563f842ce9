//! The Vulkan compute core: context, memory, kernels and recording.

mod context;
pub mod gate;
mod kernel;
mod memory;
mod record;

pub use context::{
    Context, ContextOptions, Counters, DeviceInfo, PhysicalDeviceEntry, REQUIRED_DEVICE_EXTENSIONS,
    RawHandles, list_devices,
};
pub use kernel::{BindingSpec, Kernel, KernelSpec, KernelVariants, specs};
pub use memory::{Buffer, BufferRange, MemoryKind, align_up};
pub use record::{INDIRECT_ARGS_BYTES, PassTime, Recorded, Recorder, Timer};
