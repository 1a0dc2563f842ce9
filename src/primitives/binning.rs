//! Tiled binning (SPEC §4): which items (faces after setup, anchor spheres, ...) each screen tile
//! must visit, with every capacity computed exactly.
//!
//! 1. **Count** (`kernels/binning/bin_count.comp`): per item, the number of tiles its screen box
//!    touches. An exclusive [`Scan`] of the counts gives every item its slot in the entry list,
//!    and the scan's total sizes that list exactly: the host reads it back between the two
//!    submissions of a binning ([`Bins::read_total`]), grows the entry buffers if needed, and
//!    records the rest. Nothing is ever written past a capacity, and nothing is dropped.
//!
//! Then the entries are put in tile order, each tile's items in index order (the order brute
//! force visits), in one of two ways ([`BinStrategy`], chosen per job by [`BinJob::strategy`]):
//!
//! - **Masks** (grids of at most [`MASK_MAX_TILES_PER_VIEW`] tiles per view: every image size
//!   the fits and benchmarks use). The count pass also sets each item's bit in a per-tile mask
//!   of its view's items (integer `atomicOr`, so order-independent) and, in the tile's summary
//!   of the mask, the bit of each mask word it made non-zero; one invocation per tile counts
//!   its bits (`bin_mask_counts.comp`), an exclusive [`Scan`] over the tiles gives each tile
//!   its first entry, and one invocation per tile lists its items, lowest bit first, with each
//!   entry's item-major slot and its range (`bin_mask_list.comp`). Both visit only the mask
//!   words the summary marks. No sort: the masks cost a memset and a few word visits per
//!   entry, the sort several passes over every entry (on llvmpipe the sort was a quarter of a
//!   mesh-fitting iteration; walking every mask word, as the masks did before summaries, took
//!   half of spot-256's binning).
//! - **Sort** (larger grids, where the masks would be mostly empty words): a **scatter**
//!   (`bin_scatter.comp`) writes one entry per (item, tile), item-major (view-major, then item
//!   index), keyed by tile; the stable [`RadixSort`] by tile, over exactly as many key bits as
//!   there are tiles, keeps each tile's entries in item order; the **ranges** pass
//!   (`bin_ranges.comp`) writes `[start, end)` of every tile's run.
//!
//! Both give the same entries, bit for bit.
//!
//! Each sorted entry carries its item-major slot, and the item of every slot is kept, so a tiled
//! backward can write one partial result per (item, tile) at its item-major slot and then reduce
//! each item's contiguous run in a fixed order: deterministic, without float atomics.
//!
//! [`cpu::bin`] is the twin: the same tile rectangles in the same f32 arithmetic, and the same
//! lists.
//!
//! The u32 scan is exact only while the total stays below 2^32. Where the largest possible total
//! (items × tiles) could pass it, [`Binner::record_count`] also sums the counts in 64 bits
//! (`bin_count_sum.comp`, a few thousand partial sums the host adds in [`Bins::read_total`]), so
//! the total read back is exact whatever the worst case: a binning is refused only when its
//! real entries do not fit (and then callers bin fewer views at once), never on a bound. The
//! guarded binning, whose count the host never reads, keeps the worst-case check.
//!
//! **Guarded binning** (a loop that must not wait for the count: mesh fitting). The entry
//! buffers are reserved with headroom over a count seen before ([`Bins::reserve_entry_capacity`])
//! and [`Binner::record_sort_guarded`] records the rest without knowing the count. With masks
//! nothing changes but that no entry is written past the capacity. With the sort, every slot of
//! the capacity is first filled with a *sentinel* key (all ones, which [`BinJob::padded_key_bits`]
//! sorts past every tile), the scatter overwrites the first `total` slots, and the sort and the
//! ranges run over the whole capacity; the sentinels end up after every tile's run and the
//! ranges pass skips them, so the result is the exact binning's, whatever the headroom. The
//! sorting kernels stay generic (no count read from a buffer); the price is sorting the headroom
//! too. Whether `total` fit is for the caller to check on the GPU (the count's total is in
//! [`Bins::total_buffer`]) before the sort runs: the scatter itself never writes past the
//! buffers it is given (an item whose entries would not fit writes none), but a count over the
//! capacity leaves the binning incomplete.
//!
//! The offsets buffer holds one entry more than the items: `offsets[items]` is the total, so a
//! consumer can find the end of the last item's entries without knowing the count on the host.
//!
//! **Windows.** A job's grid may be a window of the image's tile rows ([`TileGrid::window`]):
//! then only those rows are binned, their tiles numbered from the window's first row, so a
//! view whose entries do not fit one binding is binned (and rendered) a window at a time.

