#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
// `nn_conv_forward.comp` for rows of whole texels (in_w a multiple of 4, the input at a texel
// boundary), its kernel size, stride and padding specialization constants: per input channel
// and kernel row, the window of input texels the block's taps cover and the 4 output channels'
// weights of each tap (packed by `nn_conv_pack_weights.comp`) are read as texels of 4 floats,
// one gather each where a storage-buffer load is a scalar loop over the lanes on a CPU device.
// With K, S, P constant the window's columns are constant indices (registers, no scratch).
// out[b][o][oy][ox] = act(bias[o] + Σ_c Σ_ky Σ_kx w[o][c][ky][kx] · in[b][c][oy·s + ky − p][ox·s + kx − p]),
// summed in that order; taps outside the input (zero padding) add an exact 0.
// One invocation per block of 4 output channels × 4 adjacent columns of one output row: per
// (channel, kernel row), WT + K texels feed 16 K products.
// Twin: `crate::nn::cpu::conv2d_forward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(constant_id = 2) const uint K = 5u;
layout(constant_id = 3) const uint S = 2u;
layout(constant_id = 4) const uint P = 2u;

// Output column ox0 (a multiple of 4) reads from column ox0 S − P, which is OFF columns into
// its texel; the block's taps span SPAN columns from that texel's start, WT texels.
const uint OFF = (4u - P % 4u) % 4u;
const uint SPAN = OFF + 3u * S + K;
const uint WT = (SPAN + 3u) / 4u;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
// The packed weights: the 4 output channels of block ob at tap (c, ky, kx), texel
// ((c K + ky) K + kx) OB + ob.
layout(set = 0, binding = 1, rgba32ui) uniform readonly restrict uimageBuffer weights;
// The input batch, in[b][c][iy][ix] at texel ((b C + c) H + iy) W / 4 + ix / 4.
layout(set = 0, binding = 2, rgba32ui) uniform readonly restrict uimageBuffer inp;
layout(std430, set = 0, binding = 3) writeonly buffer Output { float outp[]; };

NN_CONV_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint x_blocks = (pc.out_w + 3u) / 4u;
    uint o_blocks = (pc.out_c + 3u) / 4u;
    uint xb = id % x_blocks;
    uint t = id / x_blocks;
    uint oy = t % pc.out_h;
    t /= pc.out_h;
    uint ob = t % o_blocks;
    uint b = t / o_blocks;
    uint o0 = ob * 4u;
    // Past the last channel: the packed weights are 0 there, the bias the last one's.
    uvec4 o = min(uvec4(o0, o0 + 1u, o0 + 2u, o0 + 3u), uvec4(pc.out_c - 1u));
    uint bias_at = pc.param_offset + pc.out_c * pc.in_c * K * K;
    vec4 bias = vec4(params[bias_at + o.x], params[bias_at + o.y], params[bias_at + o.z],
                     params[bias_at + o.w]);
    // acc[r]: the 4 channels at output column 4 xb + r.
    vec4 acc[4] = vec4[4](bias, bias, bias, bias);
    int y0 = int(oy * S) - int(P);
    uint ky0 = uint(max(-y0, 0));
    uint ky1 = uint(clamp(int(pc.in_h) - y0, 0, int(K)));
    int row_texels = int(pc.in_w / 4u);
    // The window's first texel (exact: 4 xb S − P − OFF is a multiple of 4).
    int t0 = (int(4u * xb * S) - int(P) - int(OFF)) / 4;
    for (uint c = 0u; c < pc.in_c; ++c) {
        uint plane = (b * pc.in_c + c) * pc.in_h;
        for (uint ky = ky0; ky < ky1; ++ky) {
            int row = int(plane + uint(y0 + int(ky))) * row_texels;
            vec4 win[WT];
            [[unroll]] for (uint j = 0u; j < WT; ++j) {
                int tx = t0 + int(j);
                bool inside = tx >= 0 && tx < row_texels;
                vec4 v = uintBitsToFloat(imageLoad(inp, row + clamp(tx, 0, row_texels - 1)));
                win[j] = inside ? v : vec4(0.0);
            }
            uint w_at = ((c * K + ky) * K) * o_blocks + ob;
            [[unroll]] for (uint kx = 0u; kx < K; ++kx) {
                vec4 w = uintBitsToFloat(imageLoad(weights, int(w_at + kx * o_blocks)));
                [[unroll]] for (uint r = 0u; r < 4u; ++r) {
                    uint col = OFF + r * S + kx;
                    acc[r] += w * win[col / 4u][col % 4u];
                }
            }
        }
    }
    for (uint q = 0u; q < 4u; ++q) {
        if (o0 + q >= pc.out_c) {
            break;
        }
        uint out_row = ((b * pc.out_c + o0 + q) * pc.out_h + oy) * pc.out_w;
        for (uint r = 0u; r < 4u; ++r) {
            if (4u * xb + r < pc.out_w) {
                outp[out_row + 4u * xb + r] = activate(acc[r][q]);
            }
        }
    }
}
