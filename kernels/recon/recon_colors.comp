#version 460
#extension GL_GOOGLE_include_directive : require
// The decoder's colour head: per object b and vertex i, the vertex colour
//   c = sigmoid(r_col[3 i + k]),  r_col the object's outputs after the mesh head's 3 V + 3,
// written (RGB, then an unused float: the renderer's colour layout) to every copy of the
// object (mesh b · copies + k). Twin: `crate::recon::decode::cpu::colors`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Colors { vec4 colors[]; };

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
    vec3 c;
    for (uint k = 0u; k < 3u; ++k) {
        c[k] = 1.0 / (1.0 + exp(-outputs[r0 + k]));
    }
    for (uint k = 0u; k < pc.copies; ++k) {
        colors[(b * pc.copies + k) * pc.vertex_count + i] = vec4(c, 0.0);
    }
}