use bytemuck::{Pod, Zeroable};

use super::scan::{Scan, ScanScratch};
use super::sort::{RadixSort, SortScratch};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder, specs};

/// The tile grid over a `width × height` image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileGrid {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Tile edge in pixels.
    pub tile_size: u32,
    /// Tiles per row.
    pub tiles_x: u32,
    /// Tile rows of the grid: all of the image's, or a window's ([`TileGrid::window`]).
    pub tiles_y: u32,
    /// First tile row: 0 for the whole image; a window covers tile rows
    /// `first_row .. first_row + tiles_y`, and its tiles are numbered from its first row.
    pub first_row: u32,
}

impl TileGrid {
    /// The grid of `tile_size`-pixel tiles covering the image.
    pub fn new(width: u32, height: u32, tile_size: u32) -> Result<Self> {
        if width == 0 || height == 0 || tile_size == 0 {
            return Err(Error::Input(format!(
                "tile grid of a {width}x{height} image with {tile_size}-pixel tiles"
            )));
        }
        Ok(Self {
            width,
            height,
            tile_size,
            tiles_x: width.div_ceil(tile_size),
            tiles_y: height.div_ceil(tile_size),
            first_row: 0,
        })
    }

    /// The window of `rows` tile rows from `first_row` (of the whole image's grid): binning and
    /// the tiled passes over it cover only those rows' pixels. Views whose (item, tile) entries
    /// do not fit one binding are binned and rendered window by window.
    pub fn window(&self, first_row: u32, rows: u32) -> Result<Self> {
        let all = self.height.div_ceil(self.tile_size);
        if rows == 0 || first_row.checked_add(rows).is_none_or(|end| end > all) {
            return Err(Error::Misuse(format!(
                "tile rows {first_row}..{} of a grid of {all}",
                u64::from(first_row) + u64::from(rows)
            )));
        }
        Ok(Self {
            tiles_y: rows,
            first_row,
            ..*self
        })
    }

    /// Tile rows of the whole image (a window's `tiles_y` counts its own).
    pub fn image_rows(&self) -> u32 {
        self.height.div_ceil(self.tile_size)
    }

    /// Tiles per view.
    pub fn tiles_per_view(&self) -> u64 {
        u64::from(self.tiles_x) * u64::from(self.tiles_y)
    }
}

/// Where an item's box and flags sit in the items buffer (all in 32-bit words).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ItemLayout {
    /// Words from one item to the next.
    pub stride_words: u32,
    /// Offset of the box `(x_min, y_min, x_max, y_max)` (f32, pixel-centre coordinates).
    pub box_offset: u32,
    /// Offset of the flag word.
    pub flag_offset: u32,
    /// Bits of the flag word that must all be set for the item to be binned (0: all items).
    pub flag_mask: u32,
}

/// What one binning dispatch covers: `views` views of `items_per_view` items each, starting at
/// item `first_item` of the items buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BinJob {
    /// The tile grid (the same for every view).
    pub grid: TileGrid,
    /// The item layout.
    pub layout: ItemLayout,
    /// Items per view.
    pub items_per_view: u32,
    /// Views binned together.
    pub views: u32,
    /// Index of the first item in the items buffer (view-major).
    pub first_item: u32,
}

impl BinJob {
    /// Items binned.
    pub fn item_count(&self) -> u64 {
        u64::from(self.items_per_view) * u64::from(self.views)
    }

    /// Tiles over all views.
    pub fn tile_count(&self) -> u64 {
        self.grid.tiles_per_view() * u64::from(self.views)
    }

    /// The most entries this job could produce (every item on every tile of its view).
    pub fn max_entries(&self) -> u64 {
        u64::from(self.items_per_view) * self.grid.tiles_per_view() * u64::from(self.views)
    }

    /// Key bits of a tile index.
    pub fn key_bits(&self) -> u32 {
        let tiles = self.tile_count();
        (u64::BITS - (tiles.max(2) - 1).leading_zeros()).max(1)
    }

    /// Key bits of a guarded sort ([`Binner::record_sort_guarded`]): enough that the sentinel
    /// (all ones in these bits) is above every tile index.
    pub fn padded_key_bits(&self) -> u32 {
        (u64::BITS - self.tile_count().leading_zeros()).max(1)
    }
}

/// The most tiles per view binned through masks ([`BinStrategy::Masks`]): up to this many, a
/// tile's mask (one bit per item of its view) costs at most 64 words per item, about what the
/// sort spends on a few entries; beyond it, mostly empty mask words would outweigh the sort.
pub const MASK_MAX_TILES_PER_VIEW: u64 = 2048;

