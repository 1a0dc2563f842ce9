#version 460
#extension GL_GOOGLE_include_directive : require
// Tiled backward of the fine pass, one chunk of (face, tile) entries at a time: workgroup
// (tile, part) takes the tile's entries whose item-major slot lies in [chunk_begin, chunk_end)
// (a contiguous sub-run: a tile's slots increase along its run, since binning's stable sort
// keeps the item-major order), and of those the part-th `split` faces. Invocation t takes the
// t-th face of a batch of 64 and sums its contribution over every pixel of the tile (row-major,
// 64 pixels at a time through shared memory), then writes the entry's partial at
// `slot - chunk_begin`. Splitting a crowded tile over several workgroups bounds every
// invocation's loop count (llvmpipe stops loops after 65 535 iterations) without changing any
// sum: each entry is still summed by one invocation in pixel order. Each partial has one writer
// and a fixed summation order: no atomics, bit-identical runs. `grad_reduce.comp` and
// `grad_reduce_texels.comp` then add each face's partials, in slot order, to its gradients.
// Twin: `reference_grad::backward_view` (per tile instead of per image).
#define FINE_BACKWARD
#include "common.glsl"
#include "raster_grad.glsl"

layout(local_size_x = 64) in;

// This chunk's partials: `grad_stride` floats per entry (9 screen, then colour slots × 3). The
// texel slots arrive zeroed (the host fills them) and are summed into here.
layout(std430, set = 0, binding = 6) buffer Partials { float partials[]; };
layout(std430, set = 0, binding = 7) readonly buffer Pairs { uint pairs[]; };
layout(std430, set = 0, binding = 8) readonly buffer PairItems { uint pair_items[]; };
layout(std430, set = 0, binding = 9) readonly buffer Ranges { uvec2 ranges[]; };

shared Upstream s_up[64];

// The first position of the sorted run [lo, hi) whose slot is at least `s` (at most
// bit_length(hi - lo) iterations).
uint first_slot_from(uint lo, uint hi, uint s) {
    while (lo < hi) {
        uint mid = lo + (hi - lo) / 2u;
        if (pairs[mid] < s) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

void main() {
    uint tiles_per_view = pc.tiles_x * pc.tiles_y;
    uint group = linear_group_id();
    uint tile = group / pc.parts;
    uint part = group - tile * pc.parts;
    uint view = tile / tiles_per_view;
    if (view >= pc.view_count) {
        return; // uniform across the workgroup
    }
    uint in_view = tile - view * tiles_per_view;
    uint ty = in_view / pc.tiles_x;
    uint tx = in_view - ty * pc.tiles_x;
    uint gview = pc.first_view + view;
    uvec2 range = ranges[tile];
    uint lo = first_slot_from(range.x, range.y, pc.chunk_begin);
    uint hi = first_slot_from(lo, range.y, pc.chunk_end);
    if (hi - lo <= part * pc.split) {
        return; // uniform: this part of the tile holds no entry of the chunk
    }
    uint first = lo + part * pc.split;
    uint last = first + min(pc.split, hi - first);
    uint lid = gl_LocalInvocationIndex;
    uint chunks = pc.tile_size * pc.tile_size / 64u;
    bool vertex_colors = (pc.flags & FLAG_VERTEX_COLORS) != 0u;

    for (uint start = first; start < last; start += 64u) {
        uint k = start + lid;
        bool has = k < last;
        uint slot = 0u;
        uint face = 0u;
        FaceSetup f;
        if (has) {
            slot = pairs[k];
            face = pair_items[slot];
            f = setups[gview * pc.face_count + face];
        }
        uint o = (slot - pc.chunk_begin) * pc.grad_stride;
        vec3 acc[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
        vec3 cacc[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
        for (uint chunk = 0u; chunk < chunks; ++chunk) {
            barrier();
            uint i = chunk * 64u + lid;
            uint col = tx * pc.tile_size + i % pc.tile_size;
            uint row = ty * pc.tile_size + i / pc.tile_size;
            s_up[lid] = (col < pc.width && row < pc.height) ? load_upstream(gview, col, row)
                                                           : zero_upstream();
            barrier();
            if (!has) {
                continue;
            }
            for (uint q = 0u; q < 64u; ++q) {
                Upstream u = s_up[q];
                if (upstream_is_zero(u)) {
                    continue;
                }
                FaceGrad g;
                if (!pixel_face_grad(f, face, u, g)) {
                    continue;
                }
                acc[0] += g.screen[0];
                acc[1] += g.screen[1];
                acc[2] += g.screen[2];
                if (g.colored) {
                    if (vertex_colors) {
                        cacc[0] += g.color[0];
                        cacc[1] += g.color[1];
                        cacc[2] += g.color[2];
                    } else {
                        uint t = o + 9u + 3u * g.texel;
                        partials[t] += g.color[0].x;
                        partials[t + 1u] += g.color[0].y;
                        partials[t + 2u] += g.color[0].z;
                    }
                }
            }
        }
        if (has) {
            for (uint c = 0u; c < 3u; ++c) {
                partials[o + 3u * c] = acc[c].x;
                partials[o + 3u * c + 1u] = acc[c].y;
                partials[o + 3u * c + 2u] = acc[c].z;
                if (vertex_colors) {
                    partials[o + 9u + 3u * c] = cacc[c].x;
                    partials[o + 9u + 3u * c + 1u] = cacc[c].y;
                    partials[o + 9u + 3u * c + 2u] = cacc[c].z;
                }
            }
        }
    }
}
