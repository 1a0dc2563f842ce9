// The bindings and push constants the lighting kernels share (`src/raster/light.rs`), and the
// normals they read from the world positions.
#ifndef SOFTVK_LIGHT_IO_GLSL
#define SOFTVK_LIGHT_IO_GLSL

// World positions, mesh after mesh: vertex i's xyz at `position_offset + position_stride i`
// (floats; the scene's `VertexLayout`).
layout(std430, set = 0, binding = 0) readonly buffer Positions { float positions[]; };
// Vertex indices, 3 per face (shared by the batch's meshes).
layout(std430, set = 0, binding = 1) readonly buffer Faces { uint faces[]; };
// Unlit colours: surface, R² texels per face; vertex, one per vertex (white without colours);
// per mesh of the batch, RGB and an unused float.
layout(std430, set = 0, binding = 2) readonly buffer Base { vec4 base[]; };
// Ambient, then (direction, I c) per directional light.
layout(std430, set = 0, binding = 3) readonly buffer Lights { vec4 lights[]; };
// Per vertex, its incident (face, corner) slots 3 f + c in face order (CSR: `VertexFaces`):
// offsets (V + 1), then the slots (3 F).
layout(std430, set = 0, binding = 4) readonly buffer Incident { uint incident[]; };

// Twin of `LightPush` (src/raster/light.rs).
layout(push_constant) uniform Push {
    uint vertex_count;
    uint face_count;
    uint mesh_count;
    uint texels;       // surface: R² texels per face
    uint directionals; // directional lights
    uint vertex_mode;  // 1: vertex colours and normals; 0: surface texels and face normals
    uint phase;        // light_backward.comp: 0 the normals' gradients, 1 (vertex) the corners'
    uint position_offset;
    uint position_stride;
} pc;

#include "lighting.glsl"

vec3 world_position(uint mesh, uint v) {
    uint i = pc.position_offset + pc.position_stride * (mesh * pc.vertex_count + v);
    return vec3(positions[i], positions[i + 1u], positions[i + 2u]);
}

vec3 raw_normal(uint mesh, uint f) {
    return face_normal_raw(world_position(mesh, faces[3u * f]),
                           world_position(mesh, faces[3u * f + 1u]),
                           world_position(mesh, faces[3u * f + 2u]));
}

// `vertex_normal_sums`: the raw normals of the vertex's incident faces, in face order.
vec3 vertex_normal_sum(uint mesh, uint v) {
    vec3 sum = vec3(0.0);
    for (uint k = incident[v]; k < incident[v + 1u]; ++k) {
        sum += raw_normal(mesh, incident[pc.vertex_count + 1u + k] / 3u);
    }
    return sum;
}

#endif
