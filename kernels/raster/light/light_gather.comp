#version 460
#extension GL_GOOGLE_include_directive : require
// Adds the lighting's share to each vertex's dL/d(world position): the sum of its (face,
// corner) slots of `light_backward.comp`, in slot order, added to the gradient already there
// (one writer per vertex). Twin: `VertexFaces::gather`, then the sum `GradKernels::finish`
// forms.
#include "common.glsl"
#include "light_io.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 5) readonly buffer Corners { vec4 corners[]; };
// dL/d(world position), xyz per vertex of each mesh: read and added to.
layout(std430, set = 0, binding = 6) buffer DPositions { float d_positions[]; };

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.vertex_count * pc.mesh_count) {
        return;
    }
    uint mesh = id / pc.vertex_count;
    uint v = id - mesh * pc.vertex_count;
    uint slots = pc.vertex_count + 1u;
    uint first = 3u * mesh * pc.face_count;
    vec3 acc = vec3(0.0);
    for (uint k = incident[v]; k < incident[v + 1u]; ++k) {
        acc += corners[first + incident[slots + k]].xyz;
    }
    d_positions[3u * id] += acc.x;
    d_positions[3u * id + 1u] += acc.y;
    d_positions[3u * id + 2u] += acc.z;
}
