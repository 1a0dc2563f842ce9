#version 460
#extension GL_GOOGLE_include_directive : require
// The segmented sum of the backward's partials, one window of one chunk at a time: each
// (view, face) item of a view group adds the partials of its units that lie in
// [window_begin, window_end) to its running gradient (9 screen floats, or 18 with vertex
// colours), in unit order. An item's units are contiguous: tiled, its (face, tile) entries at
// the scanned offset binning gave it; brute force, its `parts` bands. Windows and chunks are
// recorded in unit order, so the running sums add every item's partials in the same order
// whatever the chunking: results do not depend on it, bit for bit. One writer per item, fixed
// order: deterministic. Twin: the per-face sum of `reference_grad::backward_view`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
// vec4 records: screen corners, then colour slots (see raster_grad.glsl).
layout(std430, set = 0, binding = 1) readonly buffer Partials { vec4 partials[]; };
layout(std430, set = 0, binding = 2) buffer FaceGrads { float face_grads[]; };

layout(push_constant) uniform Push {
    uint item_count;   // items of the view group
    uint first_item;   // the group's first item in face_grads
    uint stride;       // floats per partial
    uint width;        // floats per face gradient: 9, or 18 with vertex colours
    uint unit_total;   // units of the group
    uint chunk_begin;  // the first unit of the chunk in `partials`
    uint window_begin; // units added by this dispatch: [window_begin, window_end)
    uint window_end;
    uint parts;        // brute force: units per item (bands); 0: tiled (from `offsets`)
    uint pad0;
    uint pad1;
    uint pad2;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.item_count) {
        return;
    }
    uint begin;
    uint end;
    if (pc.parts != 0u) {
        begin = id * pc.parts;
        end = begin + pc.parts;
    } else {
        // offsets[item_count] is the group's total (the binning writes it): a guarded binning,
        // whose count the host never reads, reserved units up to its capacity (`unit_total`)
        // but only [0, total) were written. The clamp keeps every read inside the partials.
        begin = min(offsets[id], pc.unit_total);
        end = min(offsets[id + 1u], pc.unit_total);
    }
    begin = max(begin, pc.window_begin);
    end = min(end, pc.window_end);
    if (begin >= end) {
        return;
    }
    bool colors = pc.width > 9u;
    uint o = (pc.first_item + id) * pc.width;
    vec3 s0 = vec3(face_grads[o], face_grads[o + 1u], face_grads[o + 2u]);
    vec3 s1 = vec3(face_grads[o + 3u], face_grads[o + 4u], face_grads[o + 5u]);
    vec3 s2 = vec3(face_grads[o + 6u], face_grads[o + 7u], face_grads[o + 8u]);
    vec3 c0 = vec3(0.0);
    vec3 c1 = vec3(0.0);
    vec3 c2 = vec3(0.0);
    if (colors) {
        c0 = vec3(face_grads[o + 9u], face_grads[o + 10u], face_grads[o + 11u]);
        c1 = vec3(face_grads[o + 12u], face_grads[o + 13u], face_grads[o + 14u]);
        c2 = vec3(face_grads[o + 15u], face_grads[o + 16u], face_grads[o + 17u]);
    }
    // One loop (no inner one): its iterations are what the host bounds.
    for (uint u = begin; u < end; ++u) {
        uint p = (u - pc.chunk_begin) * (pc.stride / 4u);
        s0 += partials[p].xyz;
        s1 += partials[p + 1u].xyz;
        s2 += partials[p + 2u].xyz;
        if (colors) {
            c0 += partials[p + 3u].xyz;
            c1 += partials[p + 4u].xyz;
            c2 += partials[p + 5u].xyz;
        }
    }
    face_grads[o] = s0.x;
    face_grads[o + 1u] = s0.y;
    face_grads[o + 2u] = s0.z;
    face_grads[o + 3u] = s1.x;
    face_grads[o + 4u] = s1.y;
    face_grads[o + 5u] = s1.z;
    face_grads[o + 6u] = s2.x;
    face_grads[o + 7u] = s2.y;
    face_grads[o + 8u] = s2.z;
    if (colors) {
        face_grads[o + 9u] = c0.x;
        face_grads[o + 10u] = c0.y;
        face_grads[o + 11u] = c0.z;
        face_grads[o + 12u] = c1.x;
        face_grads[o + 13u] = c1.y;
        face_grads[o + 14u] = c1.z;
        face_grads[o + 15u] = c2.x;
        face_grads[o + 16u] = c2.y;
        face_grads[o + 17u] = c2.z;
    }
}
