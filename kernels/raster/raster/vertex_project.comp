#version 460
#extension GL_GOOGLE_include_directive : require
// Every vertex of the view's mesh on screen, one invocation per (view, vertex): `to_screen`
// (a perspective view's is four correctly rounded divisions) taken once per vertex, where the
// face setup took it for each corner of each face (a vertex belongs to about six). The face
// setup reads the corners from here; the same function on the same vertex, so the same bits.
// Twin: `reference::project_faces`' projection of each vertex.
#include "common.glsl"

layout(local_size_x = 64) in;

#include "view.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Positions { float positions[]; };
layout(std430, set = 0, binding = 1) readonly buffer Views { View views[]; };
// (x_s, y_s, z, 0) of vertex v in view w at w · vertex_count + v.
layout(std430, set = 0, binding = 2) writeonly buffer Screen { vec4 screen[]; };

layout(push_constant) uniform Push {
    uint vertex_count;     // vertices per mesh of the batch
    uint view_count;
    uint position_offset;  // floats before vertex 0's x (`VertexLayout`)
    uint position_stride;  // floats from one vertex's x to the next's
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.vertex_count * pc.view_count) {
        return;
    }
    uint view_index = id / pc.vertex_count;
    uint vertex = id - view_index * pc.vertex_count;
    View view = views[view_index];
    uint at = pc.position_offset + pc.position_stride * (view.mesh * pc.vertex_count + vertex);
    vec3 q = vec3(positions[at], positions[at + 1u], positions[at + 2u]);
    screen[id] = vec4(to_screen(view, q), 0.0);
}
