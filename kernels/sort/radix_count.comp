#version 460
#extension GL_GOOGLE_include_directive : require
// Radix sort pass, step 1: per-block digit histogram, written digit-major
// (counts[digit * n_blocks + block]) so one exclusive scan of `counts` gives every (digit, block)
// its first output position, in the order that keeps the sort stable.
#include "radix_config.glsl"
#include "common.glsl"

layout(local_size_x = WG_SIZE) in;

layout(std430, set = 0, binding = 0) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Counts { uint counts[]; };

layout(push_constant) uniform Push {
    uint n;
    uint shift;
    uint n_blocks;
    uint digit_mask;
} pc;

shared uint hist[RADIX];

void main() {
    uint block = linear_group_id();
    if (block * BLOCK >= pc.n) {
        return; // surplus group of a folded 2D grid (uniform: the whole workgroup leaves)
    }
    uint lid = gl_LocalInvocationIndex;
    if (lid < RADIX) {
        hist[lid] = 0;
    }
    barrier();
    for (uint k = 0; k < ITEMS; ++k) {
        uint i = block * BLOCK + k * WG_SIZE + lid;
        if (i < pc.n) {
            atomicAdd(hist[key_digit(keys[i], pc.shift, pc.digit_mask)], 1u);
        }
    }
    barrier();
    if (lid < RADIX) {
        counts[lid * pc.n_blocks + block] = hist[lid];
    }
}
