#version 460
#extension GL_GOOGLE_include_directive : require
// Σ (P − T)² over the RGBA values of each view, one workgroup per view (the image MSE's
// partials; `fit_sum.comp` finishes the mean). Twin: `crate::fit::silhouette::cpu::mse`.
#include "common.glsl"
#include "fit_reduce.glsl"

layout(local_size_x = 256) in;

layout(std430, set = 0, binding = 0) readonly buffer Images { vec4 images[]; };
layout(std430, set = 0, binding = 1) readonly buffer Targets { vec4 targets[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Partials { float partials[]; };

layout(push_constant) uniform Push {
    uint pixels; // per view
    uint views;
} pc;

void main() {
    uint view = linear_group_id();
    if (view >= pc.views) {
        return; // the whole workgroup: uniform
    }
    uint base = view * pc.pixels;
    float acc = 0.0;
    for (uint p = gl_LocalInvocationIndex; p < pc.pixels; p += FIT_REDUCE_SIZE) {
        vec4 d = images[base + p] - targets[base + p];
        acc += ((d.x * d.x + d.y * d.y) + d.z * d.z) + d.w * d.w;
    }
    float r = workgroup_sum(vec4(acc, 0.0, 0.0, 0.0)).x;
    if (gl_LocalInvocationIndex == 0u) {
        partials[view] = r;
    }
}
