#version 460
#extension GL_GOOGLE_include_directive : require
// dL/d r_c for object b and axis k: the vertices' shares of dL/dc (`recon_decode_backward.comp`)
// summed in vertex order, times dc/d r_c = (1 − c²) · 0.1 for
// c = tanh(0.1 r_c). One invocation per (b, k). Twin: `crate::recon::decode::cpu::backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) readonly buffer Partials { float partials[]; };
layout(std430, set = 0, binding = 2) buffer DOutputs { float d_outputs[]; };

layout(push_constant) uniform Push {
    uint vertex_count;
    uint objects;
    uint copies;
    uint stride;
} pc;

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= 3u * pc.objects) {
        return;
    }
    uint b = gid / 3u;
    uint k = gid - 3u * b;
    float sum = 0.0;
    for (uint i = 0u; i < pc.vertex_count; ++i) {
        sum += partials[3u * (b * pc.vertex_count + i) + k];
    }
    uint slot = b * pc.stride + 3u * pc.vertex_count + k;
    float c = fm_tanh(0.1 * outputs[slot]);
    d_outputs[slot] = sum * ((1.0 - c * c) * 0.1);
}
