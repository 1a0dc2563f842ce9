//! Stable LSD radix sort of `(u64 key, u32 value)` pairs, [`RADIX_BITS`] bits per pass. Each pass
//! counts digits per block (digit-major), scans the counts with [`Scan`] (or, for a few blocks,
//! each scatter workgroup sums the counts before its own), and scatters every pair
//! to `offset[digit][block] + rank`, where the rank among equal digits follows input order: the
//! sort is stable, so sorting by (tile, depth) keys keeps equal keys in face order.
//!
//! Keys travel as `[u32; 2]` (lo, hi) so kernels need no `shaderInt64`.
//!
//! A sort of at most [`SMALL_SORT_MAX`] pairs (one block) with a count known when recording runs
//! every pass in one workgroup and one dispatch (`radix_small.comp`): the same passes, the same
//! result (a stable sort's output is unique), without the three dispatches a pass that cost
//! about 0.1 ms each on llvmpipe whatever their size.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::scan::{Scan, ScanScratch};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder, specs};

/// Bits sorted per pass (mirrors `RADIX_BITS` in `kernels/gpu/include/radix_config.glsl`).
pub const RADIX_BITS: u32 = 4;
const RADIX: u64 = 1 << RADIX_BITS;
/// Elements per workgroup (mirrors `BLOCK` in `kernels/gpu/include/radix_config.glsl`).
pub const SORT_BLOCK: u32 = 4096;

/// The most pairs [`RadixSort::record`] sorts in one workgroup (`radix_small.comp`): one block.
/// The grid field's backward sorts its 4 096 anchors by cell every fit-field iteration (17 bits,
/// five passes): one dispatch instead of fifteen. Sphere probing's 12 288 rays (three blocks)
/// sorted in one workgroup were slower on llvmpipe than the three workgroups' dispatches
/// (+0.8 ms a sort: a workgroup runs on one core), so larger sorts keep them.
pub const SMALL_SORT_MAX: u64 = SORT_BLOCK as u64;

/// Sorts of at most this many blocks skip a pass's scan dispatch: each scatter workgroup sums
/// the few digit counts before its own (at most `RADIX` × this many) itself. On llvmpipe a
/// dispatch costs about 0.1 ms whatever its size (sphere probing's rays: three blocks).
const SCATTER_SCAN_MAX_BLOCKS: u64 = 8;

/// Push constants of `radix_small.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct SmallPush {
    n: u32,
    key_bits: u32,
}

/// Push constants of `radix_count.comp` and `radix_scatter.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct RadixPush {
    n: u32,
    shift: u32,
    n_blocks: u32,
    digit_mask: u32,
    counted: u32,
    copy_tail: u32,
    scan_counts: u32,
}

/// The sort's pipelines, made once per context.
pub struct RadixSort {
    small: Arc<Kernel>,
    count: Arc<Kernel>,
    scatter: Arc<Kernel>,
    scan: Scan,
}

/// Ping-pong buffers and digit counts for sorts of up to `capacity` pairs.
pub struct SortScratch {
    keys_alt: Buffer,
    values_alt: Buffer,
    counts: Buffer,
    scan: ScanScratch,
    capacity: u64,
}

impl SortScratch {
    /// Scratch for sorts of up to `capacity` pairs. Fails if the key array would not fit one
    /// storage-buffer binding (`maxStorageBufferRange / 8` pairs: 16 Mi on lavapipe).
    pub fn new(ctx: &Context, capacity: u64) -> Result<Self> {
        let max = u64::from(ctx.info().limits.max_storage_buffer_range) / 8;
        if capacity > max {
            return Err(Error::Limit(format!(
                "radix sort of {capacity} pairs: this device binds at most {max} keys at once"
            )));
        }
        let counts_len = RADIX * capacity.div_ceil(u64::from(SORT_BLOCK)).max(1);
        // The one-workgroup sort ping-pongs between two halves of the alternate buffers.
        let alt = capacity.max(2 * capacity.min(SMALL_SORT_MAX));
        Ok(Self {
            keys_alt: ctx.create_buffer("sort keys (ping-pong)", 8 * alt, MemoryKind::Device)?,
            values_alt: ctx.create_buffer(
                "sort values (ping-pong)",
                4 * alt,
                MemoryKind::Device,
            )?,
            counts: ctx.create_buffer("sort digit counts", 4 * counts_len, MemoryKind::Device)?,
            scan: ScanScratch::new(ctx, counts_len)?,
            capacity,
        })
    }

    /// The largest pair count this scratch serves.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }
}

