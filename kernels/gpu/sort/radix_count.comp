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
// Counted sorts: the number of pairs to sort, at most `n` (read only when `counted` is set).
layout(std430, set = 0, binding = 2) readonly buffer Count { uint count[]; };

layout(push_constant) uniform Push {
    uint n;          // pairs (counted: the capacity; blocks past the count get zero counts)
    uint shift;
    uint n_blocks;
    uint digit_mask;
    uint counted;    // 1: sort only the first min(n, count[0]) pairs
    uint copy_tail;  // scatter only
    uint scan_counts; // scatter only
} pc;

shared uint hist[RADIX];

void main() {
    uint block = linear_group_id();
    if (block >= pc.n_blocks) {
        return; // surplus group of a folded 2D grid (uniform: the whole workgroup leaves)
    }
    uint n = pc.counted != 0u ? min(pc.n, count[0]) : pc.n;
    uint lid = gl_LocalInvocationIndex;
    if (lid < RADIX) {
        hist[lid] = 0;
    }
    barrier();
    for (uint k = 0; k < ITEMS; ++k) {
        uint i = block * BLOCK + k * WG_SIZE + lid;
        if (i < n) {
            atomicAdd(hist[key_digit(keys[i], pc.shift, pc.digit_mask)], 1u);
        }
    }
    barrier();
    if (lid < RADIX) {
        counts[lid * pc.n_blocks + block] = hist[lid];
    }
}
