//! The CPU twin of binning: the same tile rectangles in the same f32 arithmetic
//! (`binning.glsl`), and the same lists.

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

#[cfg(test)]
mod tests {
    use super::*;

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
            let rect = tile_rect(b, &grid);
            for row in 0..grid.height {
                for col in 0..grid.width {
                    let x = (2.0 * col as f32 + 1.0 - 37.0) / s;
                    let y = (2.0 * (23.0 - 1.0 - row as f32) + 1.0 - 23.0) / s;
                    if x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3] {
                        let r = rect.unwrap_or_else(|| panic!("{b:?} lost ({col}, {row})"));
                        let (tx, ty) = pixel_tile(col, row, &grid);
                        assert!(tx >= r[0] && tx <= r[2] && ty >= r[1] && ty <= r[3]);
                    }
                }
            }
        }
        assert_eq!(tile_rect([5.0, 5.0, 6.0, 6.0], &grid), None);
        assert_eq!(tile_rect([f32::NAN, 0.0, 1.0, 1.0], &grid), None);
        assert_eq!(tile_rect([1.0, 1.0, -1.0, -1.0], &grid), None);
    }

    #[test]
    fn cpu_bin_keeps_item_order_within_tiles() {
        let grid = TileGrid::new(16, 16, 8).unwrap();
        let all = Some([-2.0, -2.0, 2.0, 2.0]);
        let boxes = vec![all, None, all, Some([-1.0, -1.0, -0.5, -0.5]), all, all];
        let b = bin(&boxes, 3, &grid);
        assert_eq!(b.total, 4 + 4 + 1 + 4 + 4);
        assert_eq!(b.offsets, vec![0, 4, 4, 8, 9, 13]);
        // View 0's bottom-left tile (tx 0, ty 1) has items 0, 2; view 1's has items 0, 1, 2.
        assert_eq!(b.tile_items(2), vec![0, 2]);
        assert_eq!(b.tile_items(4 + 2), vec![0, 1, 2]);
        assert_eq!(b.tile_items(4), vec![1, 2]);
    }
}
