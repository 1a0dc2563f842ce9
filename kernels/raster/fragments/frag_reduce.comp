#version 460
#extension GL_GOOGLE_include_directive : require
// PyTorch3D's rasterizer backward, step 2: one invocation per binning item (view, face slot):
// the face's gradient is the sum of its entries' partials (`frag_backward.comp`), in slot
// order (its tiles row by row). A face that no pixel kept, or that was not binned, gets 0.
// One writer per face, a fixed order: deterministic. Loop iterations: one per entry of the
// face (at most the tiles of a view). Twin: `reference::rasterize_grad` (its sum over pixels).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Meshes { uvec2 meshes[]; };
layout(std430, set = 0, binding = 1) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 2) readonly buffer Partials { float partials[]; };
// [faces, 3, 3]: every face of a mesh is written; faces of no mesh are left as they are.
layout(std430, set = 0, binding = 3) writeonly buffer GradFaceVerts { float grad_face_verts[]; };

#define FRAGMENTS_PUSH_ONLY
#include "fragments.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.views * pc.items_per_view) {
        return;
    }
    uint view = id / pc.items_per_view;
    uint j = id - view * pc.items_per_view;
    uvec2 mesh = meshes[view];
    if (j >= mesh.y) {
        return;
    }
    precise vec3 g0 = vec3(0.0);
    precise vec3 g1 = vec3(0.0);
    precise vec3 g2 = vec3(0.0);
    uint end = min(offsets[id + 1u], pc.entries);
    for (uint s = offsets[id]; s < end; ++s) {
        uint p = 9u * s;
        g0 += vec3(partials[p], partials[p + 1u], partials[p + 2u]);
        g1 += vec3(partials[p + 3u], partials[p + 4u], partials[p + 5u]);
        g2 += vec3(partials[p + 6u], partials[p + 7u], partials[p + 8u]);
    }
    uint o = 9u * (mesh.x + j);
    grad_face_verts[o] = g0.x;
    grad_face_verts[o + 1u] = g0.y;
    grad_face_verts[o + 2u] = g0.z;
    grad_face_verts[o + 3u] = g1.x;
    grad_face_verts[o + 4u] = g1.y;
    grad_face_verts[o + 5u] = g1.z;
    grad_face_verts[o + 6u] = g2.x;
    grad_face_verts[o + 7u] = g2.y;
    grad_face_verts[o + 8u] = g2.z;
}
