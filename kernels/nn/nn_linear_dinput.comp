#version 460
#extension GL_GOOGLE_include_directive : require
// Linear backward, the input's gradient: one invocation per input element (b, i):
// d_in[b][i] = Σ_o, in order, w[o][i] · d_pre[b][o] (d_pre from `nn_act_backward`).
// Twin: the d_input loop of `crate::nn::cpu::linear_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer DPre { float d_pre[]; };
layout(std430, set = 0, binding = 2) writeonly buffer DInput { float d_in[]; };

NN_LINEAR_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint i = id % pc.in_f;
    uint b = id / pc.in_f;
    uint d_at = b * pc.out_f;
    float s = 0.0;
    for (uint o = 0u; o < pc.out_f; ++o) {
        s += params[pc.param_offset + o * pc.in_f + i] * d_pre[d_at + o];
    }
    d_in[id] = s;
}
