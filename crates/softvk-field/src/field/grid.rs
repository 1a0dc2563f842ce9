//! The dense grid field's kernels: `field_grid_eval`, and the deterministic backward
//! (`field_grid_keys` → stable radix sort by cell → `field_grid_chunks` → `field_grid_corner`
//! once per corner).
//!
//! The backward scatters each point's 8 trilinear weights × dL/df to the corners of its cell
//! without float atomics: the points of a batch are sorted by cell (stably, so a cell's points
//! stay in point order); one invocation per chunk of [`GRID_CHUNK`] sorted points sums each run
//! of one cell ("piece") sequentially; then, corner by corner (eight dispatches), the first
//! position of each cell's run adds the cell's pieces in position order to the node at that
//! corner. A node is one corner of at most one cell, so no two invocations of a dispatch share
//! it, and each node sums its (up to) 8 cells in corner order. Only occupied cells work: a
//! gather over every node cost a 48³ grid milliseconds on llvmpipe for the few thousand anchors
//! of a fit-field iteration. Every sum has a fixed order, so repeated runs are bit-identical.
//! One invocation's loops are bounded by the chunk (256 points) and by `batch / GRID_CHUNK + 1`
//! pieces: far under llvmpipe's cap for any input.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::{Cube, check_binding_bytes};
use crate::error::Result;
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::primitives::{RadixSort, SortScratch};
use crate::specs;

/// Sorted points per chunk of `field_grid_chunks` (`GRID_CHUNK` in the kernels).
pub(crate) const GRID_CHUNK: u32 = 256;
/// Points per backward batch (the scratch is sized for one).
pub(crate) const GRID_BATCH: u32 = 1 << 16;

/// Push constants of `field_grid_eval` and `field_grid_keys`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GridPush {
    cube: [f32; 4],
    res: u32,
    n: u32,
    pad: [u32; 2],
}

/// Push constants of `field_grid_bounds` and `field_grid_chunks`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct CountPush {
    n: u32,
}

/// Push constants of `field_grid_corner`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct CornerPush {
    n: u32,
    res: u32,
    corner: u32,
    pad: u32,
}

pub(crate) struct GridGpu {
    res: u32,
    eval: Arc<Kernel>,
    keys_kernel: Arc<Kernel>,
    chunks: Arc<Kernel>,
    corner: Arc<Kernel>,
    sort: RadixSort,
    sort_scratch: SortScratch,
    keys: Buffer,
    values: Buffer,
    records: Buffer,
    partial: Buffer,
}

impl GridGpu {
    pub fn new(ctx: &Context, res: u32) -> Result<Self> {
        let what = format!("grid field of resolution {res}");
        let nodes = u64::from(res).pow(3);
        check_binding_bytes(ctx, &what, 4 * nodes)?;
        let batch = u64::from(GRID_BATCH);
        Ok(Self {
            res,
            eval: ctx.kernel(&specs::FIELD_GRID_EVAL, &[])?,
            keys_kernel: ctx.kernel(&specs::FIELD_GRID_KEYS, &[])?,
            chunks: ctx.kernel(&specs::FIELD_GRID_CHUNKS, &[])?,
            corner: ctx.kernel(&specs::FIELD_GRID_CORNER, &[])?,
            sort: RadixSort::new(ctx)?,
            sort_scratch: SortScratch::new(ctx, batch)?,
            keys: ctx.create_buffer("grid field sort keys", 8 * batch, MemoryKind::Device)?,
            values: ctx.create_buffer("grid field sort values", 4 * batch, MemoryKind::Device)?,
            records: ctx.create_buffer("grid field records", 16 * batch, MemoryKind::Device)?,
            partial: ctx.create_buffer("grid field piece sums", 32 * batch, MemoryKind::Device)?,
        })
    }

    fn push(&self, cube: &Cube, n: u32) -> GridPush {
        GridPush {
            cube: cube.to_f32(),
            res: self.res,
            n,
            pad: [0; 2],
        }
    }

    pub fn record_eval(
        &self,
        rec: &mut Recorder<'_>,
        cube: &Cube,
        params: BufferRange<'_>,
        points: BufferRange<'_>,
        n: u32,
        phi: BufferRange<'_>,
    ) -> Result<()> {
        rec.dispatch(
            &self.eval,
            &specs::FieldGridEvalBindings {
                params,
                points,
                phi,
            }
            .for_kernel(&self.eval)?,
            &self.push(cube, n),
            n.div_ceil(64),
        )
    }

    /// One batch of at most [`GRID_BATCH`] points.
    #[allow(clippy::too_many_arguments)]
    pub fn record_backward_batch(
        &self,
        rec: &mut Recorder<'_>,
        cube: &Cube,
        params: BufferRange<'_>,
        points: BufferRange<'_>,
        n: u32,
        d_phi: BufferRange<'_>,
        d_params: BufferRange<'_>,
        accumulate: bool,
    ) -> Result<()> {
        rec.dispatch(
            &self.keys_kernel,
            &specs::FieldGridKeysBindings {
                params,
                points,
                d_phi,
                keys: self.keys.whole(),
                values: self.values.whole(),
                records: self.records.whole(),
            }
            .for_kernel(&self.keys_kernel)?,
            &self.push(cube, n),
            n.div_ceil(64),
        )?;
        let cells = (self.res - 1).pow(3);
        let key_bits = (u32::BITS - (cells - 1).leading_zeros()).max(1);
        self.sort.record(
            rec,
            &self.sort_scratch,
            &self.keys,
            &self.values,
            u64::from(n),
            key_bits,
        )?;
        rec.dispatch(
            &self.chunks,
            &specs::FieldGridChunksBindings {
                keys: self.keys.whole(),
                values: self.values.whole(),
                records: self.records.whole(),
                partial: self.partial.whole(),
            }
            .for_kernel(&self.chunks)?,
            &CountPush { n },
            n.div_ceil(GRID_CHUNK).div_ceil(64),
        )?;
        if !accumulate {
            rec.fill(d_params, 0);
        }
        for corner in 0..8 {
            rec.dispatch(
                &self.corner,
                &specs::FieldGridCornerBindings {
                    keys: self.keys.whole(),
                    partial: self.partial.whole(),
                    d_params,
                }
                .for_kernel(&self.corner)?,
                &CornerPush {
                    n,
                    res: self.res,
                    corner,
                    pad: 0,
                },
                n.div_ceil(64),
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_structs_match_the_kernels_layout() {
        let size = |s| std::mem::size_of_val(&s) as u32;
        let grid = GridPush {
            cube: [0.0; 4],
            res: 0,
            n: 0,
            pad: [0; 2],
        };
        assert_eq!(size(grid), specs::FIELD_GRID_EVAL.push_constant_size);
        assert_eq!(size(grid), specs::FIELD_GRID_KEYS.push_constant_size);
        assert_eq!(4, specs::FIELD_GRID_CHUNKS.push_constant_size);
        let corner = CornerPush {
            n: 0,
            res: 0,
            corner: 0,
            pad: 0,
        };
        assert_eq!(
            std::mem::size_of_val(&corner) as u32,
            specs::FIELD_GRID_CORNER.push_constant_size
        );
        assert_eq!(specs::FIELD_GRID_KEYS.bindings.len(), 6);
        assert_eq!(specs::FIELD_GRID_CORNER.bindings.len(), 3);
        assert_eq!(GRID_BATCH % GRID_CHUNK, 0);
    }
}
