//! The buffers of one binning ([`Bins`]): counts and offsets, the entries and their items,
//! the sort's keys and scratch, the per-tile ranges and, for [`BinStrategy::Masks`], the tile
//! masks. They grow on demand and never shrink, so a loop re-bins without reallocating.

#[cfg(doc)]
use super::Binner;
use super::cpu;
use super::job::{BinJob, BinStrategy, COUNTS_PER_SUM, mask_layout};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, MemoryKind};
use crate::primitives::scan::ScanScratch;
use crate::primitives::sort::SortScratch;

/// The buffers of one binning, reusable across binnings (they grow on demand, never shrink).
pub struct Bins {
    pub(super) counts: Buffer,
    pub(super) scan_scratch: ScanScratch,
    pub(super) item_capacity: u64,
    pub(super) keys: Buffer,
    pub(super) pairs: Buffer,
    pub(super) pair_items: Buffer,
    pub(super) sort_scratch: SortScratch,
    pub(super) entry_capacity: u64,
    pub(super) ranges: Buffer,
    pub(super) tile_capacity: u64,
    // Masks (`BinStrategy::Masks`): each item's tile rectangle, the per-tile masks, and the
    // tiles' entry counts (scanned in place into their first entries).
    pub(super) rects: Buffer,
    pub(super) masks: Buffer,
    pub(super) mask_words: u64,
    pub(super) tile_counts: Buffer,
    pub(super) tile_scan_scratch: ScanScratch,
    // The 64-bit partial sums of a count whose u32 total could wrap, and how many the last
    // count pass recorded (0: its u32 total is exact).
    pub(super) sums: Buffer,
    pub(super) sums_recorded: std::sync::atomic::AtomicU64,
    pub(super) entries: Option<u64>,
}

impl Bins {
    /// Empty bins; [`Bins::reserve`] sizes them.
    pub fn new(ctx: &Context) -> Result<Self> {
        Self::with_capacity(ctx, 1, 1, 1)
    }

    fn with_capacity(ctx: &Context, items: u64, entries: u64, tiles: u64) -> Result<Self> {
        let (items, entries, tiles) = (items.max(1), entries.max(1), tiles.max(1));
        Ok(Self {
            counts: ctx.create_buffer("bin counts", 4 * (items + 1), MemoryKind::Device)?,
            scan_scratch: ScanScratch::new(ctx, items)?,
            item_capacity: items,
            keys: ctx.create_buffer("bin keys", 8 * entries, MemoryKind::Device)?,
            pairs: ctx.create_buffer("bin entries", 4 * entries, MemoryKind::Device)?,
            pair_items: ctx.create_buffer("bin entry items", 4 * entries, MemoryKind::Device)?,
            sort_scratch: SortScratch::new(ctx, entries)?,
            entry_capacity: entries,
            ranges: ctx.create_buffer("bin ranges", 8 * tiles, MemoryKind::Device)?,
            tile_capacity: tiles,
            rects: ctx.create_buffer("bin item rectangles", 8 * items, MemoryKind::Device)?,
            masks: ctx.create_buffer("bin tile masks", 4, MemoryKind::Device)?,
            mask_words: 1,
            tile_counts: ctx.create_buffer("bin tile counts", 4 * tiles, MemoryKind::Device)?,
            tile_scan_scratch: ScanScratch::new(ctx, tiles)?,
            sums: ctx.create_buffer("bin count sums", 8, MemoryKind::Device)?,
            sums_recorded: std::sync::atomic::AtomicU64::new(0),
            entries: None,
        })
    }

    /// Grows the item and tile buffers to hold `job` (entry buffers grow in
    /// [`Bins::reserve_entries`], once the count is known).
    pub fn reserve(&mut self, ctx: &Context, job: &BinJob) -> Result<()> {
        if job.item_count() > self.item_capacity {
            self.counts =
                ctx.create_buffer("bin counts", 4 * (job.item_count() + 1), MemoryKind::Device)?;
            self.scan_scratch = ScanScratch::new(ctx, job.item_count())?;
            self.rects = ctx.create_buffer(
                "bin item rectangles",
                8 * job.item_count(),
                MemoryKind::Device,
            )?;
            self.sums = ctx.create_buffer(
                "bin count sums",
                8 * job.item_count().div_ceil(COUNTS_PER_SUM),
                MemoryKind::Device,
            )?;
            self.item_capacity = job.item_count();
        }
        if job.tile_count() > self.tile_capacity {
            self.ranges =
                ctx.create_buffer("bin ranges", 8 * job.tile_count(), MemoryKind::Device)?;
            self.tile_counts =
                ctx.create_buffer("bin tile counts", 4 * job.tile_count(), MemoryKind::Device)?;
            self.tile_scan_scratch = ScanScratch::new(ctx, job.tile_count())?;
            self.tile_capacity = job.tile_count();
        }
        if let BinStrategy::Masks { words_per_tile } = job.strategy(ctx) {
            let (words, _) = mask_layout(words_per_tile, job.tile_count());
            if words > self.mask_words {
                self.masks = ctx.create_buffer("bin tile masks", 4 * words, MemoryKind::Device)?;
                self.mask_words = words;
            }
        }
        Ok(())
    }

