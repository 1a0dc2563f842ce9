#version 460
#extension GL_GOOGLE_include_directive : require
// Linear backward, the parameters' gradient: one invocation per parameter j, written (not
// accumulated) at d_params[param_offset + j]: Σ_b, in order, d_pre[b][o] · in[b][i] for weight
// w[o][i], Σ_b d_pre[b][o] for bias o.
// Twin: the d_params loops of `crate::nn::cpu::linear_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Input { float inp[]; };
layout(std430, set = 0, binding = 1) readonly buffer DPre { float d_pre[]; };
layout(std430, set = 0, binding = 2) writeonly buffer DParams { float d_params[]; };

NN_LINEAR_PUSH

void main() {
    uint j = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (j >= pc.total) {
        return;
    }
    uint weights = pc.out_f * pc.in_f;
    float s = 0.0;
    if (j >= weights) {
        uint o = j - weights;
        for (uint b = 0u; b < pc.batch; ++b) {
            s += d_pre[b * pc.out_f + o];
        }
    } else {
        uint o = j / pc.in_f;
        uint i = j % pc.in_f;
        for (uint b = 0u; b < pc.batch; ++b) {
            s += d_pre[b * pc.out_f + o] * inp[b * pc.in_f + i];
        }
    }
    d_params[pc.param_offset + j] = s;
}
