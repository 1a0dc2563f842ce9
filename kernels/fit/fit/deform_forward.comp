#version 460
#extension GL_GOOGLE_include_directive : require
// SoftRas's deformation (demo_deform.py), per vertex coordinate: with base = log(|t| / (1 − |t|))
// and sign(t) of the template t (precomputed on the host), c = tanh(center),
//   v = sigmoid(base + displace) sign(t);  v = relu(v) (1 − c) − relu(−v) (c + 1) + c.
// Params: displace (3 per vertex), then center (3). Twin: `crate::fit::deform::cpu::forward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Base { float base[]; };
layout(std430, set = 0, binding = 2) readonly buffer Signs { float signs[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Positions { float positions[]; };

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
        float v = s * signs[o];
        positions[o] = (max(v, 0.0) * (1.0 - c) - max(-v, 0.0) * (c + 1.0)) + c;
    }
}
