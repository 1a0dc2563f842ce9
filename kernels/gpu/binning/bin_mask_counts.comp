#version 460
#extension GL_GOOGLE_include_directive : require
// Binning through per-tile item masks: one invocation per tile counts the set bits of its mask
// (words `[t W, (t + 1) W)`, set by `bin_count.comp` for faces, `probe_items.comp` for anchors):
// the tile's entry count, which an exclusive scan over the tiles turns into each tile's first
// entry. With summaries (`pc.summary_offset` ≠ 0; see `bin_count.comp`) it visits only the
// words its summary marks non-zero. `bin_mask_list.comp` and `probe_mask_list.comp` then write
// each tile's entries, its items in index order.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Masks { uint masks[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Counts { uint counts[]; };

layout(push_constant) uniform Push {
    uint tiles;
    uint words_per_tile; // W = ⌈items per view / 32⌉
    uint pad0;
    uint summary_offset; // the first summary word; 0: no summaries, every word is counted
} pc;

void main() {
    uint tile = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (tile >= pc.tiles) {
        return;
    }
    uint base = tile * pc.words_per_tile;
    uint c = 0u;
    if (pc.summary_offset != 0u) {
        uint summary_words = (pc.words_per_tile + 31u) / 32u;
        uint summary = pc.summary_offset + tile * summary_words;
        for (uint s = 0u; s < summary_words; ++s) {
            uint nonzero = masks[summary + s];
            while (nonzero != 0u) {
                uint w = 32u * s + uint(findLSB(nonzero));
                nonzero &= nonzero - 1u;
                c += uint(bitCount(masks[base + w]));
            }
        }
    } else {
        for (uint w = 0u; w < pc.words_per_tile; ++w) {
            c += uint(bitCount(masks[base + w]));
        }
    }
    counts[tile] = c;
}