/// The words the masks of `tiles` tiles take, `words_per_tile` each, followed by their summaries
/// (⌈W / 32⌉ words a tile, one bit per mask word that is not zero: `bin_count.comp`), and the
/// index of the first summary word.
fn mask_layout(words_per_tile: u32, tiles: u64) -> (u64, u64) {
    let w = u64::from(words_per_tile);
    ((w + w.div_ceil(32)) * tiles, w * tiles)
}

/// How a binning puts its entries in tile order (see the module docs). Either way the entries
/// are the same, bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinStrategy {
    /// Per-tile item masks of `words_per_tile` = ⌈items per view / 32⌉ words, listed tile by
    /// tile: no sort.
    Masks {
        /// Words of one tile's mask.
        words_per_tile: u32,
    },
    /// Scatter, stable radix sort by tile, ranges.
    Sort,
}

impl BinJob {
    /// The strategy this job bins with on `ctx`'s device: masks when the grid has at most
    /// [`MASK_MAX_TILES_PER_VIEW`] tiles per view and the masks fit one storage-buffer binding,
    /// within the kernels' limits (tile coordinates below 2^16, at most 65 535 mask words per
    /// tile) and the driver's loop cap (llvmpipe ends an invocation's loops after 65 535
    /// iterations in all, silently: a tile's list walks its W words and, at worst, every item
    /// of its view); else the sort.
    pub fn strategy(&self, ctx: &Context) -> BinStrategy {
        let words = u64::from(self.items_per_view.div_ceil(32)).max(1);
        let bytes = 4 * (words + words.div_ceil(32)) * self.tile_count();
        // A tile's list walks its summary words, the mask words they mark and, at worst, every
        // item of its view.
        let list_iterations = words.div_ceil(32) + words + u64::from(self.items_per_view);
        let fits = self.grid.tiles_per_view() <= MASK_MAX_TILES_PER_VIEW
            && self.grid.tiles_x <= 0xFFFF
            && self.grid.tiles_y <= 0xFFFF
            && words <= 0xFFFF
            && ctx
                .info()
                .shader_loop_limit()
                .is_none_or(|limit| list_iterations <= limit)
            && bytes <= u64::from(ctx.info().limits.max_storage_buffer_range);
        if fits {
            BinStrategy::Masks {
                words_per_tile: words as u32,
            }
        } else {
            BinStrategy::Sort
        }
    }
}

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

/// Counts each invocation of `bin_count_sum.comp` adds (its loop's length).
const COUNTS_PER_SUM: u64 = 256;

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
    count: Kernel,
    scatter: Kernel,
    ranges: Kernel,
    mask_counts: Kernel,
    mask_list: Kernel,
    count_sum: Kernel,
    scan: Scan,
    sort: RadixSort,
}

/// The buffers of one binning, reusable across binnings (they grow on demand, never shrink).
pub struct Bins {
    counts: Buffer,
    scan_scratch: ScanScratch,
    item_capacity: u64,
    keys: Buffer,
    pairs: Buffer,
    pair_items: Buffer,
    sort_scratch: SortScratch,
    entry_capacity: u64,
    ranges: Buffer,
    tile_capacity: u64,
    // Masks (`BinStrategy::Masks`): each item's tile rectangle, the per-tile masks, and the
    // tiles' entry counts (scanned in place into their first entries).
    rects: Buffer,
    masks: Buffer,
    mask_words: u64,
    tile_counts: Buffer,
    tile_scan_scratch: ScanScratch,
    // The 64-bit partial sums of a count whose u32 total could wrap, and how many the last
    // count pass recorded (0: its u32 total is exact).
    sums: Buffer,
    sums_recorded: std::sync::atomic::AtomicU64,
    entries: Option<u64>,
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

impl Binner {
    /// Builds the pipelines.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            count: Kernel::new(ctx, &specs::BIN_COUNT)?,
            scatter: Kernel::new(ctx, &specs::BIN_SCATTER)?,
            ranges: Kernel::new(ctx, &specs::BIN_RANGES)?,
            mask_counts: Kernel::new(ctx, &specs::BIN_MASK_COUNTS)?,
            mask_list: Kernel::new(ctx, &specs::BIN_MASK_LIST)?,
            count_sum: Kernel::new(ctx, &specs::BIN_COUNT_SUM)?,
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
        let n = job.item_count() as usize;
        let t = total as usize;
        let slots: Vec<u32> = ctx.read_buffer(&bins.pairs, 0, t)?;
        let items_of_slot: Vec<u32> = ctx.read_buffer(&bins.pair_items, 0, t)?;
        let ranges: Vec<[u32; 2]> = ctx.read_buffer(&bins.ranges, 0, job.tile_count() as usize)?;
        // Each entry's tile, from the ranges (the masks have no keys).
        let mut tiles = vec![0u32; t];
        for (tile, r) in ranges.iter().enumerate() {
            tiles[r[0] as usize..r[1] as usize].fill(tile as u32);
        }
        Ok(cpu::Binned {
            offsets: ctx.read_buffer(&bins.counts, 0, n)?,
            total: total as u32,
            tiles,
            slots,
            slot_items: items_of_slot,
            ranges,
        })
    }
}