impl RadixSort {
    /// Builds the sort pipelines.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            small: ctx.kernel(&specs::RADIX_SMALL, &[])?,
            count: ctx.kernel(&specs::RADIX_COUNT, &[])?,
            scatter: ctx.kernel(&specs::RADIX_SCATTER, &[])?,
            scan: Scan::new(ctx)?,
        })
    }

    /// Records a stable sort of the first `n` pairs of `keys` (`[u32; 2]` each) and `values`
    /// (`u32` each), in place, by the low `key_bits` bits of the keys (higher bits are ignored;
    /// fewer bits mean fewer passes).
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        scratch: &SortScratch,
        keys: &Buffer,
        values: &Buffer,
        n: u64,
        key_bits: u32,
    ) -> Result<()> {
        self.record_inner(rec, scratch, keys, values, n, key_bits, None)
    }

    /// As [`RadixSort::record`] for a count only the GPU knows: sorts the first
    /// `min(capacity, count[0])` pairs (`count`: a u32 written by earlier GPU work, e.g. a scan's
    /// total) and leaves the pairs after them where they are. The dispatches are sized for
    /// `capacity`; the blocks past the count only write zero digit counts (and, in the first
    /// pass, copy their pairs through to the ping-pong buffers, so every pass count ends with
    /// the tail in place).
    #[allow(clippy::too_many_arguments)]
    pub fn record_counted(
        &self,
        rec: &mut Recorder<'_>,
        scratch: &SortScratch,
        keys: &Buffer,
        values: &Buffer,
        capacity: u64,
        count: BufferRange<'_>,
        key_bits: u32,
    ) -> Result<()> {
        if count.size < 4 {
            return Err(Error::Limit(format!(
                "sort count buffer `{}` holds no u32",
                count.buffer.name()
            )));
        }
        self.record_inner(rec, scratch, keys, values, capacity, key_bits, Some(count))
    }

    #[allow(clippy::too_many_arguments)]
    fn record_inner(
        &self,
        rec: &mut Recorder<'_>,
        scratch: &SortScratch,
        keys: &Buffer,
        values: &Buffer,
        n: u64,
        key_bits: u32,
        count: Option<BufferRange<'_>>,
    ) -> Result<()> {
        if n > scratch.capacity {
            return Err(Error::Limit(format!(
                "sort of {n} pairs exceeds its scratch capacity {}",
                scratch.capacity
            )));
        }
        if key_bits > 64 {
            return Err(Error::Limit(format!(
                "sort keys have 64 bits, not {key_bits}"
            )));
        }
        if keys.size() < 8 * n || values.size() < 4 * n {
            return Err(Error::Limit(format!(
                "sort buffers `{}`/`{}` hold fewer than {n} pairs",
                keys.name(),
                values.name()
            )));
        }
        if n == 0 || key_bits == 0 {
            return Ok(());
        }
        if count.is_none() && n <= SMALL_SORT_MAX {
            return rec.dispatch(
                &self.small,
                &specs::RadixSmallBindings {
                    keys: keys.range(0, 8 * n),
                    vals: values.range(0, 4 * n),
                    keys_alt: scratch.keys_alt.range(0, 16 * n),
                    vals_alt: scratch.values_alt.range(0, 8 * n),
                }
                .for_kernel(&self.small)?,
                &SmallPush {
                    n: n as u32,
                    key_bits,
                },
                1,
            );
        }
        let n_blocks = n.div_ceil(u64::from(SORT_BLOCK));
        let counts = scratch.counts.range(0, 4 * RADIX * n_blocks);
        let passes = key_bits.div_ceil(RADIX_BITS);
        let scan_in_scatter = n_blocks <= SCATTER_SCAN_MAX_BLOCKS;
        let mut src = (keys, values);
        let mut dst = (&scratch.keys_alt, &scratch.values_alt);
        for pass in 0..passes {
            let shift = pass * RADIX_BITS;
            let digit_bits = (key_bits - shift).min(RADIX_BITS);
            let push = RadixPush {
                n: n as u32,
                shift,
                n_blocks: n_blocks as u32,
                digit_mask: (1 << digit_bits) - 1,
                counted: u32::from(count.is_some()),
                copy_tail: u32::from(count.is_some() && pass == 0),
                scan_counts: u32::from(scan_in_scatter),
            };
            // Without a count, any buffer binds there (it is not read).
            let count_range = count.unwrap_or(counts);
            rec.dispatch(
                &self.count,
                &specs::RadixCountBindings {
                    keys: src.0.range(0, 8 * n),
                    counts,
                    count: count_range,
                }
                .for_kernel(&self.count)?,
                &push,
                n_blocks as u32,
            )?;
            if !scan_in_scatter {
                self.scan
                    .record(rec, &scratch.scan, counts, counts, RADIX * n_blocks)?;
            }
            rec.dispatch(
                &self.scatter,
                &specs::RadixScatterBindings {
                    keys_in: src.0.range(0, 8 * n),
                    vals_in: src.1.range(0, 4 * n),
                    keys_out: dst.0.range(0, 8 * n),
                    vals_out: dst.1.range(0, 4 * n),
                    offsets: counts,
                    count: count_range,
                }
                .for_kernel(&self.scatter)?,
                &push,
                n_blocks as u32,
            )?;
            std::mem::swap(&mut src, &mut dst);
        }
        if passes % 2 == 1 {
            // The result sits in the ping-pong buffers; bring it home.
            rec.copy(src.0, 0, keys, 0, 8 * n);
            rec.copy(src.1, 0, values, 0, 4 * n);
        }
        Ok(())
    }

    /// Convenience: uploads the pairs, sorts them on the GPU and reads them back.
    pub fn run(
        &self,
        ctx: &Context,
        keys: &[u64],
        values: &[u32],
        key_bits: u32,
    ) -> Result<(Vec<u64>, Vec<u32>)> {
        if keys.len() != values.len() {
            return Err(Error::Input(format!(
                "sort: {} keys but {} values",
                keys.len(),
                values.len()
            )));
        }
        let n = keys.len() as u64;
        let key_words: Vec<[u32; 2]> = keys.iter().map(|&k| split_key(k)).collect();
        let key_buf = ctx.upload_buffer("sort keys", &key_words)?;
        let value_buf = ctx.upload_buffer("sort values", values)?;
        let scratch = SortScratch::new(ctx, n)?;
        ctx.submit_and_wait(|rec| self.record(rec, &scratch, &key_buf, &value_buf, n, key_bits))?;
        let sorted_keys: Vec<[u32; 2]> = ctx.read_buffer(&key_buf, 0, keys.len())?;
        Ok((
            sorted_keys.into_iter().map(join_key).collect(),
            ctx.read_buffer(&value_buf, 0, values.len())?,
        ))
    }
}

