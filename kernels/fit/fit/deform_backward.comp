#version 460
#extension GL_GOOGLE_include_directive : require
// The backward of `deform_forward.comp`, per vertex coordinate, from g = dL/d(position):
//   dL/d displace = g · (v > 0 ? 1 − c : c + 1) · s (1 − s) · sign(t),
// and the vertex's share of dL/d center, g (1 − |v|) (1 − c²), at its own slot of `partials`;
// `fit_sum.comp` then sums the shares of each coordinate over the vertices in a fixed order.
// Twin: `crate::fit::deform::cpu::backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Base { float base[]; };
layout(std430, set = 0, binding = 2) readonly buffer Signs { float signs[]; };
layout(std430, set = 0, binding = 3) readonly buffer DPositions { float d_positions[]; };
layout(std430, set = 0, binding = 4) writeonly buffer DParams { float d_params[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Partials { float partials[]; };

layout(push_constant) uniform Push {
    uint vertex_count;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.vertex_count) {
        return;
    }
    for (uint k = 0u; k < 3u; ++k) {
        uint o = 3u * i + k;
        float c = fm_tanh(params[3u * pc.vertex_count + k]);
        float s = fm_sigmoid(base[o] + params[o]);
        float sign_t = signs[o];
        float v = s * sign_t;
        float g = d_positions[o];
        // d(relu(v)(1 − c) − relu(−v)(c + 1))/dv; v ≠ 0 since s > 0 and t ≠ 0.
        float dv = v > 0.0 ? 1.0 - c : c + 1.0;
        d_params[o] = g * dv * (s * (1.0 - s)) * sign_t;
        // d/dc of the same: −relu(v) − relu(−v) + 1 = 1 − |v|; times dc/d center = 1 − c².
        partials[o] = g * (1.0 - abs(v)) * (1.0 - c * c);
    }
}
