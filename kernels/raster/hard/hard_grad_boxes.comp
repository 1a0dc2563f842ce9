#version 460
#extension GL_GOOGLE_include_directive : require
// The hard family's backward, step 1: per pixel, the item it shows widens that item's visible
// box (integer atomicMin on (x, y, ~x, ~y): the result does not depend on the order). The host
// fills the boxes with all ones first. See `hard_grads.glsl`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rast { vec4 rast[]; };
layout(std430, set = 0, binding = 1) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, set = 0, binding = 2) buffer Boxes { uint boxes[]; };

#define HARD_NO_POSITIONS
#define HARD_GRADS_NO_BOXES
#include "hard.glsl"
#include "hard_grads.glsl"

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (i >= pc.batch * pixels) {
        return;
    }
    uint t;
    uint item = pixel_item(i, rast[i].w, t);
    if (item == NO_ITEM) {
        return;
    }
    uint p = i % pixels;
    uint y = p / pc.width;
    uint x = p - y * pc.width;
    atomicMin(boxes[4u * item], x);
    atomicMin(boxes[4u * item + 1u], y);
    atomicMin(boxes[4u * item + 2u], ~x);
    atomicMin(boxes[4u * item + 3u], ~y);
}
