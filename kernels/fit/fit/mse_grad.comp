#version 460
#extension GL_GOOGLE_include_directive : require
// dL/dP of L = mean((P − T)²) over M = N·W·H·4 values: 2 (P − T) / M per RGBA value, times
// the weight (`coef` = 2 weight / M); with `accumulate` added to what the buffer holds.
// Twin: `crate::fit::silhouette::cpu::mse`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Images { vec4 images[]; };
layout(std430, set = 0, binding = 1) readonly buffer Targets { vec4 targets[]; };
layout(std430, set = 0, binding = 2) buffer DImage { vec4 d_image[]; };

layout(push_constant) uniform Push {
    uint count; // pixels of all views
    float coef;
    uint accumulate;
    uint pad;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.count) {
        return;
    }
    vec4 g = pc.coef * (images[id] - targets[id]);
    if (pc.accumulate != 0u) {
        g += d_image[id];
    }
    d_image[id] = g;
}
