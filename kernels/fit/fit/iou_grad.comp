#version 460
#extension GL_GOOGLE_include_directive : require
// dL/dP of L = 1 − (1/N) Σ_n I_n / U_n, per pixel, as an RGBA gradient (RGB 0, A = dL/dP):
// dL/dP = −(1/N) (T U − I (1 − T)) / U². `coef` = −weight / N; with `accumulate` the result is
// added to what the buffer holds (one writer per pixel). Twin: `crate::fit::silhouette::cpu`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Targets { float targets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Stats { vec4 stats[]; };
layout(std430, set = 0, binding = 2) buffer DImage { vec4 d_image[]; };

layout(push_constant) uniform Push {
    uint pixels; // per view
    uint views;
    float coef;
    uint accumulate;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.pixels * pc.views) {
        return;
    }
    vec4 s = stats[id / pc.pixels];
    float t = targets[id];
    float g = pc.coef * fm_div(t * s.y - s.x * (1.0 - t), s.y * s.y);
    vec4 out_value = vec4(0.0, 0.0, 0.0, g);
    if (pc.accumulate != 0u) {
        out_value += d_image[id];
    }
    d_image[id] = out_value;
}
