#version 460
#extension GL_GOOGLE_include_directive : require
// Surface colours: the texel share of the backward's partials, one window of one chunk, one
// range of a view group's views and one range of texels at a time. An invocation adds, view
// after view and texel after texel of its group of one face's texels, the texel's slots of the
// face's units in [window_begin, window_end) to the running dL/d(lit texel) of the view's mesh.
// Units are item-major (view-major), and windows, chunks, view ranges and groups are recorded
// in unit order, so every texel gradient adds its partials in unit order whatever the chunking
// or grouping: results do not depend on them, bit for bit. One writer per (mesh, face, texel),
// fixed order: deterministic. Twin: the per-texel sums of `reference_grad::backward_view` over
// the mesh's views.
//
// An invocation takes `texel_group` consecutive texels of one face: all of the dispatch's on a
// CPU device, one on a GPU (`texel_reduce_group`). On llvmpipe every subgroup of a workgroup is
// a coroutine with a set-up cost of its own (an empty kernel over spot-256's 1 024 blocks of 64
// invocations takes 1.6 ms), and per (face, texel) there are R² times as many; the loads and
// stores per texel are the same. On spot-256 (R = 5) this reduction took 4.3 of the backward's
// 24.5 ms per (face, texel) with storage reads, 3.4 with texel reads, 2.2 per face
// (BENCHMARKS.md). A GPU wants the threads. With masks, an invocation visits only
// the texels of its group that some unit wrote (grad tiled −1.2 ms on spot-256, where 25 texels
// a face meet a handful of pixels).
#include "common.glsl"
#include "view.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Views { View views[]; };
layout(std430, set = 0, binding = 1) readonly buffer Offsets { uint offsets[]; };
// vec4 records: screen corners, then texel slots (see raster_grad.glsl), as texels of four
// words: each read below is one branch-free gather on llvmpipe, where a storage-buffer load in
// this loop is a scalar loop over the lanes with a branch per lane (under the ragged mask of
// the written-slot test, too).
layout(set = 0, binding = 2, rgba32ui) uniform readonly restrict uimageBuffer partials;
// 3 floats per (mesh, face, texel), accumulated.
layout(std430, set = 0, binding = 3) buffer TexelGrads { float texel_grads[]; };

layout(push_constant) uniform Push {
    uint face_count;
    uint texels;       // R² per face
    uint texel_begin;  // texels added by this dispatch: [texel_begin, texel_end)
    uint texel_end;
    uint texel_group;  // texels per invocation (at least 1)
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

// The first vec4 of partial `u` of the chunk.
int partial_at(uint u) {
    return int((u - pc.chunk_begin) * (pc.stride / 4u));
}

// Adds texel `texel`'s slots of units [begin, end) to its running gradient at texel index
// `face_texels + texel`, in unit order: past the three screen corners, the texel slots; with
// masks, only those written. An unwritten slot is read and dropped by a select (no branch).
void add_texel(uint face_texels, uint texel, uint begin, uint end) {
    uint o = 3u * (face_texels + texel);
    vec3 acc = vec3(texel_grads[o], texel_grads[o + 1u], texel_grads[o + 2u]);
    for (uint u = begin; u < end; ++u) {
        int p = partial_at(u);
        bool written = pc.masked == 0u || ((imageLoad(partials, p).w >> texel) & 1u) != 0u;
        vec3 slot = uintBitsToFloat(imageLoad(partials, p + 3 + int(texel)).xyz);
        acc = written ? acc + slot : acc;
    }
    texel_grads[o] = acc.x;
    texel_grads[o + 1u] = acc.y;
    texel_grads[o + 2u] = acc.z;
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint groups = (pc.texel_end - pc.texel_begin + pc.texel_group - 1u) / pc.texel_group;
    uint face = id / groups;
    if (face >= pc.face_count) {
        return;
    }
    uint first = pc.texel_begin + (id - face * groups) * pc.texel_group;
    uint last = min(first + pc.texel_group, pc.texel_end);
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
        uint face_texels = (views[pc.first_view + v].mesh * pc.face_count + face) * pc.texels;
        if (pc.masked == 0u) {
            for (uint texel = first; texel < last; ++texel) {
                add_texel(face_texels, texel, begin, end);
            }
            continue;
        }
        // With masks, only the texels some unit wrote (the union of the units' masks, each the
        // first corner's fourth float; see raster_grad.glsl): a face covers a few pixels of a
        // few tiles, and most of its R² texels get nothing (a loop over set bits is what skips
        // work on llvmpipe; a branch only narrows the lane mask).
        uint touched = 0u;
        for (uint u = begin; u < end; ++u) {
            touched |= imageLoad(partials, partial_at(u)).w;
        }
        // Bits first .. last - 1 (last - first ≤ 32 with masks).
        uint span = last - first;
        touched = (touched >> first) & (span >= 32u ? 0xFFFFFFFFu : (1u << span) - 1u);
        while (touched != 0u) {
            uint texel = first + uint(findLSB(touched));
            touched &= touched - 1u;
            add_texel(face_texels, texel, begin, end);
        }
    }
}
