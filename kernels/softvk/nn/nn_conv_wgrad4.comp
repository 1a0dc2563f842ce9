#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
// `nn_conv_wgrad.comp` for rows of whole texels (in_w and out_w multiples of 4, the input and
// the gradient at texel boundaries), its kernel size, stride and padding specialization
// constants: per output row and block of 4 output columns, the 4 output channels' gradients and
// the window of input texels the columns' taps cover are read as texels of 4 floats, one gather
// each where a storage-buffer load is a scalar loop over the lanes on a CPU device; with K, S, P
// constant the window's columns are constant indices (registers).
// The parameters' gradient per sample, partial[b · P + j] (P = O·C·K² + O): the sum over the
// sample's outputs, in the order oy, ox, of d_pre[b][o][oy][ox] · in[b][c][oy·s + ky − p][ox·s + kx − p]
// for weight w[o][c][ky][kx] (taps outside the input add an exact 0), of d_pre[b][o][oy][ox] for
// bias o. `nn_sum_rows` then sums over b in order.
// Invocations: per sample, first one per (block of 4 output channels, input channel, kernel row
// ky) for the K taps of the row (per output row and 4 columns, 4 + WT texels feed 16 K
// products), then one per bias.
// Twin: the d_params loops of `crate::nn::cpu::conv2d_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(constant_id = 2) const uint K = 5u;
layout(constant_id = 3) const uint S = 2u;
layout(constant_id = 4) const uint P = 2u;

// As in `nn_conv_forward4.comp`: output column ox0 (a multiple of 4) reads from column ox0 S − P,
// OFF columns into its texel; the 4 columns' taps span WT texels.
const uint OFF = (4u - P % 4u) % 4u;
const uint SPAN = OFF + 3u * S + K;
const uint WT = (SPAN + 3u) / 4u;

// The input batch, in[b][c][iy][ix] at texel ((b C + c) H + iy) W / 4 + ix / 4.
layout(set = 0, binding = 0, rgba32ui) uniform readonly restrict uimageBuffer inp;
// dL/d(pre-activation), d_pre[b][o][oy][ox] at texel ((b O + o) OH + oy) OW / 4 + ox / 4.
layout(set = 0, binding = 1, rgba32ui) uniform readonly restrict uimageBuffer d_pre;
layout(std430, set = 0, binding = 2) readonly buffer DPreFloats { float d_pre_floats[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Partial { float partial[]; };

NN_CONV_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint kk = K * K;
    uint o_blocks = (pc.out_c + 3u) / 4u;
    uint blocks = o_blocks * pc.in_c * K;
    uint weights = pc.out_c * pc.in_c * kk;
    uint p_count = weights + pc.out_c;
    uint plane_out = pc.out_h * pc.out_w;
    if (id >= pc.batch * blocks) {
        uint bias = id - pc.batch * blocks;
        uint b = bias / pc.out_c;
        uint o = bias % pc.out_c;
        uint at = (b * pc.out_c + o) * plane_out;
        float acc = 0.0;
        for (uint i = 0u; i < plane_out; ++i) {
            acc += d_pre_floats[at + i];
        }
        partial[b * p_count + weights + o] = acc;
        return;
    }
    uint ky = id % K;
    uint t = id / K;
    uint c = t % pc.in_c;
    t /= pc.in_c;
    uint ob = t % o_blocks;
    uint b = t / o_blocks;
    uint o0 = ob * 4u;
    uvec4 o = min(uvec4(o0, o0 + 1u, o0 + 2u, o0 + 3u), uvec4(pc.out_c - 1u));
    // The output rows whose tap row ky lands inside the input: iy = oy·s + ky − p in [0, in_h).
    uint oy0 = P > ky ? (P - ky + S - 1u) / S : 0u;
    int hy = int(pc.in_h + P) - int(ky);
    uint oy1 = hy > 0 ? min(pc.out_h, (uint(hy) + S - 1u) / S) : 0u;
    uint out_texels = pc.out_w / 4u;
    int row_texels = int(pc.in_w / 4u);
    uvec4 d_plane = (b * pc.out_c + o) * pc.out_h;
    uint in_plane = (b * pc.in_c + c) * pc.in_h;
    // acc[kx]: the 4 output channels' gradients of tap (ky, kx).
    vec4 acc[K];
    [[unroll]] for (uint kx = 0u; kx < K; ++kx) {
        acc[kx] = vec4(0.0);
    }
    for (uint oy = oy0; oy < oy1; ++oy) {
        int row = int(in_plane + oy * S + ky - P) * row_texels;
        for (uint xb = 0u; xb < out_texels; ++xb) {
            mat4 d = mat4(uintBitsToFloat(imageLoad(d_pre, int((d_plane.x + oy) * out_texels + xb))),
                          uintBitsToFloat(imageLoad(d_pre, int((d_plane.y + oy) * out_texels + xb))),
                          uintBitsToFloat(imageLoad(d_pre, int((d_plane.z + oy) * out_texels + xb))),
                          uintBitsToFloat(imageLoad(d_pre, int((d_plane.w + oy) * out_texels + xb))));
            // Rows of d: the 4 columns' gradients of one channel; d[q][r].
            int t0 = (int(4u * xb * S) - int(P) - int(OFF)) / 4;
            vec4 win[WT];
            [[unroll]] for (uint j = 0u; j < WT; ++j) {
                int tx = t0 + int(j);
                bool inside = tx >= 0 && tx < row_texels;
                vec4 v = uintBitsToFloat(imageLoad(inp, row + clamp(tx, 0, row_texels - 1)));
                win[j] = inside ? v : vec4(0.0);
            }
            [[unroll]] for (uint r = 0u; r < 4u; ++r) {
                vec4 dr = vec4(d[0][r], d[1][r], d[2][r], d[3][r]);
                [[unroll]] for (uint kx = 0u; kx < K; ++kx) {
                    uint col = OFF + r * S + kx;
                    acc[kx] += dr * win[col / 4u][col % 4u];
                }
            }
        }
    }
    for (uint q = 0u; q < 4u; ++q) {
        if (o0 + q >= pc.out_c) {
            break;
        }
        uint at = b * p_count + ((o0 + q) * pc.in_c + c) * kk + ky * K;
        [[unroll]] for (uint kx = 0u; kx < K; ++kx) {
            partial[at + kx] = acc[kx][q];
        }
    }
}
