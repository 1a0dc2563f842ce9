//! Descriptor sets for contexts without `VK_KHR_push_descriptor` ([`DescriptorMode::Sets`]).
//!
//! A push descriptor lives in the command buffer; a descriptor set must outlive every command
//! buffer it is recorded into, and [`Recorder`] cannot know when a host's command buffer is
//! submitted, finished or freed. So each set is made once per kernel layout and list of bound
//! ranges, written once, never updated again (so recording it into any number of command buffers,
//! pending or not, is safe) and kept until one of the things it names goes away: the last
//! [`Buffer`] it binds (whose drop may hand its handle value to a new buffer) or its kernel's set
//! layout. Both drops already require that no pending work uses them, so freeing the set then is
//! as safe as destroying the buffer. A fitting loop binds the same ranges every iteration, so it
//! finds its sets in the cache after the first one and allocates nothing more.
//!
//! [`DescriptorMode::Sets`]: super::DescriptorMode::Sets
//! [`Recorder`]: super::Recorder
//! [`Buffer`]: super::Buffer

use std::collections::HashMap;
use std::sync::Mutex;

use ash::vk;

use crate::error::{Result, VkContext};

/// Sets one pool holds. Pools are made as needed, so this only trades the number of pools
/// against the memory of one that stays mostly empty.
const SETS_PER_POOL: u32 = 128;

/// Storage-buffer descriptors one pool holds: four per set, about what softvk's kernels bind on
/// average (one to eleven). A set that needs more than a pool has left goes to another pool.
const BUFFERS_PER_POOL: u32 = 4 * SETS_PER_POOL;

/// What a cached set was written with: the kernel's set layout and, in binding order, each
/// range's buffer, offset and size.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
struct SetKey {
    layout: vk::DescriptorSetLayout,
    ranges: Vec<(vk::Buffer, u64, u64)>,
}

impl SetKey {
    /// The distinct buffers the set names.
    fn buffers(&self) -> impl Iterator<Item = vk::Buffer> + '_ {
        self.ranges
            .iter()
            .enumerate()
            .filter(|&(i, r)| !self.ranges[..i].iter().any(|q| q.0 == r.0))
            .map(|(_, r)| r.0)
    }
}

/// A descriptor pool and what is left in it, by softvk's own count (the validation layer checks
/// that no allocation asks for more than that).
struct Pool {
    raw: vk::DescriptorPool,
    sets_left: u32,
    buffers_left: u32,
}

/// A cached set, the pool it came from and its number of descriptors (given back on free).
struct CachedSet {
    raw: vk::DescriptorSet,
    pool: usize,
    buffers: u32,
}

#[derive(Default)]
struct State {
    pools: Vec<Pool>,
    sets: HashMap<SetKey, CachedSet>,
    /// For each buffer, the keys of the cached sets that name it: what its drop evicts.
    by_buffer: HashMap<vk::Buffer, Vec<SetKey>>,
}

/// The cache of one context's descriptor sets (in [`Shared`], where buffer and kernel drops can
/// reach it). One lock covers the map and the pools, which Vulkan requires to be externally
/// synchronized for allocating and freeing; binding a set needs no lock.
///
/// [`Shared`]: super::shared::Shared
#[derive(Default)]
pub(crate) struct DescriptorCache {
    state: Mutex<State>,
    /// Sets allocated since the context was made ([`super::Counters::descriptor_sets`]).
    allocated: std::sync::atomic::AtomicU64,
}

impl DescriptorCache {
    /// Sets cached now.
    pub(crate) fn len(&self) -> usize {
        self.lock().sets.len()
    }

    /// Sets allocated so far.
    pub(crate) fn allocated(&self) -> u64 {
        self.allocated.load(std::sync::atomic::Ordering::Relaxed)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // The state stays consistent across a panic (each step completes or is not taken).
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Destroys every pool, which frees the sets still in them.
    ///
    /// # Safety
    /// No command buffer that binds one of the sets is pending, and none is recorded again.
    pub(crate) unsafe fn destroy(&mut self, device: &ash::Device) {
        let state = self.state.get_mut().unwrap_or_else(|e| e.into_inner());
        state.sets.clear();
        state.by_buffer.clear();
        for pool in state.pools.drain(..) {
            // SAFETY: the pool belongs to `device`; the caller guarantees its sets are idle.
            unsafe { device.destroy_descriptor_pool(pool.raw, None) };
        }
    }
}

impl State {
    /// Removes the set of `key` from the cache and frees it. `dropped` is a buffer whose index
    /// entry the caller has removed already.
    fn free(&mut self, device: &ash::Device, key: &SetKey, dropped: Option<vk::Buffer>) {
        let Some(set) = self.sets.remove(key) else {
            return;
        };
        for buffer in key.buffers().filter(|&b| Some(b) != dropped) {
            if let Some(keys) = self.by_buffer.get_mut(&buffer) {
                keys.retain(|k| k != key);
                if keys.is_empty() {
                    self.by_buffer.remove(&buffer);
                }
            }
        }
        let pool = &mut self.pools[set.pool];
        // SAFETY: the set was allocated from this pool (made with FREE_DESCRIPTOR_SET), whose
        // use the cache's lock serializes; no pending command buffer binds it (the callers' drop
        // contracts). vkFreeDescriptorSets always succeeds.
        let _ = unsafe { device.free_descriptor_sets(pool.raw, &[set.raw]) };
        pool.sets_left += 1;
        pool.buffers_left += set.buffers;
    }

