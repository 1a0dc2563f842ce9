#version 460
#extension GL_GOOGLE_include_directive : require
// Surface colours: the texel share of the backward's partials, one window of one chunk and one
// range of a view group's views at a time. Invocation (face, texel) adds, view after view, the
// texel's slots of the face's units in [window_begin, window_end) to the running dL/d(lit
// texel) of the view's mesh. Units are item-major (view-major), and windows, chunks, view ranges
// and groups are recorded in unit order, so every texel gradient adds its partials in unit
// order whatever the chunking: results do not depend on it, bit for bit. One writer per
// (mesh, face, texel), fixed order: deterministic. Twin: the per-texel sums of
// `reference_grad::backward_view` over the mesh's views.
#include "common.glsl"
#include "view.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Views { View views[]; };
layout(std430, set = 0, binding = 1) readonly buffer Offsets { uint offsets[]; };
// vec4 records: screen corners, then texel slots (see raster_grad.glsl).
layout(std430, set = 0, binding = 2) readonly buffer Partials { vec4 partials[]; };
// 3 floats per (mesh, face, texel), accumulated.
layout(std430, set = 0, binding = 3) buffer TexelGrads { float texel_grads[]; };

layout(push_constant) uniform Push {
    uint face_count;
    uint texels;       // R² per face
    uint stride;       // floats per partial
    uint unit_total;   // units of the view group
    uint chunk_begin;  // the first unit of the chunk in `partials`
    uint window_begin; // units added by this dispatch: [window_begin, window_end)
    uint window_end;
    uint parts;        // brute force: units per item (bands); 0: tiled (from `offsets`)
    uint first_view;   // the group's first view
    uint group_views;  // views of the group
    uint view_begin;   // views (of the group) added by this dispatch
    uint view_end;
    uint masked;       // 1: a partial's slots are valid where its mask says (TEXEL_MASKS)
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.face_count * pc.texels) {
        return;
    }
    uint face = id / pc.texels;
    uint texel = id - face * pc.texels;
    for (uint v = pc.view_begin; v < pc.view_end; ++v) {
        uint item = v * pc.face_count + face;
        uint begin;
        uint end;
        if (pc.parts != 0u) {
            begin = item * pc.parts;
            end = begin + pc.parts;
        } else {
            // offsets[item_count] is the group's total; see grad_reduce.comp.
            begin = min(offsets[item], pc.unit_total);
            end = min(offsets[item + 1u], pc.unit_total);
        }
        begin = max(begin, pc.window_begin);
        end = min(end, pc.window_end);
        if (begin >= end) {
            continue;
        }
        uint mesh = views[pc.first_view + v].mesh;
        uint o = 3u * ((mesh * pc.face_count + face) * pc.texels + texel);
        vec3 acc = vec3(texel_grads[o], texel_grads[o + 1u], texel_grads[o + 2u]);
        for (uint u = begin; u < end; ++u) {
            // Past the three screen corners, the texel slots; with masks, only those written
            // (the mask is the first corner's fourth float; see raster_grad.glsl).
            uint p = (u - pc.chunk_begin) * (pc.stride / 4u);
            if (pc.masked == 0u || ((floatBitsToUint(partials[p].w) >> texel) & 1u) != 0u) {
                acc += partials[p + 3u + texel].xyz;
            }
        }
        texel_grads[o] = acc.x;
        texel_grads[o + 1u] = acc.y;
        texel_grads[o + 2u] = acc.z;
    }
}
