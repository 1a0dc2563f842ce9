#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, binning step 2: the bit count of every word of the tiles' anchor masks
// (`probe_masks.comp`), which an exclusive scan turns into each word's first entry: tile t's
// entries are `[offsets[t · W], offsets[(t + 1) · W])`, its anchors in index order.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Masks { uint masks[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Counts { uint counts[]; };

layout(push_constant) uniform Push {
    uint words; // tiles × W
    uint pad0;
    uint pad1;
    uint pad2;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i < pc.words) {
        counts[i] = uint(bitCount(masks[i]));
    }
}