    /// Allocates a set of `layout` with `buffers` descriptors: from the newest pool with room
    /// (by our count; a fragmented pool may still refuse, then the next is tried), else from a
    /// new pool.
    fn allocate(
        &mut self,
        device: &ash::Device,
        name: impl Fn(vk::DescriptorPool, &str),
        layout: vk::DescriptorSetLayout,
        buffers: u32,
    ) -> Result<(vk::DescriptorSet, usize)> {
        let layouts = [layout];
        let try_pool = |pool: &Pool| {
            let info = vk::DescriptorSetAllocateInfo::default()
                .descriptor_pool(pool.raw)
                .set_layouts(&layouts);
            // SAFETY: pool and layout belong to `device`; the pool has room for one set of
            // `buffers` storage-buffer descriptors by our count; the lock serializes the pool.
            unsafe { device.allocate_descriptor_sets(&info) }.map(|sets| sets[0])
        };
        for index in (0..self.pools.len()).rev() {
            let pool = &mut self.pools[index];
            if pool.sets_left == 0 || pool.buffers_left < buffers {
                continue;
            }
            match try_pool(pool) {
                Ok(set) => {
                    pool.sets_left -= 1;
                    pool.buffers_left -= buffers;
                    return Ok((set, index));
                }
                Err(vk::Result::ERROR_FRAGMENTED_POOL | vk::Result::ERROR_OUT_OF_POOL_MEMORY) => {}
                Err(result) => return Err(result).vk("vkAllocateDescriptorSets"),
            }
        }
        let capacity = BUFFERS_PER_POOL.max(buffers);
        // Room for `capacity` of either kind: a set's descriptors of both kinds are counted
        // together against `buffers_left`, so neither kind can run past its own size.
        let sizes = [
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::STORAGE_BUFFER,
                descriptor_count: capacity,
            },
            vk::DescriptorPoolSize {
                ty: vk::DescriptorType::STORAGE_TEXEL_BUFFER,
                descriptor_count: capacity,
            },
        ];
        let info = vk::DescriptorPoolCreateInfo::default()
            .flags(vk::DescriptorPoolCreateFlags::FREE_DESCRIPTOR_SET)
            .max_sets(SETS_PER_POOL)
            .pool_sizes(&sizes);
        // SAFETY: valid device; the pool is destroyed with the cache.
        let raw =
            unsafe { device.create_descriptor_pool(&info, None) }.vk("vkCreateDescriptorPool")?;
        name(raw, "softvk descriptor sets");
        self.pools.push(Pool {
            raw,
            sets_left: SETS_PER_POOL,
            buffers_left: capacity,
        });
        let index = self.pools.len() - 1;
        let pool = &mut self.pools[index];
        let set = try_pool(pool).vk("vkAllocateDescriptorSets")?;
        pool.sets_left -= 1;
        pool.buffers_left -= buffers;
        Ok((set, index))
    }
}

impl DescriptorCache {
    /// The set that binds `ranges` (buffer, offset, size) to the bindings of set layout
    /// `layout`, in binding order: the cached one, or a new one allocated on `device` now
    /// (its pool named by `name` where a new pool is made) and written with `writes` (those of
    /// `ranges`, with no set named).
    ///
    /// The ranges were checked against the kernel's interface and the device's limits.
    pub(crate) fn set(
        &self,
        device: &ash::Device,
        name: impl Fn(vk::DescriptorPool, &str),
        layout: vk::DescriptorSetLayout,
        ranges: Vec<(vk::Buffer, u64, u64)>,
        writes: &[vk::WriteDescriptorSet<'_>],
    ) -> Result<vk::DescriptorSet> {
        let key = SetKey { layout, ranges };
        let mut state = self.lock();
        if let Some(set) = state.sets.get(&key) {
            return Ok(set.raw);
        }
        let buffers = key.ranges.len() as u32;
        let (raw, pool) = state.allocate(device, name, layout, buffers)?;
        self.allocated
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let writes: Vec<_> = writes.iter().map(|w| w.dst_set(raw)).collect();
        // SAFETY: a fresh set of this device, not yet bound anywhere (so no command buffer
        // sees the update); the writes match its layout (the kernel's reflected bindings); the
        // buffers are alive (borrowed by the caller's ranges) and the ranges valid.
        unsafe { device.update_descriptor_sets(&writes, &[]) };
        for buffer in key.buffers() {
            state.by_buffer.entry(buffer).or_default().push(key.clone());
        }
        state.sets.insert(key, CachedSet { raw, pool, buffers });
        Ok(raw)
    }

    /// Frees the cached sets that name `buffer`, which is being dropped (its handle value may
    /// come back with a new buffer, which must not find them).
    pub(crate) fn evict_buffer(&self, device: &ash::Device, buffer: vk::Buffer) {
        let mut state = self.lock();
        let Some(keys) = state.by_buffer.remove(&buffer) else {
            return;
        };
        for key in keys {
            state.free(device, &key, Some(buffer));
        }
    }

    /// Frees the cached sets of set layout `layout`, whose kernel is being dropped.
    pub(crate) fn evict_layout(&self, device: &ash::Device, layout: vk::DescriptorSetLayout) {
        let mut state = self.lock();
        let keys: Vec<SetKey> = state
            .sets
            .keys()
            .filter(|k| k.layout == layout)
            .cloned()
            .collect();
        for key in keys {
            state.free(device, &key, None);
        }
    }
}
