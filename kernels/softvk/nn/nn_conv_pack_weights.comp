#version 460
#extension GL_GOOGLE_include_directive : require
// A conv layer's weights packed as texels of 4 channels, for `nn_conv_forward4.comp` (by output
// channel: texel ((c K + ky) K + kx) OB + ob holds w[4 ob + q][c][ky][kx], q = 0..3) or, with
// BY_INPUT, for `nn_conv_dinput4.comp` (by input channel: texel ((o K + ky) K + kx) CB + cb
// holds w[o][4 cb + q][ky][kx]); 0 past the last channel. One invocation per texel.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(constant_id = 2) const bool BY_INPUT = false;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Packed { vec4 packed[]; };

NN_CONV_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint kk = pc.kernel * pc.kernel;
    uint blocks = ((BY_INPUT ? pc.in_c : pc.out_c) + 3u) / 4u;
    uint block = id % blocks;
    uint tap = id / blocks;
    // The other channel (c by output channel, o by input channel) and the tap.
    uint other = tap / kk;
    uint within = tap - other * kk;
    vec4 w = vec4(0.0);
    for (uint q = 0u; q < 4u; ++q) {
        uint channel = 4u * block + q;
        if (BY_INPUT && channel < pc.in_c) {
            w[q] = params[pc.param_offset + (other * pc.in_c + channel) * kk + within];
        } else if (!BY_INPUT && channel < pc.out_c) {
            w[q] = params[pc.param_offset + (channel * pc.in_c + other) * kk + within];
        }
    }
    packed[id] = w;
}
