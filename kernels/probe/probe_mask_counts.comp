#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, binning step 2: one invocation per tile counts the set bits of its anchor
// mask (`probe_items.comp`): the tile's entry count, which an exclusive scan over the tiles
// turns into each tile's first entry. Tile t's entries are then `[offsets[t], offsets[t + 1])`
// (`probe_mask_list.comp` writes them), its anchors in index order.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Masks { uint masks[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Counts { uint counts[]; };

layout(push_constant) uniform Push {
    uint tiles;
    uint words_per_tile; // W = ⌈anchors / 32⌉
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint tile = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (tile >= pc.tiles) {
        return;
    }
    uint base = tile * pc.words_per_tile;
    uint c = 0u;
    for (uint w = 0u; w < pc.words_per_tile; ++w) {
        c += uint(bitCount(masks[base + w]));
    }
    counts[tile] = c;
}
