#version 460
#extension GL_GOOGLE_include_directive : require
// Per vertex of each mesh of the batch: the sum over its views (in order) and its incident
// (face, corner) slots (in face order, CSR) of the corners' world-position gradients and, with
// vertex colours, of their lit-colour gradients. One writer per vertex: deterministic.
// Twin: `reference_grad::VertexFaces::gather`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint vertex_offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Slots { uint vertex_slots[]; };
// Each mesh's views, ascending (CSR): `mesh_views[m] .. mesh_views[m + 1]` index the list
// that starts at `mesh_views[mesh_count + 1]`. A mesh visits only its own views: a batch of B
// meshes seen once each costs B times less than scanning every view for its mesh.
layout(std430, set = 0, binding = 2) readonly buffer Views { uint mesh_views[]; };
layout(std430, set = 0, binding = 3) readonly buffer CornerWorld { float corner_world[]; };
layout(std430, set = 0, binding = 4) readonly buffer FaceGrads { float face_grads[]; };
// 3 floats per (mesh, vertex): dL/d(world position) through the projections.
layout(std430, set = 0, binding = 5) writeonly buffer PositionGrads { float position_grads[]; };
// 3 floats per (mesh, vertex): dL/d(lit vertex colour) (vertex colour mode only).
layout(std430, set = 0, binding = 6) writeonly buffer ColorGrads { float color_grads[]; };

layout(push_constant) uniform Push {
    uint vertex_count;
    uint mesh_count;
    uint face_count;
    uint view_count;
    uint stride;        // floats per face gradient
    uint vertex_colors; // 1: gather colour gradients too
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.vertex_count * pc.mesh_count) {
        return;
    }
    uint mesh = id / pc.vertex_count;
    uint vertex = id - mesh * pc.vertex_count;
    uint begin = vertex_offsets[vertex];
    uint end = vertex_offsets[vertex + 1u];
    vec3 pos = vec3(0.0);
    vec3 col = vec3(0.0);
    uint list = pc.mesh_count + 1u;
    uint first = mesh_views[mesh];
    uint last = mesh_views[mesh + 1u];
    for (uint k = first; k < last; ++k) {
        uint v = mesh_views[list + k];
        for (uint s = begin; s < end; ++s) {
            uint slot = vertex_slots[s]; // 3 face + corner
            uint face = slot / 3u;
            uint corner = slot - 3u * face;
            uint item = v * pc.face_count + face;
            uint o = item * 9u + 3u * corner;
            pos += vec3(corner_world[o], corner_world[o + 1u], corner_world[o + 2u]);
            if (pc.vertex_colors != 0u) {
                uint c = item * pc.stride + 9u + 3u * corner;
                col += vec3(face_grads[c], face_grads[c + 1u], face_grads[c + 2u]);
            }
        }
    }
    position_grads[3u * id] = pos.x;
    position_grads[3u * id + 1u] = pos.y;
    position_grads[3u * id + 2u] = pos.z;
    if (pc.vertex_colors != 0u) {
        color_grads[3u * id] = col.x;
        color_grads[3u * id + 1u] = col.y;
        color_grads[3u * id + 2u] = col.z;
    }
}
