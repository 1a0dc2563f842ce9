#version 460
#extension GL_GOOGLE_include_directive : require
// Conv2d backward, the input's gradient, gathered: one invocation per input element
// (b, c, iy, ix) sums over the outputs its taps reach, in the order o, ky, kx:
// d_in[b][c][iy][ix] = Σ w[o][c][ky][kx] · d_pre[b][o][oy][ox] over oy·s + ky − p = iy and
// ox·s + kx − p = ix inside the output. d_pre is dL/d(pre-activation) (`nn_act_backward`).
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
    uint ix = id % pc.in_w;
    uint t = id / pc.in_w;
    uint iy = t % pc.in_h;
    t /= pc.in_h;
    uint c = t % pc.in_c;
    uint b = t / pc.in_c;
    uint k = pc.kernel;
    uint s = pc.stride;
    // ky ≡ iy + p (mod s) with 0 ≤ oy = (iy + p − ky) / s < out_h: ky from ky0 to below ky1,
    // step s (the lower bound keeps the residue: (out_h − 1) s ≡ 0).
    uint ny = iy + pc.padding;
    uint nx = ix + pc.padding;
    uint span_y = (pc.out_h - 1u) * s;
    uint span_x = (pc.out_w - 1u) * s;
    uint ky0 = ny > span_y ? ny - span_y : ny % s;
    uint kx0 = nx > span_x ? nx - span_x : nx % s;
    uint ky1 = min(k, ny + 1u);
    uint kx1 = min(k, nx + 1u);
    float acc = 0.0;
    for (uint o = 0u; o < pc.out_c; ++o) {
        uint w_row = pc.param_offset + (o * pc.in_c + c) * k * k;
        uint d_plane = (b * pc.out_c + o) * pc.out_h;
        for (uint ky = ky0; ky < ky1; ky += s) {
            uint d_at = (d_plane + (ny - ky) / s) * pc.out_w;
            for (uint kx = kx0; kx < kx1; kx += s) {
                acc += params[w_row + ky * k + kx] * d_pre[d_at + (nx - kx) / s];
            }
        }
    }
    d_in[id] = acc;
}
