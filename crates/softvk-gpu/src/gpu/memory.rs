//! Buffers through gpu-allocator. Every buffer is named, its size rounded up to the device's
//! alignment ([`super::DeviceInfo::buffer_alignment`]), and it frees itself on drop through the
//! shared device state, so an early `?` never leaks GPU memory.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};

use super::context::Context;
use super::shared::Shared;
use crate::error::{Error, Result, VkContext};

/// Where a buffer lives and what it is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemoryKind {
    /// Device-local storage for kernels; filled and read through copies.
    Device,
    /// Host-visible, written by the CPU and read by the GPU (staging uploads, small parameters).
    Upload,
    /// Host-visible, written by the GPU and read back by the CPU.
    Readback,
}

impl MemoryKind {
    fn location(self) -> MemoryLocation {
        match self {
            MemoryKind::Device => MemoryLocation::GpuOnly,
            MemoryKind::Upload => MemoryLocation::CpuToGpu,
            MemoryKind::Readback => MemoryLocation::GpuToCpu,
        }
    }
}

/// A GPU buffer. Usable as a storage buffer and as a copy source and destination.
///
/// Made by [`Context::create_buffer`] (softvk owns it and frees it on drop) or borrowed from a
/// host engine by [`Context::import_buffer`] (the host owns it; drop only forgets the handle).
pub struct Buffer {
    pub(crate) raw: vk::Buffer,
    allocation: Option<Allocation>,
    /// Whether drop destroys `raw` (false for an imported host buffer).
    owned: bool,
    size: u64,
    kind: MemoryKind,
    name: String,
    shared: Arc<Shared>,
}

impl Buffer {
    /// The raw handle, for hosts binding it in their own pipelines.
    pub fn raw(&self) -> vk::Buffer {
        self.raw
    }

    /// Size in bytes (after alignment rounding).
    pub fn size(&self) -> u64 {
        self.size
    }

    /// The debug name given at creation.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether softvk owns this buffer (false: borrowed by [`Context::import_buffer`]).
    pub fn is_owned(&self) -> bool {
        self.owned
    }

    /// Memory kind chosen at creation.
    pub fn kind(&self) -> MemoryKind {
        self.kind
    }

    /// The whole buffer as a binding range.
    pub fn whole(&self) -> BufferRange<'_> {
        BufferRange {
            buffer: self,
            offset: 0,
            size: self.size,
        }
    }

    /// `size` bytes from `offset`, as a binding range.
    pub fn range(&self, offset: u64, size: u64) -> BufferRange<'_> {
        debug_assert!(offset + size <= self.size, "range outside `{}`", self.name);
        BufferRange {
            buffer: self,
            offset,
            size,
        }
    }

    /// The mapped bytes of an `Upload` or `Readback` buffer.
    pub fn mapped(&self) -> Option<&[u8]> {
        self.allocation.as_ref().and_then(Allocation::mapped_slice)
    }

    /// The mapped bytes of an `Upload` or `Readback` buffer, writable.
    pub fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        self.allocation
            .as_mut()
            .and_then(Allocation::mapped_slice_mut)
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // Cached descriptor sets that name this buffer go first, owned or imported: a later
        // buffer may get the same handle value, and must not find sets written for this one.
        self.shared.evict_buffer(self.raw);
        if !self.owned {
            // The host's buffer: the host destroys it.
            return;
        }
        // SAFETY: the buffer belongs to `shared.device`, which outlives it (we hold the Arc);
        // callers wait for GPU work using the buffer before dropping it.
        unsafe { self.shared.device.destroy_buffer(self.raw, None) };
        if let Some(allocation) = self.allocation.take() {
            if let Ok(mut allocator) = self.shared.allocator.lock() {
                let _ = allocator.free(allocation);
            }
        }
    }
}

/// A byte range of a buffer, as bound to a kernel.
#[derive(Clone, Copy)]
pub struct BufferRange<'a> {
    /// The buffer.
    pub buffer: &'a Buffer,
    /// Offset in bytes; a multiple of the device's `minStorageBufferOffsetAlignment`.
    pub offset: u64,
    /// Size in bytes; at most `maxStorageBufferRange`.
    pub size: u64,
}

impl<'a> BufferRange<'a> {
    /// `Ok` when this range holds `need` bytes; else [`Error::BufferTooSmall`] naming the
    /// buffer, both sizes and `what` needs them.
    pub fn require(&self, need: u64, what: &str) -> Result<()> {
        if self.size < need {
            return Err(Error::BufferTooSmall {
                buffer: self.buffer.name().to_string(),
                have: self.size,
                need,
                what: what.to_string(),
            });
        }
        Ok(())
    }

