#version 460
#extension GL_GOOGLE_include_directive : require
// Grid backward, step 4 of 4: per grid node, the sum over the (up to) 8 cells it is a corner of,
// in a fixed cell order, of that cell's piece sums in position order (a cell's pieces start at
// its first position and at every GRID_CHUNK boundary inside its range). Writes
// d_params[node] = (accumulate ? d_params[node] : 0) + sum: batch after batch, fixed order.
// Twin: `crate::field::cpu::backward` (Grid).
#include "common.glsl"

#define GRID_CHUNK 256u

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer CellStart { uint cell_start[]; };
layout(std430, set = 0, binding = 1) readonly buffer CellEnd { uint cell_end[]; };
layout(std430, set = 0, binding = 2) readonly buffer Partial { float partial[]; };
layout(std430, set = 0, binding = 3) buffer DParams { float d_params[]; };

layout(push_constant) uniform Push {
    uint res;
    uint accumulate;
} pc;

void main() {
    uint v = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint res = pc.res;
    if (v >= res * res * res) {
        return;
    }
    uvec3 q = uvec3(v % res, (v / res) % res, v / (res * res));
    uint cells = res - 1u;
    float acc = 0.0;
    for (uint k = 0u; k < 8u; ++k) {
        // The node is corner k of the cell q − o(k).
        uvec3 o = uvec3(k & 1u, (k >> 1u) & 1u, (k >> 2u) & 1u);
        if (any(lessThan(q, o)) || any(greaterThanEqual(q - o, uvec3(cells)))) {
            continue;
        }
        uvec3 c = q - o;
        uint ci = c.x + cells * (c.y + cells * c.z);
        uint s = cell_start[ci];
        uint e = cell_end[ci];
        while (s < e) {
            acc += partial[8u * s + k];
            s = (s / GRID_CHUNK + 1u) * GRID_CHUNK;
        }
    }
    d_params[v] = (pc.accumulate != 0u ? d_params[v] : 0.0) + acc;
}
