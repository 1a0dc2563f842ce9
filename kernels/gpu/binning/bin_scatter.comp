#version 460
#extension GL_GOOGLE_include_directive : require
// Binning, step 2: every item writes one (tile, pair) entry per tile it touches, at its scanned
// offset, tiles in row-major order. Entries are therefore item-major (view-major, then item
// order): a stable sort by tile then leaves every tile's items in index order, which is what
// makes the tiled passes visit faces in the brute-force order. Twin: `binning::cpu::bin`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Items { float items[]; };
layout(std430, set = 0, binding = 1) readonly buffer Offsets { uint offsets[]; };
// Sort keys (lo, hi): the tile, view-major within this dispatch.
layout(std430, set = 0, binding = 2) writeonly buffer Keys { uvec2 keys[]; };
// Sort values: the entry's own item-major index, so that after sorting by tile each entry still
// knows its item-major slot (the backward writes per-pair partials there).
layout(std430, set = 0, binding = 3) writeonly buffer Pairs { uint pairs[]; };
// The item (within its view) of every item-major entry.
layout(std430, set = 0, binding = 4) writeonly buffer PairItems { uint pair_items[]; };

#include "binning.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.item_count) {
        return;
    }
    vec4 box;
    uvec4 rect;
    if (!(item_box(pc.first_item + id, box) && tile_rect(box, rect) && window_rect(rect))) {
        return;
    }
    uint view = id / pc.items_per_view;
    uint item = id - view * pc.items_per_view;
    uint tile_base = view * pc.tiles_x * pc.tiles_y;
    uint slot = offsets[id];
    // Never write past the bound entries: with a guarded binning (`record_sort_guarded`) the
    // count may exceed the capacity, and the caller then discards the whole binning.
    uint n = (rect.z - rect.x + 1u) * (rect.w - rect.y + 1u);
    if (uint(keys.length()) < n || slot > uint(keys.length()) - n) {
        return;
    }
    for (uint ty = rect.y; ty <= rect.w; ++ty) {
        for (uint tx = rect.x; tx <= rect.z; ++tx) {
            keys[slot] = uvec2(tile_base + ty * pc.tiles_x + tx, 0u);
            pairs[slot] = slot;
            pair_items[slot] = item;
            ++slot;
        }
    }
}
