#version 460
#extension GL_GOOGLE_include_directive : require
// PyTorch3D's rasterizer, step 1: one invocation per binning item, (view n, face slot j) with
// n the mesh and j < the largest mesh's face count. Item (n, j) is face `first_n + j` of the
// packed faces when j < count_n. It is binned unless PyTorch3D skips the face at every pixel:
// zero area (|area| <= 1e-8), culled (area < 0 with cull_backfaces), a vertex nearer than 1e-8
// (`z_min < kEpsilon`), or a coordinate that is not finite (then PyTorch3D's arithmetic is NaN
// at every pixel; here the face is not drawn). Its box is the face's, grown by √blur_radius, in
// the binning's pixel-centre coordinates: PyTorch3D's x (+X left) is the binning's −x, y is y
// (`binning.glsl`; binning adds a pixel on each side against rounding, and the fine pass tests
// PyTorch3D's exact box per pixel). Twin: `reference::face_skipped`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer FaceVerts { float face_verts[]; };
// Per mesh: (first packed face, face count).
layout(std430, set = 0, binding = 1) readonly buffer Meshes { uvec2 meshes[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Items { float items[]; };

#include "fragments.glsl"

bool finite3(vec3 v) {
    return !any(isinf(v)) && !any(isnan(v));
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.views * pc.items_per_view) {
        return;
    }
    uint view = id / pc.items_per_view;
    uint j = id - view * pc.items_per_view;
    uvec2 mesh = meshes[view];
    uint o = id * ITEM_WORDS;
    bool binned = false;
    vec4 box = vec4(0.0);
    if (j < mesh.y) {
        vec3 q0;
        vec3 q1;
        vec3 q2;
        load_face_verts(mesh.x + j, q0, q1, q2);
        float area = face_area(q0.xy, q1.xy, q2.xy);
        float z_min = min(q0.z, min(q1.z, q2.z));
        bool culled = (pc.flags & FRAG_CULL) != 0u && area < 0.0;
        bool flat_face = area <= P3D_EPS && area >= -P3D_EPS;
        binned = finite3(q0) && finite3(q1) && finite3(q2) && !culled && !flat_face
              && !(z_min < P3D_EPS);
        if (binned) {
            precise float x0 = min(q0.x, min(q1.x, q2.x)) - pc.grow;
            precise float x1 = max(q0.x, max(q1.x, q2.x)) + pc.grow;
            precise float y0 = min(q0.y, min(q1.y, q2.y)) - pc.grow;
            precise float y1 = max(q0.y, max(q1.y, q2.y)) + pc.grow;
            box = vec4(-x1, y0, -x0, y1);
        }
    }
    items[o] = box.x;
    items[o + 1u] = box.y;
    items[o + 2u] = box.z;
    items[o + 3u] = box.w;
    items[o + 4u] = uintBitsToFloat(binned ? ITEM_BINNED : 0u);
    items[o + 5u] = 0.0;
    items[o + 6u] = 0.0;
    items[o + 7u] = 0.0;
}
