#version 460
#extension GL_GOOGLE_include_directive : require
// `nn_linear_wgrad.comp` for rows of whole texels (in_f a multiple of 4): the inputs are read
// as texels of 4 floats, one gather per texel where a storage-buffer load is a scalar loop over
// the lanes on a CPU device. The parameters' gradient, written (not accumulated) at
// d_params[param_offset + j]: Σ_b, in order, d_pre[b][o] · in[b][i] for weight w[o][i], Σ_b
// d_pre[b][o] for bias o. Invocations: one per block of 4 outputs × 8 inputs (2 texels; per
// sample, 4 gradients and 2 texels feed 32 products), then one per bias.
// Twin: the d_params loops of `crate::nn::cpu::linear_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

// The input batch, in[b][i] at texel (b in_f + i) / 4.
layout(set = 0, binding = 0, rgba32ui) uniform readonly restrict uimageBuffer inp;
layout(std430, set = 0, binding = 1) readonly buffer DPre { float d_pre[]; };
layout(std430, set = 0, binding = 2) writeonly buffer DParams { float d_params[]; };

NN_LINEAR_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint row = pc.in_f / 4u;
    uint i_blocks = (row + 1u) / 2u;
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
    uint t0 = (id % i_blocks) * 2u;
    uint o0 = (id / i_blocks) * 4u;
    // Past the last output or texel: read the last one's, store nothing.
    uint t1 = min(t0 + 1u, row - 1u);
    uvec4 o = min(uvec4(o0, o0 + 1u, o0 + 2u, o0 + 3u), uvec4(pc.out_f - 1u));
    vec4 a0 = vec4(0.0), a1 = vec4(0.0), a2 = vec4(0.0), a3 = vec4(0.0);
    vec4 c0 = vec4(0.0), c1 = vec4(0.0), c2 = vec4(0.0), c3 = vec4(0.0);
    for (uint b = 0u; b < pc.batch; ++b) {
        vec4 xa = uintBitsToFloat(imageLoad(inp, int(b * row + t0)));
        vec4 xb = uintBitsToFloat(imageLoad(inp, int(b * row + t1)));
        uint d_row = b * pc.out_f;
        float d0 = d_pre[d_row + o.x];
        float d1 = d_pre[d_row + o.y];
        float d2 = d_pre[d_row + o.z];
        float d3 = d_pre[d_row + o.w];
        a0 += d0 * xa;
        c0 += d0 * xb;
        a1 += d1 * xa;
        c1 += d1 * xb;
        a2 += d2 * xa;
        c2 += d2 * xb;
        a3 += d3 * xa;
        c3 += d3 * xb;
    }
    vec4 lo[4] = vec4[4](a0, a1, a2, a3);
    vec4 hi[4] = vec4[4](c0, c1, c2, c3);
    for (uint q = 0u; q < 4u; ++q) {
        if (o0 + q >= pc.out_f) {
            break;
        }
        uint at = pc.param_offset + (o0 + q) * pc.in_f + 4u * t0;
        for (uint r = 0u; r < 4u; ++r) {
            d_params[at + r] = lo[q][r];
        }
        if (t0 + 1u < row) {
            for (uint r = 0u; r < 4u; ++r) {
                d_params[at + 4u + r] = hi[q][r];
            }
        }
    }
}
