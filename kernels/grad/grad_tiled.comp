#version 460
#extension GL_GOOGLE_include_directive : require
// Tiled backward of the fine pass: one workgroup per tile; invocation t takes the tile's t-th
// face of a batch of 64 and sums its contribution over every pixel of the tile (row-major,
// 64 pixels at a time through shared memory), then writes the (face, tile) partial gradient at
// the entry's item-major slot. Each slot has one writer and a fixed summation order: no atomics,
// bit-identical runs. `grad_reduce.comp` then sums each face's slots in order.
// Twin: `reference_grad::backward_view` (per tile instead of per image).
#define FINE_BACKWARD
#include "common.glsl"
#include "raster_grad.glsl"

layout(local_size_x = 64) in;

// Partials: `grad_stride` floats per entry slot (9 screen, then colour slots × 3).
layout(std430, set = 0, binding = 6) buffer Partials { float partials[]; };
layout(std430, set = 0, binding = 7) readonly buffer Pairs { uint pairs[]; };
layout(std430, set = 0, binding = 8) readonly buffer PairItems { uint pair_items[]; };
layout(std430, set = 0, binding = 9) readonly buffer Ranges { uvec2 ranges[]; };

shared Upstream s_up[64];

void main() {
    uint tiles_per_view = pc.tiles_x * pc.tiles_y;
    uint tile = linear_group_id();
    uint view = tile / tiles_per_view;
    if (view >= pc.view_count) {
        return; // uniform across the workgroup
    }
    uint in_view = tile - view * tiles_per_view;
    uint ty = in_view / pc.tiles_x;
    uint tx = in_view - ty * pc.tiles_x;
    uint gview = pc.first_view + view;
    uvec2 range = ranges[tile];
    uint lid = gl_LocalInvocationIndex;
    uint chunks = pc.tile_size * pc.tile_size / 64u;
    bool vertex_colors = (pc.flags & FLAG_VERTEX_COLORS) != 0u;

    for (uint start = range.x; start < range.y; start += 64u) {
        uint k = start + lid;
        bool has = k < range.y;
        uint slot = 0u;
        uint face = 0u;
        FaceSetup f;
        if (has) {
            slot = pairs[k];
            face = pair_items[slot];
            f = setups[gview * pc.face_count + face];
            if (!vertex_colors) {
                for (uint i = 9u; i < pc.grad_stride; ++i) {
                    partials[slot * pc.grad_stride + i] = 0.0;
                }
            }
        }
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
                        uint o = slot * pc.grad_stride + 9u + 3u * g.texel;
                        partials[o] += g.color[0].x;
                        partials[o + 1u] += g.color[0].y;
                        partials[o + 2u] += g.color[0].z;
                    }
                }
            }
        }
        if (has) {
            uint o = slot * pc.grad_stride;
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
