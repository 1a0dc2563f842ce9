#version 460
#extension GL_GOOGLE_include_directive : require
// The colour generator's vertex colours: per object b and vertex i,
//   c_i = Σ_p softmax_p(w[i])_p C_p    (`recon_colors.glsl`; the palette by `recon_palette.comp`)
// written (RGB, then an unused float: the renderer's colour layout) to every copy of the
// object (mesh b · copies + k). Twin: `crate::recon::colors::cpu::forward`.
#include "common.glsl"
#include "recon_colors.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) readonly buffer Palette { vec4 palette[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Colors { vec4 colors[]; };

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.vertex_count * pc.objects) {
        return;
    }
    uint b = gid / pc.vertex_count;
    uint i = gid - b * pc.vertex_count;
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
    for (uint k = 0u; k < pc.copies; ++k) {
        colors[(b * pc.copies + k) * pc.vertex_count + i] = vec4(c, 0.0);
    }
}
