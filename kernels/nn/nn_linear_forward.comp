#version 460
#extension GL_GOOGLE_include_directive : require
// Linear forward with its fused activation, one invocation per output (b, o):
// out[b][o] = act(bias[o] + Σ_i, in order, w[o][i] · in[b][i]).
// Twin: `crate::nn::cpu::linear_forward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Input { float inp[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Output { float outp[]; };

NN_LINEAR_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint o = id % pc.out_f;
    uint b = id / pc.out_f;
    float s = params[pc.param_offset + pc.out_f * pc.in_f + o];
    uint w_at = pc.param_offset + o * pc.in_f;
    uint in_at = b * pc.in_f;
    for (uint i = 0u; i < pc.in_f; ++i) {
        s += params[w_at + i] * inp[in_at + i];
    }
    outp[id] = activate(s);
}
