#version 460
#extension GL_GOOGLE_include_directive : require
// A conv layer's weights packed for `nn_conv_forward4.comp`: texel ((c K + ky) K + kx) OB + ob
// holds w[4 ob + q][c][ky][kx] for q = 0..3 (0 past the last output channel), OB = the output
// channels in blocks of 4. One invocation per texel.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Packed { vec4 packed[]; };

NN_CONV_PUSH

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.total) {
        return;
    }
    uint o_blocks = (pc.out_c + 3u) / 4u;
    uint ob = id % o_blocks;
    uint tap = id / o_blocks;
    uint kk = pc.kernel * pc.kernel;
    uint c = tap / kk;
    uint within = tap - c * kk;
    vec4 w = vec4(0.0);
    for (uint q = 0u; q < 4u; ++q) {
        uint o = 4u * ob + q;
        if (o < pc.out_c) {
            w[q] = params[pc.param_offset + (o * pc.in_c + c) * kk + within];
        }
    }
    packed[id] = w;
}
