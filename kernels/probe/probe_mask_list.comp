#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, binning step 3: one invocation per word of the tiles' anchor masks writes
// its anchors (its set bits, lowest first) and their tile at the word's first entry (the tile's
// scanned offset plus the word's prefix within the tile, `probe_mask_counts.comp`). The
// entries come out sorted by tile (view-major), each tile's anchors in index order: what the
// generic binning's stable sort gives, without a sort.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Masks { uint masks[]; };
layout(std430, set = 0, binding = 1) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 2) readonly buffer WordPrefix { uint word_prefix[]; };
layout(std430, set = 0, binding = 3) writeonly buffer List { uint list[]; };
layout(std430, set = 0, binding = 4) writeonly buffer ListTiles { uint list_tiles[]; };

layout(push_constant) uniform Push {
    uint words;          // tiles × W
    uint words_per_tile; // W = ⌈anchors / 32⌉
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.words) {
        return;
    }
    uint m = masks[i];
    uint tile = i / pc.words_per_tile;
    uint o = offsets[tile] + word_prefix[i];
    uint base = 32u * (i - tile * pc.words_per_tile);
    while (m != 0u) {
        list[o] = base + uint(findLSB(m));
        list_tiles[o] = tile;
        m &= m - 1u;
        ++o;
    }
}
