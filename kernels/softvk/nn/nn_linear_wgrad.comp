#version 460
#extension GL_GOOGLE_include_directive : require
// Linear backward, the parameters' gradient, written (not accumulated) at
// d_params[param_offset + j]: Σ_b, in order, d_pre[b][o] · in[b][i] for weight w[o][i], Σ_b
// d_pre[b][o] for bias o. Invocations: one per block of 4 outputs × 4 inputs (per sample, 4
// gradients and 4 inputs feed 16 products), then one per bias.
// Twin: the d_params loops of `crate::nn::cpu::linear_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Input { float inp[]; };
layout(std430, set = 0, binding = 1) readonly buffer DPre { float d_pre[]; };
layout(std430, set = 0, binding = 2) writeonly buffer DParams { float d_params[]; };

NN_LINEAR_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint i_blocks = (pc.in_f + 3u) / 4u;
    uint blocks = ((pc.out_f + 3u) / 4u) * i_blocks;
    uint weights = pc.out_f * pc.in_f;
    if (id >= blocks) {
        uint o = id - blocks;
        float s = 0.0;
        for (uint b = 0u; b < pc.batch; ++b) {
            s += d_pre[b * pc.out_f + o];
        }
        d_params[pc.param_offset + weights + o] = s;
        return;
    }
    uint i0 = (id % i_blocks) * 4u;
    uint o0 = (id / i_blocks) * 4u;
    uvec4 o = min(uvec4(o0, o0 + 1u, o0 + 2u, o0 + 3u), uvec4(pc.out_f - 1u));
    uvec4 i = min(uvec4(i0, i0 + 1u, i0 + 2u, i0 + 3u), uvec4(pc.in_f - 1u));
    vec4 acc0 = vec4(0.0);
    vec4 acc1 = vec4(0.0);
    vec4 acc2 = vec4(0.0);
    vec4 acc3 = vec4(0.0);
    for (uint b = 0u; b < pc.batch; ++b) {
        uint in_row = b * pc.in_f;
        uint d_row = b * pc.out_f;
        vec4 x = vec4(inp[in_row + i.x], inp[in_row + i.y], inp[in_row + i.z], inp[in_row + i.w]);
        acc0 += d_pre[d_row + o.x] * x;
        acc1 += d_pre[d_row + o.y] * x;
        acc2 += d_pre[d_row + o.z] * x;
        acc3 += d_pre[d_row + o.w] * x;
    }
    mat4 acc = mat4(acc0, acc1, acc2, acc3);
    for (uint q = 0u; q < 4u; ++q) {
        if (o0 + q >= pc.out_f) {
            break;
        }
        for (uint r = 0u; r < 4u; ++r) {
            if (i0 + r < pc.in_f) {
                d_params[pc.param_offset + (o0 + q) * pc.in_f + i0 + r] = acc[q][r];
            }
        }
    }
}
