#version 460
#extension GL_GOOGLE_include_directive : require
// Level-up pass of the multi-level exclusive scan: one sum per BLOCK of input elements.
#include "scan_config.glsl"
#include "common.glsl"
#include "workgroup_scan.glsl"

layout(local_size_x = WG_SIZE) in;

layout(std430, set = 0, binding = 0) readonly buffer Input { uint data_in[]; };
layout(std430, set = 0, binding = 1) writeonly buffer BlockSums { uint block_sums[]; };

layout(push_constant) uniform Push {
    uint n;          // elements in this (possibly chunked) range of the input
    uint block_base; // index in block_sums of this range's first block
} pc;

void main() {
    uint block = linear_group_id();
    if (block * BLOCK >= pc.n) {
        return; // surplus group of a folded 2D grid (uniform: the whole workgroup leaves)
    }
    uint base = block * BLOCK + gl_LocalInvocationIndex * ITEMS;
    uint sum = 0;
    for (uint k = 0; k < ITEMS; ++k) {
        uint i = base + k;
        sum += i < pc.n ? data_in[i] : 0u;
    }
    uint total;
    workgroup_exclusive_scan(sum, total);
    if (gl_LocalInvocationIndex == 0) {
        block_sums[pc.block_base + block] = total;
    }
}
