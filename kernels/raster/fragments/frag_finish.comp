#version 460
#extension GL_GOOGLE_include_directive : require
// PyTorch3D's rasterizer, step 4: the outputs from the lists `frag_forward.comp` left, one
// invocation per pixel, over its list's filled slots (the host filled every output with -1
// first; an empty slot's pair of words is all ones, its int64 -1, already). A filled slot holds
// (face, the depth's bits); the face's barycentrics and distance at the pixel are computed again
// by the code the selection ran, so they are the values it saw, bit for bit, and the pair of
// words becomes the int64 face index. (Per slot rather than per pixel, the empty slots' writes
// cost as much as the rest on llvmpipe, where a branch does not skip work.) Loop iterations: at
// most K. Twin: `reference::rasterize`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer FaceVerts { float face_verts[]; };
// [views, H, W, K] pairs of words: in, (face, z bits); out, the int64 face index.
layout(std430, set = 0, binding = 1) buffer Lists { uvec2 lists[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Zbuf { float zbuf[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Dists { float dists[]; };
// [views, H, W, K, 3].
layout(std430, set = 0, binding = 4) writeonly buffer Bary { float bary[]; };

#include "fragments.glsl"

void main() {
    uint pixel = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (pixel >= pc.views * pixels) {
        return;
    }
    uint in_view = pixel - (pixel / pixels) * pixels;
    uint row = in_view / pc.width;
    uint col = in_view - row * pc.width;
    vec2 p = frag_pixel(row, col);
    uint base = pixel * pc.k;
    for (uint i = 0u; i < pc.k; ++i) {
        uint slot = base + i;
        uvec2 entry = lists[slot];
        int face = int(entry.x);
        if (face < 0) {
            break;
        }
        float z = uintBitsToFloat(entry.y);
        vec3 q0;
        vec3 q1;
        vec3 q2;
        load_face_verts(uint(face), q0, q1, q2);
        vec3 w0;
        vec3 w;
        vec3 w_clip;
        frag_barycentrics(p, q0, q1, q2, w0, w, w_clip);
        vec3 ed = edge_dists(p, q0.xy, q1.xy, q2.xy);
        float dist = min(min(ed.x, ed.y), ed.z);
        bool inside = w.x > 0.0 && w.y > 0.0 && w.z > 0.0;
        lists[slot].y = 0u;
        zbuf[slot] = z;
        dists[slot] = inside ? -dist : dist;
        bary[3u * slot] = w_clip.x;
        bary[3u * slot + 1u] = w_clip.y;
        bary[3u * slot + 2u] = w_clip.z;
    }
}
