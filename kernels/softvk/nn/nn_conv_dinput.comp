#version 460
#extension GL_GOOGLE_include_directive : require
// Conv2d backward, the input's gradient, gathered (no scatter): each input element sums over the
// outputs its taps reach, in the order o, ky, kx:
// d_in[b][c][iy][ix] = Σ w[o][c][ky][kx] · d_pre[b][o][oy][ox] over oy·s + ky − p = iy and
// ox·s + kx − p = ix inside the output; d_pre is dL/d(pre-activation) (`nn_act_backward`).
// One invocation per block of 4 input channels × 4 columns of one row that share a residue
// ix ≡ px (mod s), so they share their taps kx: per tap, 4 weights and 4 gradients feed 16
// products; columns whose output is outside add an exact 0.
// Twin: the d_input loops of `crate::nn::cpu::conv2d_backward`.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer DPre { float d_pre[]; };
layout(std430, set = 0, binding = 2) writeonly buffer DInput { float d_in[]; };

NN_CONV_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint s = pc.stride;
    uint k = pc.kernel;
    uint kk = k * k;
    // Columns ix = px + s (q0 + r), r < 4: q_blocks blocks per residue px.
    uint q_blocks = ((pc.in_w + s - 1u) / s + 3u) / 4u;
    uint c_blocks = (pc.in_c + 3u) / 4u;
    uint qb = id % q_blocks;
    uint t = id / q_blocks;
    uint px = t % s;
    t /= s;
    uint iy = t % pc.in_h;
    t /= pc.in_h;
    uint cb = t % c_blocks;
    uint b = t / c_blocks;
    uint c0 = cb * 4u;
    uint q0 = qb * 4u;
    uvec4 c = min(uvec4(c0, c0 + 1u, c0 + 2u, c0 + 3u), uvec4(pc.in_c - 1u));
    // ky ≡ iy + p (mod s) with 0 ≤ oy = (iy + p − ky) / s < out_h: ky from ky0 to below ky1,
    // step s (the lower bound keeps the residue: (out_h − 1) s ≡ 0).
    uint ny = iy + pc.padding;
    uint span_y = (pc.out_h - 1u) * s;
    uint ky0 = ny > span_y ? ny - span_y : ny % s;
    uint ky1 = min(k, ny + 1u);
    // kx ≡ px + p (mod s); column r's output is ox = (px + p − kx) / s + q0 + r.
    uint nx = px + pc.padding;
    uint kx0 = nx % s;
    int last = int(pc.out_w) - 1;
    vec4 acc0 = vec4(0.0);
    vec4 acc1 = vec4(0.0);
    vec4 acc2 = vec4(0.0);
    vec4 acc3 = vec4(0.0);
    for (uint o = 0u; o < pc.out_c; ++o) {
        uvec4 w_row = pc.param_offset + (o * pc.in_c + c) * kk;
        uint d_plane = (b * pc.out_c + o) * pc.out_h;
        for (uint ky = ky0; ky < ky1; ky += s) {
            uint d_row = (d_plane + (ny - ky) / s) * pc.out_w;
            uint w_at = ky * k;
            for (uint kx = kx0; kx < k; kx += s) {
                ivec4 ox = ivec4((int(nx) - int(kx)) / int(s) + int(q0)) + ivec4(0, 1, 2, 3);
                bvec4 inside = lessThanEqual(uvec4(ox), uvec4(last));
                ivec4 at = clamp(ox, 0, last);
                vec4 raw = vec4(d_pre[d_row + at.x], d_pre[d_row + at.y], d_pre[d_row + at.z],
                                d_pre[d_row + at.w]);
                vec4 d = mix(vec4(0.0), raw, inside);
                acc0 += params[w_row.x + w_at + kx] * d;
                acc1 += params[w_row.y + w_at + kx] * d;
                acc2 += params[w_row.z + w_at + kx] * d;
                acc3 += params[w_row.w + w_at + kx] * d;
            }
        }
    }
    mat4 acc = mat4(acc0, acc1, acc2, acc3);
    for (uint q = 0u; q < 4u; ++q) {
        if (c0 + q >= pc.in_c) {
            break;
        }
        uint in_row = ((b * pc.in_c + c0 + q) * pc.in_h + iy) * pc.in_w;
        for (uint r = 0u; r < 4u; ++r) {
            uint ix = px + s * (q0 + r);
            if (ix < pc.in_w) {
                d_in[in_row + ix] = acc[q][r];
            }
        }
    }
}
