//! Tiled binning (SPEC §4): which items (faces after setup, anchor spheres, ...) each screen tile
//! must visit, with every capacity computed exactly.
//!
//! 1. **Count** (`kernels/gpu/binning/bin_count.comp`): per item, the number of tiles its screen box
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
//!
//! The parts: the job and its planning (`job.rs`: [`TileGrid`], [`BinJob`], [`BinStrategy`]),
//! the buffers ([`Bins`], `bins.rs`), the recorded passes ([`Binner`], `passes.rs`) and the twin
//! ([`cpu`]).

mod bins;
pub mod cpu;
mod job;
mod passes;

pub use bins::{Bins, max_entries};
pub use job::{BinJob, BinStrategy, ItemLayout, MASK_MAX_TILES_PER_VIEW, TileGrid};
pub use passes::Binner;

#[cfg(doc)]
use super::{scan::Scan, sort::RadixSort};
