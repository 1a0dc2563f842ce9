#version 460
#extension GL_GOOGLE_include_directive : require
// The hard family's backward, step 4 (after a slot kernel): per (item, float d), the sum of the
// item's slots' partials in slot order. See `hard_grads.glsl`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Counts { uint counts[]; };
layout(std430, set = 0, binding = 2) readonly buffer Partials { float partials[]; };
layout(std430, set = 0, binding = 3) writeonly buffer ItemGrads { float item_grads[]; };

#define HARD_NO_POSITIONS
#include "hard.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.items * pc.dims) {
        return;
    }
    uint item = id / pc.dims;
    uint d = id - item * pc.dims;
    uint first = offsets[item];
    uint n = counts[item];
    precise float sum = 0.0;
    for (uint s = 0u; s < n; ++s) {
        sum += partials[(first + s) * pc.dims + d];
    }
    item_grads[id] = sum;
}
