#version 460
#extension GL_GOOGLE_include_directive : require
// The backward of `recon_colors.comp`, per object b and vertex i: the copies' colour
// gradients (3 floats per vertex, mesh after mesh: the renderer's backward's layout) summed
// in copy order, times the sigmoid's derivative s (1 − s), into the colour head's slots of
// dL/d(outputs). Twin: `crate::recon::decode::cpu::colors_backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) readonly buffer DColors { float d_colors[]; };
layout(std430, set = 0, binding = 2) writeonly buffer DOutputs { float d_outputs[]; };

layout(push_constant) uniform Push {
    uint vertex_count;
    uint objects;
    uint copies;
    uint stride;
} pc;

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.vertex_count * pc.objects) {
        return;
    }
    uint b = gid / pc.vertex_count;
    uint i = gid - b * pc.vertex_count;
    uint r0 = b * pc.stride + 3u * pc.vertex_count + 3u + 3u * i;
    for (uint k = 0u; k < 3u; ++k) {
        float g = 0.0;
        for (uint j = 0u; j < pc.copies; ++j) {
            g += d_colors[3u * ((b * pc.copies + j) * pc.vertex_count + i) + k];
        }
        float s = 1.0 / (1.0 + exp(-outputs[r0 + k]));
        d_outputs[r0 + k] = g * (s * (1.0 - s));
    }
}
