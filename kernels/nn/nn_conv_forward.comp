#version 460
#extension GL_GOOGLE_include_directive : require
// Conv2d forward with its fused activation, one invocation per output element (b, o, oy, ox),
// NCHW: out = act(bias[o] + Σ_c Σ_ky Σ_kx w[o][c][ky][kx] · in[b][c][oy·s + ky − p][ox·s + kx − p]),
// summed in that order over the taps inside the input (zero padding contributes nothing).
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
    uint ox = id % pc.out_w;
    uint t = id / pc.out_w;
    uint oy = t % pc.out_h;
    t /= pc.out_h;
    uint o = t % pc.out_c;
    uint b = t / pc.out_c;
    uint k = pc.kernel;
    // The taps that land inside the input: ky in [ky0, ky1), kx in [kx0, kx1).
    int y0 = int(oy * pc.stride) - int(pc.padding);
    int x0 = int(ox * pc.stride) - int(pc.padding);
    uint ky0 = uint(max(-y0, 0));
    uint ky1 = uint(clamp(int(pc.in_h) - y0, 0, int(k)));
    uint kx0 = uint(max(-x0, 0));
    uint kx1 = uint(clamp(int(pc.in_w) - x0, 0, int(k)));
    float s = params[pc.param_offset + pc.out_c * pc.in_c * k * k + o];
    for (uint c = 0u; c < pc.in_c; ++c) {
        uint w_row = pc.param_offset + (o * pc.in_c + c) * k * k;
        uint in_plane = (b * pc.in_c + c) * pc.in_h;
        for (uint ky = ky0; ky < ky1; ++ky) {
            uint w_at = w_row + ky * k;
            uint in_at = (in_plane + uint(y0 + int(ky))) * pc.in_w;
            for (uint kx = kx0; kx < kx1; ++kx) {
                s += params[w_at + kx] * inp[in_at + uint(x0 + int(kx))];
            }
        }
    }
    outp[id] = activate(s);
}
