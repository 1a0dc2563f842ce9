#version 460
#extension GL_GOOGLE_include_directive : require
// The backward of `recon_colors.comp`, per object b and vertex i: with g_i the copies' colour
// gradients (3 floats per vertex, mesh after mesh: the renderer's backward's layout) summed in
// copy order and β = softmax(w[i]),
//   dL/dw[i][p] = β_p (C_p − c_i) · g_i
// into the selection logits' slots of dL/d(outputs). Twin: `crate::recon::colors::cpu::backward`.
#include "common.glsl"
#include "recon_colors.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) readonly buffer Palette { vec4 palette[]; };
layout(std430, set = 0, binding = 2) readonly buffer DColors { float d_colors[]; };
layout(std430, set = 0, binding = 3) writeonly buffer DOutputs { float d_outputs[]; };

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.vertex_count * pc.objects) {
        return;
    }
    uint b = gid / pc.vertex_count;
    uint i = gid - b * pc.vertex_count;
    vec3 g = vec3(0.0);
    for (uint j = 0u; j < pc.copies; ++j) {
        uint at = 3u * ((b * pc.copies + j) * pc.vertex_count + i);
        g += vec3(d_colors[at], d_colors[at + 1u], d_colors[at + 2u]);
    }
    uint w0 = selection_logit(b, i, 0u);
    float m = outputs[w0];
    for (uint p = 1u; p < pc.palette; ++p) {
        m = max(m, outputs[w0 + p]);
    }
    float total = 0.0;
    vec3 c = vec3(0.0);
    for (uint p = 0u; p < pc.palette; ++p) {
        float e = fm_exp(outputs[w0 + p] - m);
        total += e;
        c += e * palette[b * pc.palette + p].rgb;
    }
    c = fm_div3(c, total);
    for (uint p = 0u; p < pc.palette; ++p) {
        float beta = fm_div(fm_exp(outputs[w0 + p] - m), total);
        d_outputs[w0 + p] = beta * fm_dot3(palette[b * pc.palette + p].rgb - c, g);
    }
}
