#version 460
#extension GL_GOOGLE_include_directive : require
// Conv2d backward, the parameters' gradient per sample: one invocation per (b, parameter j)
// writes partial[b · P + j] (P = O·C·K² + O), the sum over the sample's outputs, in the order
// oy, ox, of d_pre[b][o][oy][ox] · in[b][c][oy·s + ky − p][ox·s + kx − p] (weight
// w[o][c][ky][kx]) or of d_pre[b][o][oy][ox] (bias o). `nn_sum_rows` then sums over b in order.
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
    uint weights = pc.out_c * pc.in_c * k * k;
    uint p_count = weights + pc.out_c;
    uint b = id / p_count;
    uint j = id % p_count;
    float acc = 0.0;
    if (j >= weights) {
        uint at = (b * pc.out_c + (j - weights)) * pc.out_h * pc.out_w;
        for (uint i = 0u; i < pc.out_h * pc.out_w; ++i) {
            acc += d_pre[at + i];
        }
    } else {
        uint kx = j % k;
        uint ky = (j / k) % k;
        uint c = (j / (k * k)) % pc.in_c;
        uint o = j / (k * k * pc.in_c);
        uint s = pc.stride;
        // The outputs whose tap (ky, kx) lands inside the input: oy in [oy0, oy1), ox likewise.
        // iy = oy·s + ky − p ≥ 0 ⇔ oy ≥ ceil((p − ky) / s); iy < in_h ⇔ oy·s < in_h + p − ky.
        uint oy0 = pc.padding > ky ? (pc.padding - ky + s - 1u) / s : 0u;
        uint ox0 = pc.padding > kx ? (pc.padding - kx + s - 1u) / s : 0u;
        int hy = int(pc.in_h + pc.padding) - int(ky);
        int hx = int(pc.in_w + pc.padding) - int(kx);
        uint oy1 = hy > 0 ? min(pc.out_h, (uint(hy) + s - 1u) / s) : 0u;
        uint ox1 = hx > 0 ? min(pc.out_w, (uint(hx) + s - 1u) / s) : 0u;
        uint d_plane = (b * pc.out_c + o) * pc.out_h;
        uint in_plane = (b * pc.in_c + c) * pc.in_h;
        for (uint oy = oy0; oy < oy1; ++oy) {
            uint d_at = (d_plane + oy) * pc.out_w;
            uint in_at = (in_plane + oy * s + ky - pc.padding) * pc.in_w + kx - pc.padding;
            for (uint ox = ox0; ox < ox1; ++ox) {
                acc += d_pre[d_at + ox] * inp[in_at + ox * s];
            }
        }
    }
    partial[id] = acc;
}
