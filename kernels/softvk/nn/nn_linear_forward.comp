#version 460
#extension GL_GOOGLE_include_directive : require
// Linear forward with its fused activation: out[b][o] = act(bias[o] + Σ_i, in order,
// w[o][i] · in[b][i]). One invocation per block of 4 outputs × 4 samples: per input, 4 weights
// and 4 inputs feed 16 products (llvmpipe turns every load into 8 lane loads).
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
    uint o_blocks = (pc.out_f + 3u) / 4u;
    uint o0 = (id % o_blocks) * 4u;
    uint b0 = (id / o_blocks) * 4u;
    // Past the last output or sample: read the last one's, store nothing.
    uvec4 o = min(uvec4(o0, o0 + 1u, o0 + 2u, o0 + 3u), uvec4(pc.out_f - 1u));
    uvec4 in_row = min(uvec4(b0, b0 + 1u, b0 + 2u, b0 + 3u), uvec4(pc.batch - 1u)) * pc.in_f;
    uvec4 w_row = pc.param_offset + o * pc.in_f;
    uint bias_at = pc.param_offset + pc.out_f * pc.in_f;
    vec4 acc0 = vec4(params[bias_at + o.x]);
    vec4 acc1 = vec4(params[bias_at + o.y]);
    vec4 acc2 = vec4(params[bias_at + o.z]);
    vec4 acc3 = vec4(params[bias_at + o.w]);
    for (uint i = 0u; i < pc.in_f; ++i) {
        vec4 x = vec4(inp[in_row.x + i], inp[in_row.y + i], inp[in_row.z + i], inp[in_row.w + i]);
        acc0 += params[w_row.x + i] * x;
        acc1 += params[w_row.y + i] * x;
        acc2 += params[w_row.z + i] * x;
        acc3 += params[w_row.w + i] * x;
    }
    mat4 acc = mat4(acc0, acc1, acc2, acc3);
    for (uint q = 0u; q < 4u; ++q) {
        if (o0 + q >= pc.out_f) {
            break;
        }
        for (uint r = 0u; r < 4u; ++r) {
            if (b0 + r < pc.batch) {
                outp[(b0 + r) * pc.out_f + o0 + q] = activate(acc[q][r]);
            }
        }
    }
}
