//! What one binning covers and how it is planned: the tile grid ([`TileGrid`], or a window of
//! its rows), where the items' boxes sit ([`ItemLayout`]), the job ([`BinJob`]), the strategy
//! its entries are put in tile order by ([`BinStrategy`]), and the sizes of the masks and the
//! count's 64-bit sums, which the buffers and the passes both follow.

#[cfg(doc)]
use super::Binner;
use crate::error::{Error, Result};
use crate::gpu::Context;

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
pub(super) fn mask_layout(words_per_tile: u32, tiles: u64) -> (u64, u64) {
    let w = u64::from(words_per_tile);
    ((w + w.div_ceil(32)) * tiles, w * tiles)
}

/// Counts each invocation of `bin_count_sum.comp` adds (its loop's length).
pub(super) const COUNTS_PER_SUM: u64 = 256;

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

#[cfg(test)]
mod tests {
    use super::*;

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
}
