//! The binning's recorded passes ([`Binner`]): the count and its scan, then either the masks'
//! per-tile counts and lists or the scatter, the radix sort by tile and the ranges; exact (the
//! count read back first) or guarded (over a reserved capacity, the count left on the GPU).

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

#[cfg(doc)]
use super::TileGrid;
use super::bins::Bins;
use super::cpu;
use super::job::{BinJob, BinStrategy, COUNTS_PER_SUM, mask_layout};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, Recorder, specs};
use crate::primitives::scan::Scan;
use crate::primitives::sort::RadixSort;

/// Push constants of `bin_count.comp` and `bin_scatter.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct BinPush {
    item_count: u32,
    items_per_view: u32,
    first_item: u32,
    stride_words: u32,
    box_offset: u32,
    flag_offset: u32,
    flag_mask: u32,
    width: u32,
    height: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    /// `bin_count.comp`: W of the masks to set (0: the sort's count, no masks).
    words_per_tile: u32,
    /// First tile row of the grid's window ([`TileGrid::window`]).
    first_row: u32,
    /// `bin_count.comp` with masks: the first word of the masks' summaries ([`mask_layout`]).
    summary_offset: u32,
    pad: u32,
}

/// Push constants of `bin_mask_counts.comp` (its first four words).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct MaskCountsPush {
    tiles: u32,
    words_per_tile: u32,
    pad: u32,
    /// The first word of the masks' summaries ([`mask_layout`]); 0: none (every word is read).
    summary_offset: u32,
}

/// Push constants of `bin_mask_list.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct MaskListPush {
    tiles: u32,
    words_per_tile: u32,
    items_per_view: u32,
    tiles_x: u32,
    tiles_per_view: u32,
    summary_offset: u32,
    pad: [u32; 2],
}

/// Push constants of `bin_count_sum.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct CountSumPush {
    n: u32,
    per_sum: u32,
    pad: [u32; 2],
}

/// Push constants of `bin_ranges.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct RangesPush {
    n: u32,
    tiles: u32,
    pad: [u32; 2],
}

/// The binning pipelines, made once per context.
pub struct Binner {
    count: Arc<Kernel>,
    scatter: Arc<Kernel>,
    ranges: Arc<Kernel>,
    mask_counts: Arc<Kernel>,
    mask_list: Arc<Kernel>,
    count_sum: Arc<Kernel>,
    scan: Scan,
    sort: RadixSort,
}

