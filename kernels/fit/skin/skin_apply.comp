#version 460
#extension GL_GOOGLE_include_directive : require
// Linear blend skinning: p' = Σ_i w_i (M_{k_i} p + b_{k_i}) over the vertex's four bones, one
// invocation per vertex, packed xyz. Twin: `Rig::skin` (f64).
#include "common.glsl"
#include "skin.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Bones { Bone bones[]; };
layout(std430, set = 0, binding = 1) readonly buffer Rest { float rest[]; };
layout(std430, set = 0, binding = 2) readonly buffer Skins { Skin skins[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Posed { float posed[]; };

void main() {
    uint v = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (v >= pc.vertex_count) {
        return;
    }
    vec3 p = vec3(rest[3u * v], rest[3u * v + 1u], rest[3u * v + 2u]);
    Skin s = skins[v];
    vec3 q = vec3(0.0);
    for (uint i = 0u; i < 4u; i++) {
        q += s.weights[i] * bone_apply(bones[s.bones[i]], p);
    }
    posed[3u * v] = q.x;
    posed[3u * v + 1u] = q.y;
    posed[3u * v + 2u] = q.z;
}
