#version 460
#extension GL_GOOGLE_include_directive : require
// The backward of `recon_palette.comp` through `recon_colors.comp`, per object b and palette
// entry p: with g_i the copies' colour gradients summed in copy order,
//   dL/dC_p = Σ_i softmax_p(w[i])_p g_i                  (over the vertices in order)
//   dL/ds[p][k] = a_k (q_k − C_p) · dL/dC_p,   a = softmax(s[p]) = e^{s − lse}
// into the sampling logits' slots of dL/d(outputs) (the input image gets no gradient).
// Twin: `crate::recon::colors::cpu::backward`.
#include "common.glsl"
#include "recon_colors.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) readonly buffer Pooled { vec4 pooled[]; };
layout(std430, set = 0, binding = 2) readonly buffer Palette { vec4 palette[]; };
layout(std430, set = 0, binding = 3) readonly buffer DColors { float d_colors[]; };
layout(std430, set = 0, binding = 4) writeonly buffer DOutputs { float d_outputs[]; };

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.objects * pc.palette) {
        return;
    }
    uint b = gid / pc.palette;
    uint p = gid - b * pc.palette;
    vec3 d_c = vec3(0.0);
    for (uint i = 0u; i < pc.vertex_count; ++i) {
        vec3 g = vec3(0.0);
        for (uint j = 0u; j < pc.copies; ++j) {
            uint at = 3u * ((b * pc.copies + j) * pc.vertex_count + i);
            g += vec3(d_colors[at], d_colors[at + 1u], d_colors[at + 2u]);
        }
        uint w0 = selection_logit(b, i, 0u);
        float m = outputs[w0];
        for (uint q = 1u; q < pc.palette; ++q) {
            m = max(m, outputs[w0 + q]);
        }
        float total = 0.0;
        for (uint q = 0u; q < pc.palette; ++q) {
            total += fm_exp(outputs[w0 + q] - m);
        }
        d_c += fm_div(fm_exp(outputs[w0 + p] - m), total) * g;
    }
    vec4 entry = palette[gid];
    uint cells = pc.grid * pc.grid;
    uint s0 = sampling_logit(b, p, 0u);
    for (uint k = 0u; k < cells; ++k) {
        float a = fm_exp(outputs[s0 + k] - entry.w);
        d_outputs[s0 + k] = a * fm_dot3(pooled[b * cells + k].rgb - entry.rgb, d_c);
    }
}