    /// `size` bytes starting `offset` bytes into this range.
    pub fn sub(&self, offset: u64, size: u64) -> BufferRange<'a> {
        debug_assert!(
            offset + size <= self.size,
            "sub-range outside `{}`",
            self.buffer.name()
        );
        BufferRange {
            buffer: self.buffer,
            offset: self.offset + offset,
            size,
        }
    }
}

/// Rounds `value` up to a multiple of `align`.
pub fn align_up(value: u64, align: u64) -> u64 {
    value.div_ceil(align) * align
}

impl Context {
    /// Creates a buffer of at least `size` bytes (rounded up to the device's alignment; a zero
    /// size still gets one aligned unit, so empty inputs need no special case downstream).
    ///
    /// A size over [`Context::max_buffer_size`] is [`Error::BufferTooLarge`], before any Vulkan
    /// call; an allocation the device then cannot make is [`Error::Allocation`]. Both name the
    /// buffer and the size.
    pub fn create_buffer(&self, name: &str, size: u64, kind: MemoryKind) -> Result<Buffer> {
        let align = self.info().buffer_alignment();
        let (limit, what) = self.max_buffer_size(kind);
        let too_large = || Error::BufferTooLarge {
            name: name.to_string(),
            size,
            limit,
            what,
        };
        if size > limit {
            return Err(too_large());
        }
        let size = size
            .max(1)
            .checked_next_multiple_of(align)
            .filter(|&s| s <= limit)
            .ok_or_else(too_large)?;
        let device = &self.shared.device;
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(
                vk::BufferUsageFlags::STORAGE_BUFFER
                    | vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER
                    | vk::BufferUsageFlags::INDIRECT_BUFFER
                    | vk::BufferUsageFlags::TRANSFER_SRC
                    | vk::BufferUsageFlags::TRANSFER_DST,
            )
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid device and create info.
        let raw = unsafe { device.create_buffer(&info, None) }.vk("vkCreateBuffer")?;
        // SAFETY: `raw` was just created on this device.
        let requirements = unsafe { device.get_buffer_memory_requirements(raw) };
        let allocation = self
            .shared
            .allocator
            .lock()
            .map_err(|_| Error::Limit("the allocator's lock is poisoned".into()))
            .and_then(|mut a| {
                a.allocate(&AllocationCreateDesc {
                    name,
                    requirements,
                    location: kind.location(),
                    linear: true,
                    allocation_scheme: AllocationScheme::GpuAllocatorManaged,
                })
                .map_err(|source| Error::Allocation {
                    name: name.to_string(),
                    size,
                    source,
                })
            });
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: not bound to anything yet.
                unsafe { device.destroy_buffer(raw, None) };
                return Err(e);
            }
        };
        // Wrap first so every later failure frees both buffer and memory.
        let buffer = Buffer {
            raw,
            allocation: Some(allocation),
            owned: true,
            size,
            kind,
            name: name.to_string(),
            shared: Arc::clone(&self.shared),
        };
        let allocation = buffer.allocation.as_ref().expect("set above");
        // SAFETY: memory from the allocator for exactly these requirements; not yet bound.
        unsafe { device.bind_buffer_memory(raw, allocation.memory(), allocation.offset()) }
            .vk("vkBindBufferMemory")?;
        self.name(raw, name);
        Ok(buffer)
    }

    /// Borrows a buffer a host engine made on this context's device, so softvk can bind ranges
    /// of it (a host's vertex buffer as a scene's positions, a host's image as an upstream
    /// gradient). softvk never destroys, frees or maps it; [`Buffer::kind`] reports
    /// [`MemoryKind::Device`] and [`Buffer::mapped`] `None`.
    ///
    /// # Safety
    /// `raw` is a buffer of this context's device with at least `size` bytes bound to memory,
    /// created with `STORAGE_BUFFER` usage (and `TRANSFER_SRC`/`TRANSFER_DST` where softvk
    /// copies or fills it, `STORAGE_TEXEL_BUFFER` where it is bound to a
    /// [`BindingKind::Texels`](super::BindingKind::Texels) binding: the tiled fine passes' face
    /// setups and colours, and the image and aux their backward reads; never an upstream
    /// gradient or a result), and it outlives the returned `Buffer` and every command buffer that
    /// uses it.
    pub unsafe fn import_buffer(&self, raw: vk::Buffer, size: u64, name: &str) -> Buffer {
        self.name(raw, name);
        Buffer {
            raw,
            allocation: None,
            owned: false,
            size,
            kind: MemoryKind::Device,
            name: name.to_string(),
            shared: Arc::clone(&self.shared),
        }
    }

    /// The largest buffer of `kind` the device can hold, and which limit that is: the largest
    /// memory heap with a memory type for `kind` (device-local for [`MemoryKind::Device`],
    /// host-visible and coherent for the others), or `maxMemoryAllocationSize` (a buffer is one
    /// allocation) when that is smaller.
    pub fn max_buffer_size(&self, kind: MemoryKind) -> (u64, &'static str) {
        let info = self.info();
        let (required, heap) = match kind {
            MemoryKind::Device => (
                vk::MemoryPropertyFlags::DEVICE_LOCAL,
                "the largest device-local memory heap",
            ),
            MemoryKind::Upload | MemoryKind::Readback => (
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                "the largest host-visible memory heap",
            ),
        };
        let memory = &info.memory;
        let types = &memory.memory_types[..memory.memory_type_count as usize];
        let largest_heap = types
            .iter()
            .filter(|t| t.property_flags.contains(required))
            .filter_map(|t| memory.memory_heaps.get(t.heap_index as usize))
            .map(|h| h.size)
            .max();
        let allocation = info.max_memory_allocation_size;
        match largest_heap {
            // A device without such memory: gpu-allocator says so on allocation.
            None if allocation == 0 => (u64::MAX, heap),
            Some(h) if allocation == 0 || h <= allocation => (h, heap),
            _ => (allocation, "maxMemoryAllocationSize"),
        }
    }

    /// Creates a device buffer holding `data` (through a staging copy, waited on).
    pub fn upload_buffer<T: bytemuck::Pod>(&self, name: &str, data: &[T]) -> Result<Buffer> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let buffer = self.create_buffer(name, bytes.len() as u64, MemoryKind::Device)?;
        self.write_buffer(&buffer, 0, data)?;
        Ok(buffer)
    }

    /// Writes `data` at byte `offset` of `buffer` through a staging copy, and waits for it.
    /// (Host-visible buffers can also be written directly with [`Buffer::mapped_mut`].)
    pub fn write_buffer<T: bytemuck::Pod>(
        &self,
        buffer: &Buffer,
        offset: u64,
        data: &[T],
    ) -> Result<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.is_empty() {
            return Ok(());
        }
        if offset
            .checked_add(bytes.len() as u64)
            .is_none_or(|end| end > buffer.size())
        {
            return Err(Error::Limit(format!(
                "write of {} bytes at {offset} overflows buffer `{}` ({} bytes)",
                bytes.len(),
                buffer.name(),
                buffer.size()
            )));
        }
        let mut staging = self.create_buffer(
            &format!("{} (staging)", buffer.name()),
            bytes.len() as u64,
            MemoryKind::Upload,
        )?;
        staging
            .mapped_mut()
            .ok_or_else(|| Error::Limit("upload memory is not host-mapped".into()))?[..bytes.len()]
            .copy_from_slice(bytes);
        self.counters
            .staging_copies
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.submit_and_wait(|rec| {
            rec.copy(&staging, 0, buffer, offset, bytes.len() as u64);
            Ok(())
        })
    }

    /// Reads `count` elements of `T` from byte `offset` of `buffer` (through a readback copy,
    /// waited on).
    pub fn read_buffer<T: bytemuck::Pod>(
        &self,
        buffer: &Buffer,
        offset: u64,
        count: usize,
    ) -> Result<Vec<T>> {
        let len = (count as u64).saturating_mul(std::mem::size_of::<T>() as u64);
        if count == 0 {
            return Ok(Vec::new());
        }
        if offset
            .checked_add(len)
            .is_none_or(|end| end > buffer.size())
        {
            return Err(Error::Limit(format!(
                "read of {len} bytes at {offset} overflows buffer `{}` ({} bytes)",
                buffer.name(),
                buffer.size()
            )));
        }
        let readback = self.create_buffer(
            &format!("{} (readback)", buffer.name()),
            len,
            MemoryKind::Readback,
        )?;
        self.counters
            .staging_copies
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.submit_and_wait(|rec| {
            rec.copy(buffer, offset, &readback, 0, len);
            Ok(())
        })?;
        let bytes = readback
            .mapped()
            .ok_or_else(|| Error::Limit("readback memory is not host-mapped".into()))?;
        // Copy out element-wise: the mapping is not guaranteed aligned for T.
        Ok(bytemuck::pod_collect_to_vec(&bytes[..len as usize]))
    }
}