/// A `u64` key as the `(lo, hi)` words the kernels read.
pub fn split_key(key: u64) -> [u32; 2] {
    [key as u32, (key >> 32) as u32]
}

/// Inverse of [`split_key`].
pub fn join_key(words: [u32; 2]) -> u64 {
    u64::from(words[0]) | (u64::from(words[1]) << 32)
}

/// CPU twin.
pub mod cpu {
    /// Stable sort of `(key, value)` pairs by the low `key_bits` bits of the key; keys keep
    /// their high bits, as on the GPU.
    pub fn sort_pairs(keys: &[u64], values: &[u32], key_bits: u32) -> (Vec<u64>, Vec<u32>) {
        let mask = if key_bits >= 64 {
            u64::MAX
        } else {
            (1u64 << key_bits) - 1
        };
        let mut pairs: Vec<(u64, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
        pairs.sort_by_key(|&(k, _)| k & mask); // `sort_by_key` is stable
        pairs.into_iter().unzip()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_struct_matches_the_kernels_layout() {
        let size = std::mem::size_of::<RadixPush>() as u32;
        assert_eq!(size, specs::RADIX_COUNT.push_constant_size);
        assert_eq!(size, specs::RADIX_SCATTER.push_constant_size);
        assert_eq!(specs::RADIX_SCATTER.workgroup_size[0] * 16, SORT_BLOCK);
        assert_eq!(specs::RADIX_SCATTER.bindings.len(), 6);
        assert_eq!(specs::RADIX_COUNT.bindings.len(), 3);
        let small = std::mem::size_of::<SmallPush>() as u32;
        assert_eq!(small, specs::RADIX_SMALL.push_constant_size);
        assert_eq!(specs::RADIX_SMALL.workgroup_size[0] * 16, SORT_BLOCK);
    }

    #[test]
    fn key_words_round_trip() {
        for k in [0, 1, u64::MAX, 0x1234_5678_9abc_def0] {
            assert_eq!(join_key(split_key(k)), k);
        }
    }

    #[test]
    fn cpu_twin_is_stable_and_honours_key_bits() {
        let (k, v) = cpu::sort_pairs(&[0x13, 0x02, 0x03, 0x12], &[0, 1, 2, 3], 4);
        assert_eq!(k, vec![0x02, 0x12, 0x13, 0x03]);
        assert_eq!(v, vec![1, 3, 0, 2]);
    }
}
