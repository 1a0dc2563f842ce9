#version 460
#extension GL_GOOGLE_include_directive : require
// Binning through per-tile item masks, last step (`BinStrategy::Masks`; in place of the
// scatter, the sort and the ranges pass): one invocation per tile writes the tile's entries
// from its first one on (the scan of `bin_mask_counts.comp`'s counts), its items in index
// order (the set bits of its mask, word by word, lowest first: the words its summary marks
// non-zero; see `bin_count.comp`), and its `[start, end)` range (`[0, 0]` when empty). Each
// entry is the item-major slot of its (item, tile) pair: the item's first slot (the count's
// scan) plus the tile's row-major place in the item's rectangle, which is where
// `bin_scatter.comp` would have put it; the item of every slot is written too. So the result is
// the sorted binning's, entry for entry. (One invocation per tile rather than per
// mask word: on llvmpipe the workgroups of a dispatch over every word cost more than the loop.)
// Twin: `binning::cpu::bin`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Masks { uint masks[]; };
layout(std430, set = 0, binding = 1) readonly buffer TileOffsets { uint tile_offsets[]; };
layout(std430, set = 0, binding = 2) readonly buffer ItemOffsets { uint item_offsets[]; };
layout(std430, set = 0, binding = 3) readonly buffer Rects { uvec2 rects[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Entries { uint entries[]; };
layout(std430, set = 0, binding = 5) writeonly buffer EntryItems { uint entry_items[]; };
layout(std430, set = 0, binding = 6) writeonly buffer Ranges { uvec2 ranges[]; };

layout(push_constant) uniform Push {
    uint tiles;          // tiles of the job (views × tiles per view)
    uint words_per_tile; // W = ⌈items per view / 32⌉
    uint items_per_view;
    uint tiles_x;
    uint tiles_per_view;
    uint summary_offset; // the first summary word (see bin_count.comp)
    uint pad1;
    uint pad2;
} pc;

void main() {
    uint tile = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (tile >= pc.tiles) {
        return;
    }
    uint view = tile / pc.tiles_per_view;
    uint in_view = tile - view * pc.tiles_per_view;
    uint ty = in_view / pc.tiles_x;
    uint tx = in_view - ty * pc.tiles_x;
    // A guarded binning (`Binner::record_sort_guarded`) may count more entries than the buffers
    // hold; nothing is written past them (the caller then discards the binning).
    uint cap = uint(entries.length());
    uint first = tile_offsets[tile];
    uint o = first;
    uint base = tile * pc.words_per_tile;
    uint summary_words = (pc.words_per_tile + 31u) / 32u;
    uint summary = pc.summary_offset + tile * summary_words;
    for (uint s = 0u; s < summary_words; ++s) {
        uint nonzero = masks[summary + s];
        while (nonzero != 0u) {
            uint w = 32u * s + uint(findLSB(nonzero));
            nonzero &= nonzero - 1u;
            uint m = masks[base + w];
            while (m != 0u) {
                uint item = 32u * w + uint(findLSB(m));
                m &= m - 1u;
                uint id = view * pc.items_per_view + item;
                uvec2 r = rects[id];
                uint x0 = r.x & 0xFFFFu;
                uint x1 = r.x >> 16u;
                uint y0 = r.y & 0xFFFFu;
                uint slot = item_offsets[id] + (ty - y0) * (x1 - x0 + 1u) + (tx - x0);
                if (o < cap && slot < cap) {
                    entries[o] = slot;
                    entry_items[slot] = item;
                }
                ++o;
            }
        }
    }
    ranges[tile] = o == first ? uvec2(0u) : uvec2(first, o);
}
