//! The Vulkan compute core: context, memory, kernels and recording.

mod context;
mod descriptors;
mod dispatch;
pub mod gate;
mod kernel;
mod memory;
mod passes;
mod record;
mod texel_views;

pub use context::{
    Context, ContextOptions, Counters, DescriptorMode, DeviceInfo, PUSH_DESCRIPTOR_EXTENSION,
    PhysicalDeviceEntry, REQUIRED_DEVICE_EXTENSIONS, RawHandles, list_devices,
};
pub use dispatch::GradOut;
pub(crate) use dispatch::{check_binding, check_floats, check_texels, groups};
pub use kernel::{
    BindingKind, BindingSpec, Kernel, KernelSpec, KernelVariants, TEXEL_BYTES, TEXEL_FORMAT, specs,
};
pub use memory::{Buffer, BufferRange, MemoryKind, align_up};
pub(crate) use passes::pass_size;
pub use record::{INDIRECT_ARGS_BYTES, PassTime, Recorded, Recorder, Timer};
