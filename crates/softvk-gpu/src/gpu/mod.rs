//! The Vulkan compute core: context, memory, kernels and recording.
//!
//! Bottom up, none importing from above: the caches that a dropped buffer or kernel evicts from
//! (descriptor sets, texel views); the device state the context shares with everything it makes
//! (`shared`, which holds those caches); the context; buffers and kernels, which hold that state
//! to free themselves; recording and dispatch.
//!
//! **One way to get a pipeline: [`Context::kernel`]`(&specs::NAME, &constants)`.** The context
//! builds each (kernel, specialization constants) once, through its pipeline cache, and shares
//! the `Arc<Kernel>` with every caller for its own life: a pipeline costs a compile and, on
//! lavapipe, its machine code in memory, and many objects record the same kernels (a sampler
//! per training object). A struct that records one kernel in several specializations keeps a
//! [`KernelVariants`] (the kernel named once) and asks it with the constants at hand; it asks
//! the same cache. `Kernel` has no public constructor: nothing else builds a pipeline.

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
pub use dispatch::{check_binding, check_floats, check_texels, groups};
pub use kernel::{BindingKind, BindingSpec, Kernel, KernelSpec, KernelVariants, specs};
pub use memory::{Buffer, BufferRange, MemoryKind, align_up};
pub use passes::pass_size;
pub use record::{INDIRECT_ARGS_BYTES, PassTime, Recorded, Recorder, Timer};
pub use texel_views::{TEXEL_BYTES, TEXEL_FORMAT};
