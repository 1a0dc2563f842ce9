//! The Vulkan compute core: context, memory, kernels and recording.
//!
//! Bottom up, none importing from above: the caches that a dropped buffer or kernel evicts from
//! (descriptor sets, texel views); the device state the context shares with everything it makes
//! (`shared`, which holds those caches); the context; buffers and kernels, which hold that state
//! to free themselves; recording and dispatch.

mod context;
mod descriptors;
mod dispatch;
pub mod gate;
mod kernel;
mod memory;
mod passes;
mod record;
mod shared;
mod texel_views;

pub use context::{
    Context, ContextOptions, Counters, DescriptorMode, DeviceInfo, PUSH_DESCRIPTOR_EXTENSION,
    PhysicalDeviceEntry, REQUIRED_DEVICE_EXTENSIONS, RawHandles, list_devices,
};
pub use dispatch::GradOut;
pub(crate) use dispatch::{check_binding, check_floats, check_texels, groups};
pub use kernel::{BindingKind, BindingSpec, Kernel, KernelSpec, KernelVariants, specs};
pub use memory::{Buffer, BufferRange, MemoryKind, align_up};
pub(crate) use passes::pass_size;
pub use record::{INDIRECT_ARGS_BYTES, PassTime, Recorded, Recorder, Timer};
pub use texel_views::{TEXEL_BYTES, TEXEL_FORMAT};