    /// Grows the entry buffers to hold `entries` entries. Fails when one storage-buffer binding
    /// cannot hold them (`maxStorageBufferRange / 8` entries): the caller bins fewer views at
    /// once.
    pub fn reserve_entries(&mut self, ctx: &Context, entries: u64) -> Result<()> {
        let max = max_entries(ctx);
        if entries > max {
            return Err(Error::Limit(format!(
                "binning needs {entries} (face, tile) entries, over the {max} this device binds at \
                 once; use fewer views, a larger tile or a smaller σ"
            )));
        }
        if entries > self.entry_capacity {
            // Grow with headroom, so that a scene that breathes a little does not reallocate.
            self.allocate_entries(ctx, (entries + entries / 4).min(max))?;
        }
        Ok(())
    }

    /// Makes the entry buffers hold exactly `entries` entries, if they hold fewer (no headroom
    /// added: the caller of a guarded binning chose it). Fails as [`Bins::reserve_entries`].
    pub fn reserve_entry_capacity(&mut self, ctx: &Context, entries: u64) -> Result<()> {
        let max = max_entries(ctx);
        if entries > max {
            return Err(Error::Limit(format!(
                "binning needs {entries} (face, tile) entries, over the {max} this device binds at \
                 once; use fewer views, a larger tile or a smaller σ"
            )));
        }
        if entries > self.entry_capacity {
            self.allocate_entries(ctx, entries)?;
        }
        Ok(())
    }

    fn allocate_entries(&mut self, ctx: &Context, cap: u64) -> Result<()> {
        self.keys = ctx.create_buffer("bin keys", 8 * cap, MemoryKind::Device)?;
        self.pairs = ctx.create_buffer("bin entries", 4 * cap, MemoryKind::Device)?;
        self.pair_items = ctx.create_buffer("bin entry items", 4 * cap, MemoryKind::Device)?;
        self.sort_scratch = SortScratch::new(ctx, cap)?;
        self.entry_capacity = cap;
        Ok(())
    }

    /// The entries the entry buffers hold.
    pub fn entry_capacity(&self) -> u64 {
        self.entry_capacity
    }

    /// The one `u32` where the last count pass left its entry total (on the GPU).
    pub fn total_buffer(&self) -> &Buffer {
        self.scan_scratch.total()
    }

    /// Reads back a sorted binning of `job` holding `total` entries (the count's total), as its
    /// CPU twin lays it out ([`cpu::bin`]): what tests compare the GPU's binning with.
    pub fn read(&self, ctx: &Context, job: &BinJob, total: u64) -> Result<cpu::Binned> {
        let n = job.item_count() as usize;
        let t = total as usize;
        let slots: Vec<u32> = ctx.read_buffer(&self.pairs, 0, t)?;
        let items_of_slot: Vec<u32> = ctx.read_buffer(&self.pair_items, 0, t)?;
        let ranges: Vec<[u32; 2]> = ctx.read_buffer(&self.ranges, 0, job.tile_count() as usize)?;
        // Each entry's tile, from the ranges (the masks have no keys).
        let mut tiles = vec![0u32; t];
        for (tile, r) in ranges.iter().enumerate() {
            tiles[r[0] as usize..r[1] as usize].fill(tile as u32);
        }
        Ok(cpu::Binned {
            offsets: ctx.read_buffer(&self.counts, 0, n)?,
            total: total as u32,
            tiles,
            slots,
            slot_items: items_of_slot,
            ranges,
        })
    }

    /// Reads the entry count of the last recorded count pass (after its submission finished),
    /// exactly even past 2^32 (then from its 64-bit partial sums), and remembers it for
    /// [`Binner::record_sort`].
    pub fn read_total(&mut self, ctx: &Context) -> Result<u64> {
        let sums = *self.sums_recorded.get_mut();
        let total = if sums > 0 {
            ctx.read_buffer::<[u32; 2]>(&self.sums, 0, sums as usize)?
                .iter()
                .map(|s| u64::from(s[0]) | (u64::from(s[1]) << 32))
                .sum()
        } else {
            u64::from(ctx.read_buffer::<u32>(self.scan_scratch.total(), 0, 1)?[0])
        };
        self.entries = Some(total);
        Ok(total)
    }

    /// Sets the entry count without reading it back (a caller that knows it, e.g. re-running the
    /// same scene).
    pub fn set_total(&mut self, total: u64) {
        self.entries = Some(total);
    }

    /// The entry count of the current binning, once known.
    pub fn total(&self) -> Option<u64> {
        self.entries
    }

    /// The item-major exclusive offsets of the entries (after the count pass), followed by the
    /// total: `items + 1` values.
    pub fn offsets(&self) -> &Buffer {
        &self.counts
    }

    /// Sorted entries: the item-major slot of each (after [`Binner::record_sort`]).
    pub fn entries(&self) -> &Buffer {
        &self.pairs
    }

    /// The item (within its view) of each item-major slot.
    pub fn entry_items(&self) -> &Buffer {
        &self.pair_items
    }

    /// Sorted tile keys `[tile, 0]` of the entries.
    pub fn keys(&self) -> &Buffer {
        &self.keys
    }

    /// `[start, end)` per tile into the sorted entries.
    pub fn ranges(&self) -> &Buffer {
        &self.ranges
    }
}

/// The most entries one binning can hold on this device.
pub fn max_entries(ctx: &Context) -> u64 {
    u64::from(ctx.info().limits.max_storage_buffer_range) / 8
}
