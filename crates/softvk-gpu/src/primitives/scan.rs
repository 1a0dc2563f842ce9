//! Exclusive prefix sum over `u32` of any length, multi-level: each level reduces blocks of
//! [`SCAN_BLOCK`] elements to one sum, the sums are scanned (recursively), and each block is then
//! scanned locally on top of its block's offset. Ranges larger than the device's
//! `maxStorageBufferRange` are processed in chunks of bound sub-ranges, so lavapipe's 128 MiB limit
//! does not cap the length. Sums wrap modulo 2^32, exactly as the CPU twin's.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder, specs};

/// Elements per workgroup (mirrors `BLOCK` in `kernels/gpu/include/scan_config.glsl`). Each level
/// past one block costs two more dispatches, and on llvmpipe a dispatch costs about 0.1 ms of
/// its own: 8 192 (rather than 4 096) makes binning's scan of a mesh's per-face counts one
/// dispatch up to 8 192 faces (spot-256's bin count 0.85 -> 0.63 ms; BENCHMARKS.md).
pub const SCAN_BLOCK: u32 = 8192;

/// Push constants of `kernels/gpu/scan/scan_reduce.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ReducePush {
    n: u32,
    block_base: u32,
}

/// Push constants of `kernels/gpu/scan/scan_block.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct BlockPush {
    n: u32,
    block_base: u32,
    use_offsets: u32,
    total_index: u32,
}

/// The scan's pipelines, made once per context.
pub struct Scan {
    reduce: Arc<Kernel>,
    block: Arc<Kernel>,
}

/// Scratch for scans of up to `capacity` elements: the block sums of every level, and the
/// grand total of the last scan recorded with it.
pub struct ScanScratch {
    levels: Vec<Buffer>,
    total: Buffer,
    capacity: u64,
}

impl ScanScratch {
    /// Scratch for scans of up to `capacity` elements.
    pub fn new(ctx: &Context, capacity: u64) -> Result<Self> {
        let mut levels = Vec::new();
        let mut n = capacity;
        while n > u64::from(SCAN_BLOCK) {
            n = n.div_ceil(u64::from(SCAN_BLOCK));
            levels.push(ctx.create_buffer(
                &format!("scan block sums (level {})", levels.len()),
                4 * n,
                MemoryKind::Device,
            )?);
        }
        let total = ctx.create_buffer("scan total", 4, MemoryKind::Device)?;
        Ok(Self {
            levels,
            total,
            capacity,
        })
    }

    /// Holds the sum of all elements of the last scan recorded with this scratch (one `u32`).
    pub fn total(&self) -> &Buffer {
        &self.total
    }

    /// The largest element count this scratch serves.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }
}