/// The CPU twin of binning.
pub mod cpu {
    use super::TileGrid;

    /// A binning's result, as the GPU leaves it.
    #[derive(Clone, Debug, PartialEq, Eq)]
    pub struct Binned {
        /// Exclusive offsets of every item's entries (item-major).
        pub offsets: Vec<u32>,
        /// Number of entries.
        pub total: u32,
        /// Tile of every entry, sorted (stable) by tile.
        pub tiles: Vec<u32>,
        /// Item-major slot of every sorted entry.
        pub slots: Vec<u32>,
        /// Item (within its view) of every item-major slot.
        pub slot_items: Vec<u32>,
        /// `[start, end)` per tile (`[0, 0]` when empty).
        pub ranges: Vec<[u32; 2]>,
    }

    impl Binned {
        /// The items tile `tile` visits, in order.
        pub fn tile_items(&self, tile: usize) -> Vec<u32> {
            let [s, e] = self.ranges[tile];
            (s..e)
                .map(|i| self.slot_items[self.slots[i as usize] as usize])
                .collect()
        }
    }

    /// `tile_rect` of `binning.glsl`, in the same f32 operations: the tiles `(x0, y0, x1, y1)`
    /// (inclusive) a box may touch, or `None` when it touches no pixel of the image.
    pub fn tile_rect(b: [f32; 4], grid: &TileGrid) -> Option<[u32; 4]> {
        if b.iter().any(|c| c.is_nan()) {
            return None;
        }
        let w = grid.width as f32;
        let h = grid.height as f32;
        let s = w.min(h);
        // Separate multiply and add, as the kernel's `precise` forces.
        let c0 = ((b[0] * s + (w - 1.0)) * 0.5).floor() - 1.0;
        let c1 = ((b[2] * s + (w - 1.0)) * 0.5).ceil() + 1.0;
        let r0 = (((h - 1.0) - b[3] * s) * 0.5).floor() - 1.0;
        let r1 = (((h - 1.0) - b[1] * s) * 0.5).ceil() + 1.0;
        let (c0, r0) = (c0.max(0.0), r0.max(0.0));
        let (c1, r1) = (c1.min(w - 1.0), r1.min(h - 1.0));
        if !(c0 <= c1 && r0 <= r1) {
            return None;
        }
        let ts = grid.tile_size;
        Some([
            c0 as u32 / ts,
            r0 as u32 / ts,
            c1 as u32 / ts,
            r1 as u32 / ts,
        ])
    }

    /// `window_rect` of `binning.glsl`: the part of a tile rectangle inside `grid`'s window of
    /// tile rows ([`TileGrid::window`]), its rows numbered from the window's first.
    pub fn window_rect(r: [u32; 4], grid: &TileGrid) -> Option<[u32; 4]> {
        let last = grid.first_row + grid.tiles_y - 1;
        if r[3] < grid.first_row || r[1] > last {
            return None;
        }
        Some([
            r[0],
            r[1].max(grid.first_row) - grid.first_row,
            r[2],
            r[3].min(last) - grid.first_row,
        ])
    }

