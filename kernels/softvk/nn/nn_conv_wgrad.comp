#version 460
#extension GL_GOOGLE_include_directive : require
// Conv2d backward, the parameters' gradient per sample, partial[b · P + j] (P = O·C·K² + O):
// the sum over the sample's outputs, in the order oy, ox, of
// d_pre[b][o][oy][ox] · in[b][c][oy·s + ky − p][ox·s + kx − p] for weight w[o][c][ky][kx] (the
// outputs whose tap lands inside the input), of d_pre[b][o][oy][ox] for bias o.
// `nn_sum_rows` then sums over b in order.
// Invocations: per sample, first one per block of 4 output × 4 input channels and tap (ky, kx)
// (per output, 4 gradients and 4 inputs feed 16 products), then one per bias.
// Twin: the d_params loops of `crate::nn::cpu::conv2d_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Input { float inp[]; };
layout(std430, set = 0, binding = 1) readonly buffer DPre { float d_pre[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Partial { float partial[]; };

NN_CONV_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint k = pc.kernel;
    uint kk = k * k;
    uint o_blocks = (pc.out_c + 3u) / 4u;
    uint c_blocks = (pc.in_c + 3u) / 4u;
    uint blocks = o_blocks * c_blocks * kk;
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
            acc += d_pre[at + i];
        }
        partial[b * p_count + weights + o] = acc;
        return;
    }
    uint kx = id % k;
    uint t = id / k;
    uint ky = t % k;
    t /= k;
    uint cb = t % c_blocks;
    t /= c_blocks;
    uint ob = t % o_blocks;
    uint b = t / o_blocks;
    uint o0 = ob * 4u;
    uint c0 = cb * 4u;
    uvec4 o = min(uvec4(o0, o0 + 1u, o0 + 2u, o0 + 3u), uvec4(pc.out_c - 1u));
    uvec4 c = min(uvec4(c0, c0 + 1u, c0 + 2u, c0 + 3u), uvec4(pc.in_c - 1u));
    uint s = pc.stride;
    // The outputs whose tap (ky, kx) lands inside the input: oy in [oy0, oy1), ox likewise.
    // iy = oy·s + ky − p ≥ 0 ⇔ oy ≥ ceil((p − ky) / s); iy < in_h ⇔ oy·s < in_h + p − ky.
    uint oy0 = pc.padding > ky ? (pc.padding - ky + s - 1u) / s : 0u;
    uint ox0 = pc.padding > kx ? (pc.padding - kx + s - 1u) / s : 0u;
    int hy = int(pc.in_h + pc.padding) - int(ky);
    int hx = int(pc.in_w + pc.padding) - int(kx);
    uint oy1 = hy > 0 ? min(pc.out_h, (uint(hy) + s - 1u) / s) : 0u;
    uint ox1 = hx > 0 ? min(pc.out_w, (uint(hx) + s - 1u) / s) : 0u;
    uvec4 d_plane = (b * pc.out_c + o) * plane_out;
    uvec4 in_plane = (b * pc.in_c + c) * (pc.in_h * pc.in_w);
    vec4 acc0 = vec4(0.0);
    vec4 acc1 = vec4(0.0);
    vec4 acc2 = vec4(0.0);
    vec4 acc3 = vec4(0.0);
    for (uint oy = oy0; oy < oy1; ++oy) {
        uint d_row = oy * pc.out_w;
        // Wrapping uint arithmetic: the sum is the in-range column once ox·s is added.
        uint in_row = (oy * s + ky - pc.padding) * pc.in_w + kx - pc.padding;
        for (uint ox = ox0; ox < ox1; ++ox) {
            uint d_at = d_row + ox;
            uint in_at = in_row + ox * s;
            vec4 x = vec4(inp[in_plane.x + in_at], inp[in_plane.y + in_at], inp[in_plane.z + in_at],
                          inp[in_plane.w + in_at]);
            acc0 += d_pre[d_plane.x + d_at] * x;
            acc1 += d_pre[d_plane.y + d_at] * x;
            acc2 += d_pre[d_plane.z + d_at] * x;
            acc3 += d_pre[d_plane.w + d_at] * x;
        }
    }
    mat4 acc = mat4(acc0, acc1, acc2, acc3);
    for (uint q = 0u; q < 4u; ++q) {
        if (o0 + q >= pc.out_c) {
            break;
        }
        for (uint r = 0u; r < 4u; ++r) {
            if (c0 + r < pc.in_c) {
                partial[b * p_count + ((o0 + q) * pc.in_c + c0 + r) * kk + ky * k + kx] = acc[q][r];
            }
        }
    }
}
