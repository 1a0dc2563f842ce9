#version 460
#extension GL_GOOGLE_include_directive : require
// The hard family's backward, step 5: per (output row r, float c < dims / 3), the sum over the
// row's (item, corner) list (CSR, built on the host in minibatch, triangle, corner order) of the
// item's float `corner · dims / 3 + c`. One writer per output float: deterministic. See
// `hard_grads.glsl`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer RowOffsets { uint row_offsets[]; };
// item · 3 + corner
layout(std430, set = 0, binding = 1) readonly buffer RowEntries { uint row_entries[]; };
layout(std430, set = 0, binding = 2) readonly buffer ItemGrads { float item_grads[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Out { float grads[]; };

#define HARD_NO_POSITIONS
#include "hard.glsl"

void main() {
    uint per = pc.dims / 3u;
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.rows * per) {
        return;
    }
    uint row = id / per;
    uint c = id - row * per;
    precise float sum = 0.0;
    for (uint e = row_offsets[row]; e < row_offsets[row + 1u]; ++e) {
        uint entry = row_entries[e];
        uint item = entry / 3u;
        uint corner = entry - 3u * item;
        sum += item_grads[item * pc.dims + corner * per + c];
    }
    grads[id] = sum;
}