    /// Bins `boxes` (`views × items_per_view`, view-major; `None` = not binned) exactly as the
    /// GPU does: count, exclusive scan, item-major scatter, stable sort by tile, ranges. Over a
    /// window, only its tile rows.
    pub fn bin(boxes: &[Option<[f32; 4]>], items_per_view: u32, grid: &TileGrid) -> Binned {
        let per_view = grid.tiles_per_view() as u32;
        let mut offsets = Vec::with_capacity(boxes.len());
        let mut entries: Vec<(u32, u32, u32)> = Vec::new(); // (tile, slot, item)
        for (id, b) in boxes.iter().enumerate() {
            offsets.push(entries.len() as u32);
            let Some(rect) = b
                .and_then(|b| tile_rect(b, grid))
                .and_then(|r| window_rect(r, grid))
            else {
                continue;
            };
            let view = id as u32 / items_per_view.max(1);
            let item = id as u32 - view * items_per_view;
            for ty in rect[1]..=rect[3] {
                for tx in rect[0]..=rect[2] {
                    let slot = entries.len() as u32;
                    entries.push((view * per_view + ty * grid.tiles_x + tx, slot, item));
                }
            }
        }
        let slot_items: Vec<u32> = entries.iter().map(|e| e.2).collect();
        let total = entries.len() as u32;
        entries.sort_by_key(|e| e.0); // stable
        let views = boxes.len() as u32 / items_per_view.max(1);
        let mut ranges = vec![[0u32; 2]; (per_view * views) as usize];
        for (i, e) in entries.iter().enumerate() {
            let r = &mut ranges[e.0 as usize];
            if i == 0 || entries[i - 1].0 != e.0 {
                r[0] = i as u32;
            }
            r[1] = i as u32 + 1;
        }
        Binned {
            offsets,
            total,
            tiles: entries.iter().map(|e| e.0).collect(),
            slots: entries.iter().map(|e| e.1).collect(),
            slot_items,
            ranges,
        }
    }

    /// The tile `(tx, ty)` holding pixel `(col, row)`.
    pub fn pixel_tile(col: u32, row: u32, grid: &TileGrid) -> (u32, u32) {
        (col / grid.tile_size, row / grid.tile_size)
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

    #[test]
    fn key_bits_cover_every_tile() {
        let grid = TileGrid::new(100, 30, 16).unwrap();
        assert_eq!((grid.tiles_x, grid.tiles_y), (7, 2));
        for views in 1..40 {
            let job = BinJob {
                grid,
                layout: ItemLayout {
                    stride_words: 4,
                    box_offset: 0,
                    flag_offset: 0,
                    flag_mask: 0,
                },
                items_per_view: 3,
                views,
                first_item: 0,
            };
            let tiles = job.tile_count();
            assert!(tiles - 1 < 1 << job.key_bits(), "{views}");
            assert!(job.key_bits() == 1 || tiles > 1 << (job.key_bits() - 1));
        }
    }

    #[test]
    fn tile_rect_contains_every_pixel_the_box_contains() {
        let grid = TileGrid::new(37, 23, 8).unwrap();
        let s = 23.0_f32;
        let boxes = [
            [-0.3, -0.2, 0.1, 0.4],
            [-5.0, -5.0, 5.0, 5.0],
            [0.99, 0.99, 3.0, 3.0],
            [-0.01, 0.3, -0.01, 0.3],
            [
                f32::NEG_INFINITY,
                f32::NEG_INFINITY,
                f32::INFINITY,
                f32::INFINITY,
            ],
        ];
        for b in boxes {
            let rect = cpu::tile_rect(b, &grid);
            for row in 0..grid.height {
                for col in 0..grid.width {
                    let x = (2.0 * col as f32 + 1.0 - 37.0) / s;
                    let y = (2.0 * (23.0 - 1.0 - row as f32) + 1.0 - 23.0) / s;
                    if x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3] {
                        let r = rect.unwrap_or_else(|| panic!("{b:?} lost ({col}, {row})"));
                        let (tx, ty) = cpu::pixel_tile(col, row, &grid);
                        assert!(tx >= r[0] && tx <= r[2] && ty >= r[1] && ty <= r[3]);
                    }
                }
            }
        }
        assert_eq!(cpu::tile_rect([5.0, 5.0, 6.0, 6.0], &grid), None);
        assert_eq!(cpu::tile_rect([f32::NAN, 0.0, 1.0, 1.0], &grid), None);
        assert_eq!(cpu::tile_rect([1.0, 1.0, -1.0, -1.0], &grid), None);
    }

    #[test]
    fn cpu_bin_keeps_item_order_within_tiles() {
        let grid = TileGrid::new(16, 16, 8).unwrap();
        let all = Some([-2.0, -2.0, 2.0, 2.0]);
        let boxes = vec![all, None, all, Some([-1.0, -1.0, -0.5, -0.5]), all, all];
        let b = cpu::bin(&boxes, 3, &grid);
        assert_eq!(b.total, 4 + 4 + 1 + 4 + 4);
        assert_eq!(b.offsets, vec![0, 4, 4, 8, 9, 13]);
        // View 0's bottom-left tile (tx 0, ty 1) has items 0, 2; view 1's has items 0, 1, 2.
        assert_eq!(b.tile_items(2), vec![0, 2]);
        assert_eq!(b.tile_items(4 + 2), vec![0, 1, 2]);
        assert_eq!(b.tile_items(4), vec![1, 2]);
    }
}
