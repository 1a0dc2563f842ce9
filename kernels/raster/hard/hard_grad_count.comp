#version 460
#extension GL_GOOGLE_include_directive : require
// The hard family's backward, step 2: per item, the tiles of its widened visible box (its
// slots; 0 where it shows nowhere). An exclusive scan then gives each item its first slot. See
// `hard_grads.glsl`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Boxes { uint boxes[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Counts { uint counts[]; };

#define HARD_NO_POSITIONS
#define HARD_GRADS_NO_RANGES
#include "hard.glsl"
#include "hard_grads.glsl"

void main() {
    uint item = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (item >= pc.items) {
        return;
    }
    uvec4 rect;
    counts[item] = item_tiles(item, rect) ? (rect.z - rect.x + 1u) * (rect.w - rect.y + 1u) : 0u;
}
