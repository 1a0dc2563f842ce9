#version 460
#extension GL_GOOGLE_include_directive : require
// Surface colours: per (mesh, face, texel), the sum over the mesh's views (in order) of the
// face gradients' texel slots: dL/d(lit texel). One writer each: deterministic.
#include "common.glsl"
#include "view.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Views { View views[]; };
layout(std430, set = 0, binding = 1) readonly buffer FaceGrads { float face_grads[]; };
// 3 floats per (mesh, face, texel).
layout(std430, set = 0, binding = 2) writeonly buffer TexelGrads { float texel_grads[]; };

layout(push_constant) uniform Push {
    uint texels;     // R² per face
    uint face_count;
    uint mesh_count;
    uint view_count;
    uint stride;     // floats per face gradient
    uint pad0;
    uint pad1;
    uint pad2;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint per_mesh = pc.face_count * pc.texels;
    if (id >= per_mesh * pc.mesh_count) {
        return;
    }
    uint mesh = id / per_mesh;
    uint rest = id - mesh * per_mesh;
    uint face = rest / pc.texels;
    uint texel = rest - face * pc.texels;
    vec3 acc = vec3(0.0);
    for (uint v = 0u; v < pc.view_count; ++v) {
        if (views[v].mesh != mesh) {
            continue;
        }
        uint o = (v * pc.face_count + face) * pc.stride + 9u + 3u * texel;
        acc += vec3(face_grads[o], face_grads[o + 1u], face_grads[o + 2u]);
    }
    texel_grads[3u * id] = acc.x;
    texel_grads[3u * id + 1u] = acc.y;
    texel_grads[3u * id + 2u] = acc.z;
}