impl Scan {
    /// The scan's pipelines (the context's, shared by every scan: [`Context::kernel`]).
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            reduce: ctx.kernel(&specs::SCAN_REDUCE, &[])?,
            block: ctx.kernel(&specs::SCAN_BLOCK, &[])?,
        })
    }

    /// Records an exclusive scan of the first `n` `u32`s of `input` into `output` (which may be
    /// the same range: the scan works in place). The sum of all `n` lands in
    /// [`ScanScratch::total`]. `n = 0` records nothing.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        scratch: &ScanScratch,
        input: BufferRange<'_>,
        output: BufferRange<'_>,
        n: u64,
    ) -> Result<()> {
        if n > scratch.capacity {
            return Err(Error::Limit(format!(
                "scan of {n} elements exceeds its scratch capacity {}",
                scratch.capacity
            )));
        }
        if n > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "scan of {n} elements: at most 2^32 - 1"
            )));
        }
        for (what, range) in [("input", &input), ("output", &output)] {
            if range.size < 4 * n {
                return Err(Error::Limit(format!(
                    "scan {what} `{}`: {} bytes hold fewer than {n} elements",
                    range.buffer.name(),
                    range.size
                )));
            }
        }
        if n == 0 {
            return Ok(());
        }
        self.record_level(rec, scratch, input, output, n, 0, true)
    }

    #[allow(clippy::too_many_arguments)]
    fn record_level(
        &self,
        rec: &mut Recorder<'_>,
        scratch: &ScanScratch,
        input: BufferRange<'_>,
        output: BufferRange<'_>,
        n: u64,
        level: usize,
        write_total: bool,
    ) -> Result<()> {
        let block = u64::from(SCAN_BLOCK);
        let chunk = chunk_len(rec.context());
        let blocks = n.div_ceil(block);
        let chunks = || (0..n.div_ceil(chunk)).map(move |c| (c * chunk, chunk.min(n - c * chunk)));

        let sums = if blocks > 1 {
            let sums = &scratch.levels[level];
            for (start, len) in chunks() {
                let push = ReducePush {
                    n: len as u32,
                    block_base: (start / block) as u32,
                };
                rec.dispatch(
                    &self.reduce,
                    &specs::ScanReduceBindings {
                        input: input.sub(4 * start, 4 * len),
                        block_sums: sums.range(0, 4 * blocks),
                    }
                    .for_kernel(&self.reduce)?,
                    &push,
                    len.div_ceil(block) as u32,
                )?;
            }
            let sums_range = sums.range(0, 4 * blocks);
            self.record_level(
                rec,
                scratch,
                sums_range,
                sums_range,
                blocks,
                level + 1,
                false,
            )?;
            Some(sums_range)
        } else {
            None
        };

        for (start, len) in chunks() {
            let last = start + len == n;
            let push = BlockPush {
                n: len as u32,
                block_base: (start / block) as u32,
                use_offsets: u32::from(sums.is_some()),
                total_index: if write_total && last {
                    (len - 1) as u32
                } else {
                    u32::MAX
                },
            };
            // Without a level above, the offsets binding is unused; bind the total as a stand-in.
            let offsets = sums.unwrap_or_else(|| scratch.total.whole());
            rec.dispatch(
                &self.block,
                &specs::ScanBlockBindings {
                    input: input.sub(4 * start, 4 * len),
                    output: output.sub(4 * start, 4 * len),
                    block_offsets: offsets,
                    total: scratch.total.whole(),
                }
                .for_kernel(&self.block)?,
                &push,
                len.div_ceil(block) as u32,
            )?;
        }
        Ok(())
    }

    /// Convenience: uploads `data`, scans it on the GPU and reads back `(exclusive scan, total)`.
    pub fn run(&self, ctx: &Context, data: &[u32]) -> Result<(Vec<u32>, u32)> {
        let n = data.len() as u64;
        let buffer = ctx.upload_buffer("scan data", data)?;
        let scratch = ScanScratch::new(ctx, n)?;
        ctx.submit_and_wait(|rec| {
            let range = buffer.range(0, 4 * n.max(1));
            self.record(rec, &scratch, range, range, n)
        })?;
        let total = if n == 0 {
            0
        } else {
            ctx.read_buffer::<u32>(&scratch.total, 0, 1)?[0]
        };
        Ok((ctx.read_buffer(&buffer, 0, data.len())?, total))
    }
}

/// Elements per chunk: the largest multiple of [`SCAN_BLOCK`] whose bytes fit one binding.
fn chunk_len(ctx: &Context) -> u64 {
    let max_elems = u64::from(ctx.info().limits.max_storage_buffer_range) / 4;
    (max_elems / u64::from(SCAN_BLOCK)).max(1) * u64::from(SCAN_BLOCK)
}

/// CPU twin.
pub mod cpu {
    /// Exclusive prefix sum with wrapping adds, and the wrapped total.
    pub fn exclusive_scan(data: &[u32]) -> (Vec<u32>, u32) {
        let mut acc = 0u32;
        let out = data
            .iter()
            .map(|&v| {
                let before = acc;
                acc = acc.wrapping_add(v);
                before
            })
            .collect();
        (out, acc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_structs_match_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<ReducePush>() as u32,
            specs::SCAN_REDUCE.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<BlockPush>() as u32,
            specs::SCAN_BLOCK.push_constant_size
        );
        // ITEMS (scan_config.glsl) elements an invocation.
        assert_eq!(specs::SCAN_BLOCK.workgroup_size[0] * 32, SCAN_BLOCK);
        assert_eq!(specs::SCAN_REDUCE.bindings.len(), 2);
        assert_eq!(specs::SCAN_BLOCK.bindings.len(), 4);
    }

    #[test]
    fn cpu_twin_scans_and_wraps() {
        assert_eq!(cpu::exclusive_scan(&[]), (vec![], 0));
        assert_eq!(cpu::exclusive_scan(&[3, 1, 4]), (vec![0, 3, 4], 8));
        assert_eq!(cpu::exclusive_scan(&[u32::MAX, 2]), (vec![0, u32::MAX], 1));
    }
}
