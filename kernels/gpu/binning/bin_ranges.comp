#version 460
#extension GL_GOOGLE_include_directive : require
// Binning, step 3: after the stable sort by tile, each tile's entries are one run; this writes
// [start, end) of every non-empty tile's run (the buffer is cleared to 0 first, so empty tiles
// read as empty). One invocation per sorted entry. Twin: `binning::cpu::bin`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) buffer Ranges { uvec2 ranges[]; };

layout(push_constant) uniform Push {
    uint n;      // sorted entries
    uint tiles;  // tiles in the ranges buffer
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    uint tile = keys[i].x;
    if (tile >= pc.tiles) {
        return; // cannot happen with consistent keys; never write out of bounds
    }
    if (i == 0u || keys[i - 1u].x != tile) {
        ranges[tile].x = i;
    }
    if (i + 1u == pc.n || keys[i + 1u].x != tile) {
        ranges[tile].y = i + 1u;
    }
}
