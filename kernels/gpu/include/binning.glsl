// Tiled binning, shared by the count and scatter kernels: which screen tiles an item's box can
// touch. Twin: `binning::cpu::tile_rect` (src/primitives/binning.rs), operation for operation.
//
// Items (faces after setup, anchor spheres, ...) live in a float buffer with a fixed stride; each
// has a screen box (x_min, y_min, x_max, y_max) in the SPEC's pixel-centre coordinates
// x_p = (2c + 1 - W) / S, y_p = (2(H - 1 - r) + 1 - H) / S, and optionally a flag word whose
// `flag_mask` bits must all be set for the item to be binned at all.
#ifndef SOFTVK_BINNING_GLSL
#define SOFTVK_BINNING_GLSL
// A kernel that defines BINNING_TILE_RECT_ONLY gets `tile_rect` alone, reading `pc.width`,
// `pc.height` and `pc.tile_size` from its own push constants (sphere probing's items kernel).
#ifndef BINNING_TILE_RECT_ONLY

// Twin of `BinPush` (src/primitives/binning.rs).
layout(push_constant) uniform Push {
    uint item_count;      // items binned by this dispatch (views × items per view)
    uint items_per_view;
    uint first_item;      // index of the first binned item in the items buffer
    uint stride_words;    // item stride in 32-bit words
    uint box_offset;      // word offset of the box within an item
    uint flag_offset;     // word offset of the flag word within an item
    uint flag_mask;       // bits that must all be set (0: every item is binned)
    uint width;           // image size in pixels
    uint height;
    uint tile_size;       // tile edge in pixels
    uint tiles_x;
    uint tiles_y;
    uint words_per_tile;  // count: W of the per-tile item masks to set (0: none; see bin_count)
    uint first_row;       // the window's first tile row (tiles_y rows from it; 0: the image)
    uint summary_offset;  // count with masks: the first summary word (see bin_count)
    uint pad2;
} pc;
#endif

// Columns and rows of pixel centres the box may contain, widened by one pixel on each side
// against rounding, as (c0, r0, c1, r1) inclusive. False when no pixel of the image can be
// touched or the box has a NaN; ±∞ boxes are clamped to the image.
bool pixel_rect(vec4 box, out uvec4 rect) {
    if (any(isnan(box))) {
        rect = uvec4(0u);
        return false;
    }
    float w = float(pc.width);
    float h = float(pc.height);
    float s = min(w, h);
    // c = (x S + W - 1) / 2; r = (H - 1 - y S) / 2. `precise`: no fused multiply-add, so the
    // CPU twin reproduces every rounding.
    precise float c0 = floor((box.x * s + (w - 1.0)) * 0.5) - 1.0;
    precise float c1 = ceil((box.z * s + (w - 1.0)) * 0.5) + 1.0;
    precise float r0 = floor(((h - 1.0) - box.w * s) * 0.5) - 1.0;
    precise float r1 = ceil(((h - 1.0) - box.y * s) * 0.5) + 1.0;
    c0 = max(c0, 0.0);
    r0 = max(r0, 0.0);
    c1 = min(c1, w - 1.0);
    r1 = min(r1, h - 1.0);
    if (!(c0 <= c1 && r0 <= r1)) {
        rect = uvec4(0u);
        return false;
    }
    rect = uvec4(uint(c0), uint(r0), uint(c1), uint(r1));
    return true;
}

// The tiles holding `pixel_rect`'s pixels (the fine pass tests the exact box per pixel; a
// tile too many costs time, never a pixel).
bool tile_rect(vec4 box, out uvec4 rect) {
    if (!pixel_rect(box, rect)) {
        return false;
    }
    rect /= pc.tile_size;
    return true;
}

#ifndef BINNING_TILE_RECT_ONLY
// The part of a tile rectangle inside the window of tile rows `first_row .. first_row + tiles_y`
// (`TileGrid::window`), its rows numbered from the window's first; false when none is. Twin:
// `binning::cpu::window_rect`.
bool window_rect(inout uvec4 rect) {
    uint last = pc.first_row + pc.tiles_y - 1u;
    if (rect.w < pc.first_row || rect.y > last) {
        return false;
    }
    rect.y = max(rect.y, pc.first_row) - pc.first_row;
    rect.w = min(rect.w, last) - pc.first_row;
    return true;
}

// The box of item `item` (an index into the whole items buffer), or false when its flags say it
// is not binned.
bool item_box(uint item, out vec4 box) {
    uint base = item * pc.stride_words;
    uint flags = floatBitsToUint(items[base + pc.flag_offset]);
    box = vec4(items[base + pc.box_offset], items[base + pc.box_offset + 1u],
               items[base + pc.box_offset + 2u], items[base + pc.box_offset + 3u]);
    return (flags & pc.flag_mask) == pc.flag_mask;
}

#endif
#endif