impl Binner {
    /// Builds the pipelines.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            count: ctx.kernel(&specs::BIN_COUNT, &[])?,
            scatter: ctx.kernel(&specs::BIN_SCATTER, &[])?,
            ranges: ctx.kernel(&specs::BIN_RANGES, &[])?,
            mask_counts: ctx.kernel(&specs::BIN_MASK_COUNTS, &[])?,
            mask_list: ctx.kernel(&specs::BIN_MASK_LIST, &[])?,
            count_sum: ctx.kernel(&specs::BIN_COUNT_SUM, &[])?,
            scan: Scan::new(ctx)?,
            sort: RadixSort::new(ctx)?,
        })
    }

    fn push(job: &BinJob, words_per_tile: u32) -> BinPush {
        BinPush {
            item_count: job.item_count() as u32,
            items_per_view: job.items_per_view,
            first_item: job.first_item,
            stride_words: job.layout.stride_words,
            box_offset: job.layout.box_offset,
            flag_offset: job.layout.flag_offset,
            flag_mask: job.layout.flag_mask,
            width: job.grid.width,
            height: job.grid.height,
            tile_size: job.grid.tile_size,
            tiles_x: job.grid.tiles_x,
            tiles_y: job.grid.tiles_y,
            words_per_tile,
            first_row: job.grid.first_row,
            summary_offset: if words_per_tile == 0 {
                0
            } else {
                mask_layout(words_per_tile, job.tile_count()).1 as u32
            },
            pad: 0,
        }
    }

    fn check(
        job: &BinJob,
        strategy: BinStrategy,
        items: &BufferRange<'_>,
        bins: &Bins,
    ) -> Result<()> {
        if job.item_count() > u64::from(u32::MAX) || job.tile_count() >= u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "binning {} items over {} tiles: past the kernels' 32-bit indices; bin fewer \
                 views at once",
                job.item_count(),
                job.tile_count()
            )));
        }
        let words = u64::from(job.first_item + job.items_per_view * job.views)
            * u64::from(job.layout.stride_words);
        if job.layout.box_offset + 4 > job.layout.stride_words
            || job.layout.flag_offset >= job.layout.stride_words
        {
            return Err(Error::Misuse(format!(
                "binning: items of {} words cannot have the box at {} and flags at {}",
                job.layout.stride_words, job.layout.box_offset, job.layout.flag_offset
            )));
        }
        items.require(
            4 * words,
            &format!(
                "binning {} items of {} words",
                job.first_item + job.items_per_view * job.views,
                job.layout.stride_words
            ),
        )?;
        let mask_words = match strategy {
            BinStrategy::Masks { words_per_tile } => {
                mask_layout(words_per_tile, job.tile_count()).0
            }
            BinStrategy::Sort => 0,
        };
        if job.item_count() > bins.item_capacity
            || job.tile_count() > bins.tile_capacity
            || mask_words > bins.mask_words
        {
            return Err(Error::Misuse(format!(
                "binning {} items over {} tiles: bins hold {} items and {} tiles (call reserve)",
                job.item_count(),
                job.tile_count(),
                bins.item_capacity,
                bins.tile_capacity
            )));
        }
        Ok(())
    }

    /// Records the count pass and its scan: after it runs, [`Bins::offsets`] holds each item's
    /// first slot and [`Bins::read_total`] the entry count.
    pub fn record_count(
        &self,
        rec: &mut Recorder<'_>,
        bins: &Bins,
        items: BufferRange<'_>,
        job: &BinJob,
    ) -> Result<()> {
        let strategy = job.strategy(rec.context());
        Self::check(job, strategy, &items, bins)?;
        let n = job.item_count();
        if n == 0 {
            bins.sums_recorded
                .store(0, std::sync::atomic::Ordering::Relaxed);
            rec.fill(bins.scan_scratch.total().whole(), 0);
            rec.fill(bins.counts.range(0, 4), 0);
            return Ok(());
        }
        let counts = bins.counts.range(0, 4 * n);
        let (words_per_tile, masks) = match strategy {
            BinStrategy::Masks { words_per_tile } => {
                let (words, _) = mask_layout(words_per_tile, job.tile_count());
                let masks = bins.masks.range(0, 4 * words);
                rec.fill(masks, 0);
                (words_per_tile, masks)
            }
            // Bound but never written.
            BinStrategy::Sort => (0, bins.masks.range(0, 4)),
        };
        let groups = n.div_ceil(u64::from(specs::BIN_COUNT.workgroup_size[0]));
        let bindings = specs::BinCountBindings {
            items,
            counts,
            rects: bins.rects.range(0, 8 * n),
            tile_masks: masks,
        };
        rec.dispatch(
            &self.count,
            &bindings.for_kernel(&self.count)?,
            &Self::push(job, words_per_tile),
            groups as u32,
        )?;
        // Before the scan overwrites the counts with their offsets.
        let sums = if job.max_entries() > u64::from(u32::MAX) {
            let sums = n.div_ceil(COUNTS_PER_SUM);
            let push = CountSumPush {
                n: n as u32,
                per_sum: COUNTS_PER_SUM as u32,
                pad: [0; 2],
            };
            rec.dispatch(
                &self.count_sum,
                &specs::BinCountSumBindings {
                    counts,
                    sums: bins.sums.range(0, 8 * sums),
                }
                .for_kernel(&self.count_sum)?,
                &push,
                sums.div_ceil(u64::from(specs::BIN_COUNT_SUM.workgroup_size[0])) as u32,
            )?;
            sums
        } else {
            0
        };
        bins.sums_recorded
            .store(sums, std::sync::atomic::Ordering::Relaxed);
        self.scan
            .record(rec, &bins.scan_scratch, counts, counts, n)?;
        // offsets[n] = the total, for consumers that do not know it on the host.
        rec.copy(bins.scan_scratch.total(), 0, &bins.counts, 4 * n, 4);
        Ok(())
    }

    /// Records scatter, sort and ranges for the entry count that [`Bins::read_total`] (or
    /// [`Bins::set_total`]) established; the entry buffers must hold it
    /// ([`Bins::reserve_entries`]).
    pub fn record_sort(
        &self,
        rec: &mut Recorder<'_>,
        bins: &Bins,
        items: BufferRange<'_>,
        job: &BinJob,
    ) -> Result<()> {
        let strategy = job.strategy(rec.context());
        Self::check(job, strategy, &items, bins)?;
        let total = bins.entries.ok_or_else(|| {
            Error::Misuse("binning: the entry count is not known yet (read_total)".into())
        })?;
        if total > bins.entry_capacity {
            return Err(Error::Misuse(format!(
                "binning: {total} entries, entry buffers hold {} (call reserve_entries)",
                bins.entry_capacity
            )));
        }
        if let BinStrategy::Masks { words_per_tile } = strategy {
            return self.record_mask_list(rec, bins, job, words_per_tile, total);
        }
        let tiles = job.tile_count();
        rec.fill(bins.ranges.range(0, 8 * tiles), 0);
        if total == 0 {
            return Ok(());
        }
        let n = job.item_count();
        let groups = n.div_ceil(u64::from(specs::BIN_SCATTER.workgroup_size[0]));
        let bindings = specs::BinScatterBindings {
            items,
            offsets: bins.counts.range(0, 4 * n),
            keys: bins.keys.range(0, 8 * total),
            pairs: bins.pairs.range(0, 4 * total),
            pair_items: bins.pair_items.range(0, 4 * total),
        };
        rec.dispatch(
            &self.scatter,
            &bindings.for_kernel(&self.scatter)?,
            &Self::push(job, 0),
            groups as u32,
        )?;
        self.sort.record(
            rec,
            &bins.sort_scratch,
            &bins.keys,
            &bins.pairs,
            total,
            job.key_bits(),
        )?;
        self.record_ranges(
            rec,
            bins.keys.range(0, 8 * total),
            bins.ranges.range(0, 8 * tiles),
            total,
            tiles,
        )
    }

    /// Masks: counts each tile's entries, scans the counts into each tile's first entry, and
    /// lists every tile's entries (at most `cap` of them are written) and ranges.
    fn record_mask_list(
        &self,
        rec: &mut Recorder<'_>,
        bins: &Bins,
        job: &BinJob,
        words_per_tile: u32,
        cap: u64,
    ) -> Result<()> {
        let tiles = job.tile_count();
        let n = job.item_count();
        let (words, summary_offset) = mask_layout(words_per_tile, tiles);
        let masks = bins.masks.range(0, 4 * words);
        let tile_counts = bins.tile_counts.range(0, 4 * tiles);
        let groups =
            |spec: &crate::gpu::KernelSpec| tiles.div_ceil(u64::from(spec.workgroup_size[0]));
        let push = MaskCountsPush {
            tiles: tiles as u32,
            words_per_tile,
            pad: 0,
            summary_offset: summary_offset as u32,
        };
        rec.dispatch(
            &self.mask_counts,
            &specs::BinMaskCountsBindings {
                masks,
                counts: tile_counts,
            }
            .for_kernel(&self.mask_counts)?,
            &push,
            groups(&specs::BIN_MASK_COUNTS) as u32,
        )?;
        self.scan.record(
            rec,
            &bins.tile_scan_scratch,
            tile_counts,
            tile_counts,
            tiles,
        )?;
        let push = MaskListPush {
            tiles: tiles as u32,
            words_per_tile,
            items_per_view: job.items_per_view,
            tiles_x: job.grid.tiles_x,
            tiles_per_view: job.grid.tiles_per_view() as u32,
            summary_offset: summary_offset as u32,
            pad: [0; 2],
        };
        let cap = cap.max(1);
        let bindings = specs::BinMaskListBindings {
            masks,
            tile_offsets: tile_counts,
            item_offsets: bins.counts.range(0, 4 * n.max(1)),
            rects: bins.rects.range(0, 8 * n.max(1)),
            entries: bins.pairs.range(0, 4 * cap),
            entry_items: bins.pair_items.range(0, 4 * cap),
            ranges: bins.ranges.range(0, 8 * tiles),
        };
        rec.dispatch(
            &self.mask_list,
            &bindings.for_kernel(&self.mask_list)?,
            &push,
            groups(&specs::BIN_MASK_LIST) as u32,
        )
    }

    /// Records the ranges pass alone: `[start, end)` of every tile's run in the first `n` keys
    /// of `keys` (`[tile, 0]` each, sorted by tile) into `ranges` (`tiles` pairs, which must
    /// already be zero: empty tiles are not written). For other lists sorted by tile, such as
    /// sphere probing's rays.
    pub fn record_ranges(
        &self,
        rec: &mut Recorder<'_>,
        keys: BufferRange<'_>,
        ranges: BufferRange<'_>,
        n: u64,
        tiles: u64,
    ) -> Result<()> {
        if keys.size < 8 * n || ranges.size < 8 * tiles || n > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "tile ranges: `{}` ({} bytes) and `{}` ({} bytes) do not hold {n} keys and \
                 {tiles} ranges",
                keys.buffer.name(),
                keys.size,
                ranges.buffer.name(),
                ranges.size
            )));
        }
        if n == 0 {
            return Ok(());
        }
        let push = RangesPush {
            n: n as u32,
            tiles: tiles as u32,
            pad: [0; 2],
        };
        let groups = n.div_ceil(u64::from(specs::BIN_RANGES.workgroup_size[0]));
        let bindings = specs::BinRangesBindings { keys, ranges };
        rec.dispatch(
            &self.ranges,
            &bindings.for_kernel(&self.ranges)?,
            &push,
            groups as u32,
        )
    }

    /// Records scatter, sort and ranges over the whole entry capacity, for a count the host does
    /// not know (see the module docs): sentinel keys fill the capacity, the scatter overwrites
    /// the first `total` slots, and the sort and ranges pass run over all of it. The result is
    /// the exact binning's when the count's total fits [`Bins::entry_capacity`]; the caller
    /// must gate these dispatches on that ([`Recorder::gated`]).
    pub fn record_sort_guarded(
        &self,
        rec: &mut Recorder<'_>,
        bins: &Bins,
        items: BufferRange<'_>,
        job: &BinJob,
    ) -> Result<()> {
        let strategy = job.strategy(rec.context());
        Self::check(job, strategy, &items, bins)?;
        // The gate and the counted sort read the count's u32 total on the GPU: it must not wrap.
        if job.max_entries() > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "guarded binning of {} items over {} tiles per view in {} view(s) could count \
                 past 2^32 entries; bin fewer views at once or use larger tiles",
                job.items_per_view,
                job.grid.tiles_per_view(),
                job.views
            )));
        }
        let cap = bins.entry_capacity;
        if let BinStrategy::Masks { words_per_tile } = strategy {
            return self.record_mask_list(rec, bins, job, words_per_tile, cap);
        }
        let tiles = job.tile_count();
        if tiles >= u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "binning: {tiles} tiles leave no room for the sentinel key"
            )));
        }
        rec.fill(bins.keys.range(0, 8 * cap), u32::MAX);
        rec.fill(bins.ranges.range(0, 8 * tiles), 0);
        let n = job.item_count();
        if n > 0 {
            let groups = n.div_ceil(u64::from(specs::BIN_SCATTER.workgroup_size[0]));
            rec.dispatch(
                &self.scatter,
                &specs::BinScatterBindings {
                    items,
                    offsets: bins.counts.range(0, 4 * n),
                    keys: bins.keys.range(0, 8 * cap),
                    pairs: bins.pairs.range(0, 4 * cap),
                    pair_items: bins.pair_items.range(0, 4 * cap),
                }
                .for_kernel(&self.scatter)?,
                &Self::push(job, 0),
                groups as u32,
            )?;
        }
        // Only the counted entries need sorting: the sentinels after them are already last.
        self.sort.record_counted(
            rec,
            &bins.sort_scratch,
            &bins.keys,
            &bins.pairs,
            cap,
            bins.total_buffer().range(0, 4),
            job.padded_key_bits(),
        )?;
        let push = RangesPush {
            n: cap as u32,
            tiles: tiles as u32,
            pad: [0; 2],
        };
        let groups = cap.div_ceil(u64::from(specs::BIN_RANGES.workgroup_size[0]));
        rec.dispatch(
            &self.ranges,
            &specs::BinRangesBindings {
                keys: bins.keys.range(0, 8 * cap),
                ranges: bins.ranges.range(0, 8 * tiles),
            }
            .for_kernel(&self.ranges)?,
            &push,
            groups as u32,
        )
    }

    /// Convenience (tests, tools): bins `items` completely, two submissions, and reads the
    /// result back as the twin's [`cpu::Binned`].
    pub fn run(
        &self,
        ctx: &Context,
        bins: &mut Bins,
        items: &Buffer,
        job: &BinJob,
    ) -> Result<cpu::Binned> {
        bins.reserve(ctx, job)?;
        ctx.submit_and_wait(|rec| self.record_count(rec, bins, items.whole(), job))?;
        let total = bins.read_total(ctx)?;
        bins.reserve_entries(ctx, total)?;
        ctx.submit_and_wait(|rec| self.record_sort(rec, bins, items.whole(), job))?;
        bins.read(ctx, job, total)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        assert_eq!(
            std::mem::size_of::<BinPush>() as u32,
            specs::BIN_COUNT.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<BinPush>() as u32,
            specs::BIN_SCATTER.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<RangesPush>() as u32,
            specs::BIN_RANGES.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<MaskCountsPush>() as u32,
            specs::BIN_MASK_COUNTS.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<MaskListPush>() as u32,
            specs::BIN_MASK_LIST.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<CountSumPush>() as u32,
            specs::BIN_COUNT_SUM.push_constant_size
        );
    }
}
