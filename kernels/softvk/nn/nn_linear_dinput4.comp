#version 460
#extension GL_GOOGLE_include_directive : require
// `nn_linear_dinput.comp` for rows of whole texels (in_f a multiple of 4, the weights at a
// texel boundary): the weights are read as texels of 4 floats, one gather per texel where a
// storage-buffer load is a scalar loop over the lanes on a CPU device.
// d_in[b][i] = Σ_o, in order, w[o][i] · d_pre[b][o]. One invocation per block of 8 inputs
// (2 texels) × 4 samples: per output, 2 texels and 4 gradients feed 32 products.
// Twin: the d_input loop of `crate::nn::cpu::linear_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

// This layer's weights, w[o][i] at texel (o in_f + i) / 4.
layout(set = 0, binding = 0, rgba32ui) uniform readonly restrict uimageBuffer weights;
layout(std430, set = 0, binding = 1) readonly buffer DPre { float d_pre[]; };
layout(std430, set = 0, binding = 2) writeonly buffer DInput { float d_in[]; };

NN_LINEAR_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint row = pc.in_f / 4u;
    uint i_blocks = (row + 1u) / 2u;
    uint t0 = (id % i_blocks) * 2u;
    uint b0 = (id / i_blocks) * 4u;
    // Past the last texel or sample: read the last one's, store nothing.
    uint t1 = min(t0 + 1u, row - 1u);
    uvec4 d_row = min(uvec4(b0, b0 + 1u, b0 + 2u, b0 + 3u), uvec4(pc.batch - 1u)) * pc.out_f;
    vec4 a0 = vec4(0.0), a1 = vec4(0.0), a2 = vec4(0.0), a3 = vec4(0.0);
    vec4 c0 = vec4(0.0), c1 = vec4(0.0), c2 = vec4(0.0), c3 = vec4(0.0);
    for (uint o = 0u; o < pc.out_f; ++o) {
        vec4 wa = uintBitsToFloat(imageLoad(weights, int(o * row + t0)));
        vec4 wb = uintBitsToFloat(imageLoad(weights, int(o * row + t1)));
        float d0 = d_pre[d_row.x + o];
        float d1 = d_pre[d_row.y + o];
        float d2 = d_pre[d_row.z + o];
        float d3 = d_pre[d_row.w + o];
        a0 += wa * d0;
        c0 += wb * d0;
        a1 += wa * d1;
        c1 += wb * d1;
        a2 += wa * d2;
        c2 += wb * d2;
        a3 += wa * d3;
        c3 += wb * d3;
    }
    vec4 lo[4] = vec4[4](a0, a1, a2, a3);
    vec4 hi[4] = vec4[4](c0, c1, c2, c3);
    for (uint r = 0u; r < 4u; ++r) {
        if (b0 + r >= pc.batch) {
            break;
        }
        uint at = (b0 + r) * pc.in_f + 4u * t0;
        for (uint q = 0u; q < 4u; ++q) {
            d_in[at + q] = lo[r][q];
        }
        if (t0 + 1u < row) {
            for (uint q = 0u; q < 4u; ++q) {
                d_in[at + 4u + q] = hi[r][q];
            }
        }
    }
}
