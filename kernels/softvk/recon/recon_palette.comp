#version 460
#extension GL_GOOGLE_include_directive : require
// The colour generator's palette: per object b and entry p, C_p = Σ_k softmax_k(s[p])_k q_k
// over the pooled cells in order, with the softmax's log-normalizer in .w
// (`recon_colors.glsl`). Twin: `crate::recon::colors::cpu::forward`.
#include "common.glsl"
#include "recon_colors.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) readonly buffer Pooled { vec4 pooled[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Palette { vec4 palette[]; };

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.objects * pc.palette) {
        return;
    }
    uint b = gid / pc.palette;
    uint p = gid - b * pc.palette;
    uint cells = pc.grid * pc.grid;
    uint s0 = sampling_logit(b, p, 0u);
    float m = outputs[s0];
    for (uint k = 1u; k < cells; ++k) {
        m = max(m, outputs[s0 + k]);
    }
    float total = 0.0;
    vec3 c = vec3(0.0);
    for (uint k = 0u; k < cells; ++k) {
        float e = fm_exp(outputs[s0 + k] - m);
        total += e;
        c += e * pooled[b * cells + k].rgb;
    }
    palette[gid] = vec4(fm_div3(c, total), m + fm_log(total));
}
