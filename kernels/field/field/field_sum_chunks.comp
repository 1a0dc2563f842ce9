#version 460
#extension GL_GOOGLE_include_directive : require
// Backward, last step (MLP and analytic fields): per parameter j, the chunk partials of a batch
// summed in chunk order, d_params[j] = (accumulate ? d_params[j] : 0) + Σ_c partial[c · P + j]:
// one writer per element, batch after batch, a fixed order. Twin: `crate::field::cpu::backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Partial { float partial[]; };
layout(std430, set = 0, binding = 1) buffer DParams { float d_params[]; };

layout(push_constant) uniform Push {
    uint param_count;
    uint chunks;
    uint accumulate;
    uint pad;
} pc;

void main() {
    uint j = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (j >= pc.param_count) {
        return;
    }
    float s = 0.0;
    for (uint c = 0u; c < pc.chunks; ++c) {
        s += partial[c * pc.param_count + j];
    }
    d_params[j] = (pc.accumulate != 0u ? d_params[j] : 0.0) + s;
}
