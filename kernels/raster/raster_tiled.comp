#version 460
#extension GL_GOOGLE_include_directive : require
// Tiled soft rasterization: one workgroup per 8×8 block of pixels, visiting only the faces binned
// to the block's tile (`kernels/binning/`), in index order, through shared memory 64 faces at a
// time. The per-face step is `raster_fine.glsl`'s `shade_face`, as in `raster_brute.comp`, and
// binning keeps every face that can touch a pixel of the tile (a superset is harmless: the step
// ignores a face beyond its cut-off exactly as brute force does), so the pixels are bit for bit
// those of the brute-force kernel. Twin: `reference::shade_pixel`.
#include "common.glsl"
#include "raster_fine.glsl"

layout(local_size_x = 64) in;

// Bin entries sorted by tile: each holds its item-major slot.
layout(std430, set = 0, binding = 5) readonly buffer Pairs { uint pairs[]; };
// The face of every item-major slot.
layout(std430, set = 0, binding = 6) readonly buffer PairItems { uint pair_items[]; };
// [start, end) of every tile's run of sorted entries, view-major within this dispatch.
layout(std430, set = 0, binding = 7) readonly buffer Ranges { uvec2 ranges[]; };

const uint BATCH = 64u;
shared FaceSetup s_setup[BATCH];
shared uint s_face[BATCH];

void main() {
    uint blocks_x = (pc.width + 7u) / 8u;
    uint blocks_y = (pc.height + 7u) / 8u;
    uint blocks_per_view = blocks_x * blocks_y;
    uint block = linear_group_id();
    uint view = block / blocks_per_view;
    if (view >= pc.view_count) {
        return; // surplus workgroup of a folded grid: uniform across the workgroup
    }
    uint in_view = block - view * blocks_per_view;
    uint by = in_view / blocks_x;
    uint bx = in_view - by * blocks_x;
    uint lid = gl_LocalInvocationIndex;
    uint col = bx * 8u + (lid & 7u);
    uint row = by * 8u + (lid >> 3u);
    bool valid = col < pc.width && row < pc.height;

    uint blocks_per_tile = pc.tile_size / 8u;
    uint tile = view * pc.tiles_x * pc.tiles_y + (by / blocks_per_tile) * pc.tiles_x
              + bx / blocks_per_tile;
    uvec2 range = ranges[tile];
    uint setup_base = (pc.first_view + view) * pc.face_count;

    vec2 p = pixel_center(col, row, pc.width, pc.height);
    PixelState s = pixel_init();
    for (uint start = range.x; start < range.y; start += BATCH) {
        barrier();
        uint k = start + lid;
        if (k < range.y) {
            uint face = pair_items[pairs[k]];
            s_face[lid] = face;
            s_setup[lid] = setups[setup_base + face];
        }
        barrier();
        if (valid) {
            uint n = min(BATCH, range.y - start);
            for (uint i = 0u; i < n; ++i) {
                shade_face(s, s_setup[i], s_face[i], p);
            }
        }
    }
    if (valid) {
        pixel_finish(s, (pc.first_view + view) * pc.width * pc.height + row * pc.width + col);
    }
}
