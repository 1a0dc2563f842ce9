#version 460
#extension GL_GOOGLE_include_directive : require
// Binning, step 1: how many tiles each item's box touches (0 for an item that is not binned).
// One invocation per item. An exclusive scan of these counts gives every item its slot in the
// pair list, and the total sizes that list exactly. Twin: `binning::cpu::bin`.
//
// With per-tile masks (`pc.words_per_tile` = W ≠ 0; `BinStrategy::Masks`), it also bins the
// item in place of the scatter and sort: it writes the item's tile rectangle (packed) and sets
// the item's bit in the mask of every tile of the rectangle (tile t's items are the set bits of
// words `[t W, (t + 1) W)`, W = ⌈items per view / 32⌉; integer `atomicOr`, so the result does not
// depend on the order of the writes). `bin_mask_counts.comp`, a scan and `bin_mask_list.comp`
// list them. Each tile also has a summary of its mask, S = ⌈W / 32⌉ words from word
// `pc.summary_offset + t S`: bit w set where mask word w is not zero, set by the item that made
// the word non-zero. The counts and the lists walk the summaries' set bits instead of every word
// of every mask (a tile holds tens of items; a mask of spot's 5 856 faces has 183 words).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Items { float items[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Counts { uint counts[]; };
// Masks only: per item, (x0 | x1 << 16, y0 | y1 << 16) of its tile rectangle (unwritten for an
// item that is not binned: no mask lists it).
layout(std430, set = 0, binding = 2) writeonly buffer Rects { uvec2 rects[]; };
// Masks only: per tile, a bit per item of its view; zero before this kernel.
layout(std430, set = 0, binding = 3) buffer TileMasks { uint tile_masks[]; };

#include "binning.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.item_count) {
        return;
    }
    vec4 box;
    uvec4 rect;
    uint count = 0u;
    bool binned = item_box(pc.first_item + id, box) && tile_rect(box, rect) && window_rect(rect);
    if (binned) {
        count = (rect.z - rect.x + 1u) * (rect.w - rect.y + 1u);
    }
    counts[id] = count;
    uint words = pc.words_per_tile;
    if (words == 0u || !binned) {
        return;
    }
    rects[id] = uvec2(rect.x | (rect.z << 16u), rect.y | (rect.w << 16u));
    uint view = id / pc.items_per_view;
    uint item = id - view * pc.items_per_view;
    uint tile_base = view * pc.tiles_x * pc.tiles_y;
    uint word = item / 32u;
    uint bit = 1u << (item & 31u);
    uint summary_words = (words + 31u) / 32u;
    uint summary_bit = 1u << (word & 31u);
    for (uint ty = rect.y; ty <= rect.w; ++ty) {
        for (uint tx = rect.x; tx <= rect.z; ++tx) {
            uint tile = tile_base + ty * pc.tiles_x + tx;
            // Exactly one item sees the word empty: the one whose bit came first.
            if (atomicOr(tile_masks[tile * words + word], bit) == 0u) {
                atomicOr(tile_masks[pc.summary_offset + tile * summary_words + word / 32u],
                         summary_bit);
            }
        }
    }
}
