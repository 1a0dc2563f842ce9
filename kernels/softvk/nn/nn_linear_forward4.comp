#version 460
#extension GL_GOOGLE_include_directive : require
// `nn_linear_forward.comp` for rows of whole texels (in_f a multiple of 4, the weights at a
// texel boundary): the weights and the inputs are read as texels of 4 floats, one gather per
// texel where a storage-buffer load is a scalar loop over the lanes on a CPU device.
// out[b][o] = act(bias[o] + Σ_t dot(w[o][4t .. 4t+3], in[b][4t .. 4t+3])), t in order.
// One invocation per block of 4 outputs × 4 samples: per texel step, 8 texels feed 64 products.
// Twin: `crate::nn::cpu::linear_forward` (the same sum, in another order).
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
// This layer's weights, w[o][i] at texel (o in_f + i) / 4.
layout(set = 0, binding = 1, rgba32ui) uniform readonly restrict uimageBuffer weights;
// The input batch, in[b][i] at texel (b in_f + i) / 4.
layout(set = 0, binding = 2, rgba32ui) uniform readonly restrict uimageBuffer inp;
layout(std430, set = 0, binding = 3) writeonly buffer Output { float outp[]; };

NN_LINEAR_PUSH


void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint o_blocks = (pc.out_f + 3u) / 4u;
    uint o0 = (id % o_blocks) * 4u;
    uint b0 = (id / o_blocks) * 4u;
    uint row = pc.in_f / 4u;
    // Past the last output or sample: read the last one's, store nothing.
    uvec4 o = min(uvec4(o0, o0 + 1u, o0 + 2u, o0 + 3u), uvec4(pc.out_f - 1u));
    uvec4 x_at = min(uvec4(b0, b0 + 1u, b0 + 2u, b0 + 3u), uvec4(pc.batch - 1u)) * row;
    uvec4 w_at = o * row;
    uint bias_at = pc.param_offset + pc.out_f * pc.in_f;
    vec4 acc0 = vec4(params[bias_at + o.x]);
    vec4 acc1 = vec4(params[bias_at + o.y]);
    vec4 acc2 = vec4(params[bias_at + o.z]);
    vec4 acc3 = vec4(params[bias_at + o.w]);
    for (uint t = 0u; t < row; ++t) {
        vec4 x0 = uintBitsToFloat(imageLoad(inp, int(x_at.x + t)));
        vec4 x1 = uintBitsToFloat(imageLoad(inp, int(x_at.y + t)));
        vec4 x2 = uintBitsToFloat(imageLoad(inp, int(x_at.z + t)));
        vec4 x3 = uintBitsToFloat(imageLoad(inp, int(x_at.w + t)));
        vec4 w0 = uintBitsToFloat(imageLoad(weights, int(w_at.x + t)));
        vec4 w1 = uintBitsToFloat(imageLoad(weights, int(w_at.y + t)));
        vec4 w2 = uintBitsToFloat(imageLoad(weights, int(w_at.z + t)));
        vec4 w3 = uintBitsToFloat(imageLoad(weights, int(w_at.w + t)));
        acc0 += vec4(fm_dot4(w0, x0), fm_dot4(w0, x1), fm_dot4(w0, x2), fm_dot4(w0, x3));
        acc1 += vec4(fm_dot4(w1, x0), fm_dot4(w1, x1), fm_dot4(w1, x2), fm_dot4(w1, x3));
        acc2 += vec4(fm_dot4(w2, x0), fm_dot4(w2, x1), fm_dot4(w2, x2), fm_dot4(w2, x3));
        acc3 += vec4(fm_dot4(w3, x0), fm_dot4(w3, x1), fm_dot4(w3, x2), fm_dot4(w3, x3));
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
