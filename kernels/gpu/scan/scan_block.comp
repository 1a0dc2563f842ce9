#version 460
#extension GL_GOOGLE_include_directive : require
// Exclusive scan of each BLOCK of the input, offset by the already-scanned block sums of the level
// above. May run in place (data_in and data_out bound to the same range): every invocation reads
// its own ITEMS elements before the first barrier and writes only those.
#include "scan_config.glsl"
#include "common.glsl"
#include "workgroup_scan.glsl"

layout(local_size_x = WG_SIZE) in;

layout(std430, set = 0, binding = 0) buffer Input { uint data_in[]; };
layout(std430, set = 0, binding = 1) buffer Output { uint data_out[]; };
// Exclusive prefix of block sums (ignored when use_offsets == 0).
layout(std430, set = 0, binding = 2) readonly buffer BlockOffsets { uint block_offsets[]; };
// Grand total of the whole scan, written by the last element's invocation when write_total != 0.
layout(std430, set = 0, binding = 3) writeonly buffer Total { uint total_out[]; };

layout(push_constant) uniform Push {
    uint n;           // elements in this range
    uint block_base;  // index in block_offsets of this range's first block
    uint use_offsets;
    uint total_index; // n - 1 of the *whole* scan, relative to this range; ~0u when not here
} pc;

void main() {
    uint block = linear_group_id();
    if (block * BLOCK >= pc.n) {
        return; // surplus group of a folded 2D grid (uniform: the whole workgroup leaves)
    }
    uint base = block * BLOCK + gl_LocalInvocationIndex * ITEMS;
    uint v[ITEMS];
    uint sum = 0;
    for (uint k = 0; k < ITEMS; ++k) {
        uint i = base + k;
        v[k] = i < pc.n ? data_in[i] : 0u;
        sum += v[k];
    }
    uint block_total;
    uint prefix = workgroup_exclusive_scan(sum, block_total);
    if (pc.use_offsets != 0) {
        prefix += block_offsets[pc.block_base + block];
    }
    for (uint k = 0; k < ITEMS; ++k) {
        uint i = base + k;
        if (i < pc.n) {
            data_out[i] = prefix;
        }
        if (i == pc.total_index) {
            total_out[0] = prefix + v[k];
        }
        prefix += v[k];
    }
}
