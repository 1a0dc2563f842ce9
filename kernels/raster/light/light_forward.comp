#version 460
#extension GL_GOOGLE_include_directive : require
// Lights the colours of every mesh of a batch from its world positions, on the GPU: surface
// mode, one invocation per face (its texels times L(face normal)); vertex mode, one per vertex
// (its colour times L(normalized sum of its incident faces' raw normals, in face order)).
// Twin: `Lighting::apply_surface_of` / `apply_vertex_of`.
#include "common.glsl"
#include "light_io.glsl"

layout(local_size_x = 64) in;

// Lit colours, RGB and an unused float (the scene's colour layout).
layout(std430, set = 0, binding = 5) writeonly buffer Lit { vec4 lit[]; };

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (pc.vertex_mode != 0u) {
        if (id >= pc.vertex_count * pc.mesh_count) {
            return;
        }
        uint mesh = id / pc.vertex_count;
        uint v = id - mesh * pc.vertex_count;
        vec3 n = normalize_eps(vertex_normal_sum(mesh, v));
        lit[id] = vec4(base[id].rgb * light_factor(n, pc.directionals), 0.0);
        return;
    }
    if (id >= pc.face_count * pc.mesh_count) {
        return;
    }
    uint mesh = id / pc.face_count;
    uint f = id - mesh * pc.face_count;
    vec3 l = light_factor(normalize_eps(raw_normal(mesh, f)), pc.directionals);
    for (uint t = id * pc.texels; t < (id + 1u) * pc.texels; ++t) {
        lit[t] = vec4(base[t].rgb * l, 0.0);
    }
}
