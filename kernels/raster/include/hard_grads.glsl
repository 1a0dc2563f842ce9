// The hard family's backward, what its kernels share: a deterministic sum of per-pixel
// contributions into per-vertex gradients without float atomics. Every drawn pixel belongs to an
// item (minibatch item b, triangle slot j; `pixel_item`); each item's visible box (the pixels
// that show it, widened by `pc.grow`: `hard_grad_boxes.comp`) is cut into 8×8 tiles, one slot
// each (`hard_grad_count.comp` and a scan give each item its first slot). A slot kernel sums its
// tile's contributions in pixel order (rows from the bottom, columns left to right), the reduce
// sums each item's slots in order, the gather each vertex's (item, corner) list in order.
// Twin: the pixel loops of `reference.rs` and `antialias.rs` (in another order, in f64).
#ifndef SOFTVK_HARD_GRADS_GLSL
#define SOFTVK_HARD_GRADS_GLSL

const uint NO_ITEM = 0xFFFFFFFFu;

#ifndef HARD_GRADS_NO_RANGES
// The item pixel i shows (`id` is rast's fourth channel), or NO_ITEM: nothing drawn, an id past
// the triangles, or a triangle outside its minibatch item's range. `t` gets the triangle.
uint pixel_item(uint i, float id, out uint t) {
    t = 0u;
    uint b = i / (pc.width * pc.height);
    if (!(id >= 1.0) || !(id <= float(pc.tri_count))) {
        return NO_ITEM;
    }
    t = uint(id) - 1u;
    uvec2 r = ranges[b];
    if (t < r.x || t - r.x >= r.y) {
        return NO_ITEM;
    }
    return b * pc.items_per_view + (t - r.x);
}
#endif

#ifndef HARD_GRADS_NO_BOXES
// The tiles (x0, y0, x1, y1 inclusive, rows from the bottom) of an item's widened visible box;
// false when it shows nowhere. Boxes hold (min x, min y, ~max x, ~max y), all ones when empty.
bool item_tiles(uint item, out uvec4 rect) {
    uint x0 = boxes[4u * item];
    if (x0 == 0xFFFFFFFFu) {
        rect = uvec4(0u);
        return false;
    }
    uint y0 = boxes[4u * item + 1u];
    uint x1 = ~boxes[4u * item + 2u];
    uint y1 = ~boxes[4u * item + 3u];
    x0 = x0 > pc.grow ? x0 - pc.grow : 0u;
    y0 = y0 > pc.grow ? y0 - pc.grow : 0u;
    x1 = min(x1 + pc.grow, pc.width - 1u);
    y1 = min(y1 + pc.grow, pc.height - 1u);
    rect = uvec4(x0 / 8u, y0 / 8u, x1 / 8u, y1 / 8u);
    return true;
}

#endif

#ifdef HARD_GRADS_SLOTS
// The slot's item (the last whose first slot is at most `slot`) and its tile (column, row of
// tiles); binary search over the items' first slots.
uvec3 slot_tile(uint slot) {
    uint lo = 0u;
    uint hi = pc.items - 1u;
    while (lo < hi) {
        uint mid = (lo + hi + 1u) / 2u;
        if (offsets[mid] <= slot) {
            lo = mid;
        } else {
            hi = mid - 1u;
        }
    }
    uvec4 rect;
    item_tiles(lo, rect);
    uint k = slot - offsets[lo];
    uint across = rect.z - rect.x + 1u;
    uint row = k / across;
    return uvec3(lo, rect.x + (k - row * across), rect.y + row);
}
#endif

#endif
