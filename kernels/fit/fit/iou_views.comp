#version 460
#extension GL_GOOGLE_include_directive : require
// SoftRas's IoU per view, one workgroup per view: I = Σ P T, U = Σ (P + T − P T) + 1e-6 over
// the view's pixels, P the alpha channel of the rendered RGBA image, T the target silhouette.
// Writes (I, U, I / U, 0). Twin: `crate::fit::silhouette::cpu::neg_iou`.
#include "common.glsl"
#include "fit_reduce.glsl"

layout(local_size_x = 256) in;

layout(std430, set = 0, binding = 0) readonly buffer Images { vec4 images[]; };
layout(std430, set = 0, binding = 1) readonly buffer Targets { float targets[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Stats { vec4 stats[]; };

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
    vec2 acc = vec2(0.0);
    for (uint p = gl_LocalInvocationIndex; p < pc.pixels; p += FIT_REDUCE_SIZE) {
        float a = images[base + p].w;
        float t = targets[base + p];
        float pt = a * t;
        acc += vec2(pt, a + t - pt);
    }
    vec2 r = workgroup_sum(vec4(acc, 0.0, 0.0)).xy;
    if (gl_LocalInvocationIndex == 0u) {
        float u = r.y + 1e-6;
        stats[view] = vec4(r.x, u, fm_div(r.x, u), 0.0);
    }
}
