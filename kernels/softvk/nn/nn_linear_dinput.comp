#version 460
#extension GL_GOOGLE_include_directive : require
// Linear backward, the input's gradient: d_in[b][i] = Σ_o, in order, w[o][i] · d_pre[b][o]
// (d_pre from `nn_act_backward`). One invocation per block of 4 inputs × 4 samples: per output,
// 4 weights and 4 gradients feed 16 products.
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
    uint i_blocks = (pc.in_f + 3u) / 4u;
    uint i0 = (id % i_blocks) * 4u;
    uint b0 = (id / i_blocks) * 4u;
    uvec4 i = pc.param_offset + min(uvec4(i0, i0 + 1u, i0 + 2u, i0 + 3u), uvec4(pc.in_f - 1u));
    uvec4 d_row = min(uvec4(b0, b0 + 1u, b0 + 2u, b0 + 3u), uvec4(pc.batch - 1u)) * pc.out_f;
    vec4 acc0 = vec4(0.0);
    vec4 acc1 = vec4(0.0);
    vec4 acc2 = vec4(0.0);
    vec4 acc3 = vec4(0.0);
    for (uint o = 0u; o < pc.out_f; ++o) {
        vec4 d = vec4(d_pre[d_row.x + o], d_pre[d_row.y + o], d_pre[d_row.z + o], d_pre[d_row.w + o]);
        uint w_row = o * pc.in_f;
        acc0 += params[w_row + i.x] * d;
        acc1 += params[w_row + i.y] * d;
        acc2 += params[w_row + i.z] * d;
        acc3 += params[w_row + i.w] * d;
    }
    mat4 acc = mat4(acc0, acc1, acc2, acc3);
    for (uint q = 0u; q < 4u; ++q) {
        if (i0 + q >= pc.in_f) {
            break;
        }
        for (uint r = 0u; r < 4u; ++r) {
            if (b0 + r < pc.batch) {
                d_in[(b0 + r) * pc.in_f + i0 + q] = acc[q][r];
            }
        }
    }
}
