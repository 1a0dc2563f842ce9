#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, binning step 3: one invocation per tile writes the tile's anchors (the set
// bits of its mask, `probe_items.comp`, word by word, lowest first) from the tile's first entry
// on (the scan of `bin_mask_counts.comp`'s counts), and where the per-entry backward runs
// (not under G = max), each entry's tile and each word's first entry within the tile, which the
// gradient sum (`probe_reduce.comp`) looks entries up by. The entries come out sorted by tile
// (view-major), each tile's anchors in index order: what the generic binning's stable sort
// gives, without a sort. (One invocation per tile rather than per word: on llvmpipe the
// workgroups of a dispatch over every word cost more than the loop.)
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Masks { uint masks[]; };
layout(std430, set = 0, binding = 1) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 2) writeonly buffer WordPrefix { uint word_prefix[]; };
layout(std430, set = 0, binding = 3) writeonly buffer List { uint list[]; };
layout(std430, set = 0, binding = 4) writeonly buffer ListTiles { uint list_tiles[]; };

layout(push_constant) uniform Push {
    uint tiles;
    uint words_per_tile; // W = ⌈anchors / 32⌉
    uint word_begin;     // with PARTS: this pass's words [word_begin, word_end) of each mask
    uint word_end;
} pc;

// Write `list_tiles` and `word_prefix` (the per-entry backward's): a specialization constant,
// since on llvmpipe a store under a false `if` still costs a masked scalar loop per entry.
layout(constant_id = 0) const uint WRITE_TILES = 1u;
// A mask whose words and bits are too many for one invocation's loops (llvmpipe: 65 535
// iterations) is listed in passes over its words; each pass starts at the entry that the bits of
// the words before it leave (their bit counts: one iteration a word).
layout(constant_id = 1) const uint PARTS = 0u;

void main() {
    uint tile = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (tile >= pc.tiles) {
        return;
    }
    uint first = offsets[tile];
    uint o = first;
    uint base = tile * pc.words_per_tile;
    uint begin = PARTS != 0u ? min(pc.word_begin, pc.words_per_tile) : 0u;
    uint end = PARTS != 0u ? min(pc.word_end, pc.words_per_tile) : pc.words_per_tile;
    for (uint w = 0u; w < begin; ++w) {
        o += uint(bitCount(masks[base + w]));
    }
    for (uint w = begin; w < end; ++w) {
        uint m = masks[base + w];
        if (WRITE_TILES != 0u) {
            word_prefix[base + w] = o - first;
        }
        while (m != 0u) {
            list[o] = 32u * w + uint(findLSB(m));
            if (WRITE_TILES != 0u) {
                list_tiles[o] = tile;
            }
            m &= m - 1u;
            ++o;
        }
    }
}
