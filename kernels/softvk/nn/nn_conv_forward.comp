#version 460
#extension GL_GOOGLE_include_directive : require
// Conv2d forward with its fused activation, NCHW:
// out[b][o][oy][ox] = act(bias[o] + Σ_c Σ_ky Σ_kx w[o][c][ky][kx] · in[b][c][oy·s + ky − p][ox·s + kx − p]),
// summed in that order; taps outside the input (zero padding) add an exact 0.
// One invocation per block of 4 output channels × 4 adjacent columns of one output row: per tap,
// 4 weights and 4 inputs feed 16 products (llvmpipe turns every load into 8 lane loads, so
// loads per product are what it costs).
// Twin: `crate::nn::cpu::conv2d_forward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Input { float inp[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Output { float outp[]; };

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
    uint k = pc.kernel;
    uint kk = k * k;
    uint o0 = ob * 4u;
    uint ox0 = xb * 4u;
    // Past the last channel: read the last one's weights, store nothing.
    uvec4 o = min(uvec4(o0, o0 + 1u, o0 + 2u, o0 + 3u), uvec4(pc.out_c - 1u));
    uvec4 w_row = pc.param_offset + o * (pc.in_c * kk);
    uint bias_at = pc.param_offset + pc.out_c * pc.in_c * kk;
    vec4 acc0 = vec4(params[bias_at + o.x]);
    vec4 acc1 = vec4(params[bias_at + o.y]);
    vec4 acc2 = vec4(params[bias_at + o.z]);
    vec4 acc3 = vec4(params[bias_at + o.w]);
    // The rows inside the input: ky in [ky0, ky1).
    int y0 = int(oy * pc.stride) - int(pc.padding);
    uint ky0 = uint(max(-y0, 0));
    uint ky1 = uint(clamp(int(pc.in_h) - y0, 0, int(k)));
    // Column of tap kx for the 4 outputs: x0 + kx + (0, s, 2s, 3s).
    ivec4 x0 = ivec4(ox0 * pc.stride) + ivec4(0, 1, 2, 3) * int(pc.stride) - int(pc.padding);
    int last = int(pc.in_w) - 1;
    for (uint c = 0u; c < pc.in_c; ++c) {
        uint plane = (b * pc.in_c + c) * pc.in_h;
        for (uint ky = ky0; ky < ky1; ++ky) {
            uint row = (plane + uint(y0 + int(ky))) * pc.in_w;
            uint w_at = c * kk + ky * k;
            for (uint kx = 0u; kx < k; ++kx) {
                ivec4 ix = x0 + int(kx);
                bvec4 inside = lessThanEqual(uvec4(ix), uvec4(last));
                ivec4 at = clamp(ix, 0, last);
                vec4 raw = vec4(inp[row + at.x], inp[row + at.y], inp[row + at.z], inp[row + at.w]);
                vec4 x = mix(vec4(0.0), raw, inside);
                acc0 += params[w_row.x + w_at + kx] * x;
                acc1 += params[w_row.y + w_at + kx] * x;
                acc2 += params[w_row.z + w_at + kx] * x;
                acc3 += params[w_row.w + w_at + kx] * x;
            }
        }
    }
    mat4 acc = mat4(acc0, acc1, acc2, acc3);
    for (uint q = 0u; q < 4u; ++q) {
        if (o0 + q >= pc.out_c) {
            break;
        }
        uint out_row = ((b * pc.out_c + o0 + q) * pc.out_h + oy) * pc.out_w;
        for (uint r = 0u; r < 4u; ++r) {
            if (ox0 + r < pc.out_w) {
                outp[out_row + ox0 + r] = activate(acc[q][r]);
            }
        }
    }
}
