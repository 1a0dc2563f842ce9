#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
#extension GL_KHR_shader_subgroup_arithmetic : require
// Tiled soft rasterization (in passes over consecutive parts of a crowded tile's run where the
// driver's loop cap asks: `CARRY` in raster_fine.glsl): one workgroup per 8×8 block of pixels (a block is the unit a tile
// size must be a multiple of; 64 invocations, one per pixel, or fewer, each shading a pixel of
// several of the block's segments in turn: `tiled_forward_workgroup` in src/raster/fine.rs says
// when and why), visiting only the faces binned to the block's tile (`kernels/gpu/binning/`), in
// index order. Binning keeps every face that can touch a pixel of the tile (a superset is
// harmless: the step ignores a face beyond its cut-off exactly as brute force does), so the
// pixels are bit for bit those of `raster_brute.comp`, which calls the same `shade_face` for
// every face. Twin: `reference::shade_pixel`.
//
// Each subgroup works alone, with no shared memory and no barrier: per batch of as many binned
// faces as it has lanes, each lane loads one face; a ballot keeps the faces whose box touches
// the box of the subgroup's pixel centres (a face whose box holds none of them changes none of
// them, the same argument that lets binning drop it from the tile), and the loop over the
// ballot's bits, lowest first (index order), broadcasts each kept face with shuffles and folds it
// into every lane's pixel. The loop ends when the mask is empty, which on llvmpipe is the only
// construct that skips work (an `if` only narrows the lane mask).
//
// A silhouette render (`ALPHA_ONLY`) on a workgroup of one subgroup (a CPU device) swaps the two
// loops: each batch of faces is loaded once and folded into every segment of the block in turn,
// each lane holding its pixel of every segment, instead of the whole run being loaded again for
// each segment (fit-120's tiled forward on llvmpipe: 108 -> 71 ms, BENCHMARKS.md). Every pixel
// still folds its tile's faces in index order, each kept by the same ballot over its own
// segment's box: the same bits. (A colour render's state is too large to hold per segment.)
// The per-lane inputs as texel buffers: branch-free gathers on llvmpipe (raster_fine.glsl).
#define TEXEL_INPUTS
#define CARRY_BINDING 8
#include "common.glsl"
#include "raster_fine.glsl"
#include "subgroup_face.glsl"

// The workgroup size is the host's (constant 5): 64, or as few whole subgroups as the loop cap
// allows on a CPU device.
layout(local_size_x = 64, local_size_x_id = 5) in;

// Constant 7, set only by softvk-raster's own unit tests (`Renderer::counting_loops`):
// in place of each pixel's colour the kernel writes what it counted, (the loop iterations its
// invocation had run when it wrote the pixel, the faces it shaded for the pixel, 0, 0), which
// the host's `loops::tiled_forward_iterations` and `Binned::pair_counts` must predict. At 0 the
// counts are dead code and the compiler drops them.
layout(constant_id = 7) const uint COUNT_LOOPS = 0u;

// Bin entries sorted by tile: each holds its item-major slot.
layout(std430, set = 0, binding = 5) readonly buffer Pairs { uint pairs[]; };
// The face of every item-major slot.
layout(std430, set = 0, binding = 6) readonly buffer PairItems { uint pair_items[]; };
// [start, end) of every tile's run of sorted entries, view-major within this dispatch.
layout(std430, set = 0, binding = 7) readonly buffer Ranges { uvec2 ranges[]; };

// The faces of one batch (lane i's `f`, face index `face`) that the ballot keeps for the segment
// whose pixel centres' box is [lo, hi], folded into this lane's pixel `p` of it (state `s`), in
// index order: for one segment, in either of `main`'s paths.
void fold_batch(inout PixelState s, vec2 p, vec2 lo, vec2 hi, Face f, uint face,
                inout uint iterations, inout uint shaded) {
    uvec4 kept = subgroupBallot(face_meets_box(f, lo, hi));
    for (uint word = 0u; word < ballot_words(); ++word) {
        ++iterations;
        uint mask = kept[word];
        while (mask != 0u) {
            ++iterations;
            ++shaded;
            uint i = 32u * word + uint(findLSB(mask));
            mask &= mask - 1u;
            shade_face(s, face_shuffle(f, i), subgroupShuffle(face, i), p);
        }
    }
}

// The alpha-only path's segments: 64 / lanes of them per lane (up to 16, at 4 lanes), each a
// set of variables of its own (a loop over an array of them would index it per lane: on
// llvmpipe a gather and a scatter per access; nested loops are not unrolled), those past the
// block's 64 pixels never valid, never visited (a constant condition once the subgroup size is
// specialized) and never written.
#define SEGMENT_BEGIN(k)                                                                  \
    uvec2 at##k = segment_pixel(lane + uint(k) * lanes, 8u, lanes);                        \
    uint col##k##_ = bx * 8u + at##k.x;                                                    \
    uint row##k##_ = row0 + by * 8u + at##k.y;                                             \
    bool valid##k = uint(k) < segments && col##k##_ < pc.width && row##k##_ < pc.height;   \
    vec2 p##k = pixel_center(col##k##_, row##k##_, pc.width, pc.height);                   \
    vec2 lo##k = lane_min(valid##k ? p##k : vec2(inf));                                    \
    vec2 hi##k = lane_max(valid##k ? p##k : vec2(-inf));                                   \
    uint pixel##k = (pc.first_view + view) * pc.width * pc.height + row##k##_ * pc.width   \
                  + col##k##_;                                                             \
    PixelState s##k = begin > 0u && valid##k ? carry_load(pixel##k) : pixel_init();        \
    uint shaded##k = 0u;

#define SEGMENT_FOLD(k)                                                                   \
    if (uint(k) < segments) {                                                              \
        fold_batch(s##k, p##k, lo##k, hi##k, f, face, iterations, shaded##k);              \
    }

#define SEGMENT_END(k)                                                                    \
    if (COUNT_LOOPS != 0u) {                                                               \
        if (valid##k) {                                                                    \
            image[pixel##k] = vec4(float(iterations), float(shaded##k), 0.0, 0.0);         \
        }                                                                                  \
    } else if (valid##k && end < run) {                                                    \
        carry_store(s##k, pixel##k);                                                       \
    } else if (valid##k) {                                                                 \
        pixel_finish(s##k, pixel##k);                                                      \
    }

void main() {
    // The pixel rows of the grid's window of tile rows (all of them unless a view was binned
    // window by window); tiles are multiples of 8 pixels, so blocks never straddle two tiles.
    uint row0 = pc.first_row * pc.tile_size;
    uint rows = min(pc.height - row0, pc.tiles_y * pc.tile_size);
    uint blocks_x = (pc.width + 7u) / 8u;
    uint blocks_y = (rows + 7u) / 8u;
    uint blocks_per_view = blocks_x * blocks_y;
    uint block = linear_group_id();
    uint view = block / blocks_per_view;
    if (view >= pc.view_count) {
        return; // surplus workgroup of a folded grid: uniform across the workgroup
    }
    uint in_view = block - view * blocks_per_view;
    uint by = in_view / blocks_x;
    uint bx = in_view - by * blocks_x;
    uint blocks_per_tile = pc.tile_size / 8u;
    uint tile = view * pc.tiles_x * pc.tiles_y + (by / blocks_per_tile) * pc.tiles_x
              + bx / blocks_per_tile;
    uvec2 range = ranges[tile];
    // This pass's part of the tile's run (all of it without CARRY). A tile whose run ended in
    // an earlier pass is done: uniform across the workgroup.
    uint run = range.y - range.x;
    if (CARRY != 0u && pc.pass_begin > 0u && pc.pass_begin >= run) {
        return;
    }
    uint begin = CARRY != 0u ? pc.pass_begin : 0u;
    uint end = CARRY != 0u ? min(pc.pass_end, run) : run;
    uint setup_base = (pc.first_view + view) * pc.face_count;
    uint lanes = subgroup_lanes();
    uint lane = gl_SubgroupInvocationID;

    // Pixel b of the block, for b = this invocation's index, then one workgroup further, and so
    // on: `segment_pixel(b, 8, lanes)`. Where the driver gives subgroups consecutive invocations
    // (any does for a workgroup that is a whole number of subgroups), each subgroup covers one
    // `segment_shape` block per round. Any other assignment is still one pixel per invocation
    // and round, only less well pruned.
    uint iterations = 0u;
    float inf = uintBitsToFloat(0x7f800000u);
    // Uniform: the modes and sizes are constants, the subgroup count the same in every lane.
    if (ALPHA_ONLY && SUBGROUP_SIZE >= 4u && SUBGROUP_SIZE <= 64u && gl_NumSubgroups == 1u) {
        uint segments = 64u / lanes;
        SEGMENT_BEGIN(0) SEGMENT_BEGIN(1) SEGMENT_BEGIN(2) SEGMENT_BEGIN(3)
        SEGMENT_BEGIN(4) SEGMENT_BEGIN(5) SEGMENT_BEGIN(6) SEGMENT_BEGIN(7)
        SEGMENT_BEGIN(8) SEGMENT_BEGIN(9) SEGMENT_BEGIN(10) SEGMENT_BEGIN(11)
        SEGMENT_BEGIN(12) SEGMENT_BEGIN(13) SEGMENT_BEGIN(14) SEGMENT_BEGIN(15)
        for (uint start = range.x + begin; start < range.x + end; start += lanes) {
            ++iterations;
            uint k = start + lane;
            Face f = face_none();
            uint face = 0u;
            if (k < range.x + end) {
                face = pair_items[pairs[k]];
                f = load_face(setup_base + face);
            }
            SEGMENT_FOLD(0) SEGMENT_FOLD(1) SEGMENT_FOLD(2) SEGMENT_FOLD(3)
            SEGMENT_FOLD(4) SEGMENT_FOLD(5) SEGMENT_FOLD(6) SEGMENT_FOLD(7)
            SEGMENT_FOLD(8) SEGMENT_FOLD(9) SEGMENT_FOLD(10) SEGMENT_FOLD(11)
            SEGMENT_FOLD(12) SEGMENT_FOLD(13) SEGMENT_FOLD(14) SEGMENT_FOLD(15)
        }
        SEGMENT_END(0) SEGMENT_END(1) SEGMENT_END(2) SEGMENT_END(3)
        SEGMENT_END(4) SEGMENT_END(5) SEGMENT_END(6) SEGMENT_END(7)
        SEGMENT_END(8) SEGMENT_END(9) SEGMENT_END(10) SEGMENT_END(11)
        SEGMENT_END(12) SEGMENT_END(13) SEGMENT_END(14) SEGMENT_END(15)
        return;
    }
    for (uint b = gl_LocalInvocationIndex; b < 64u; b += gl_WorkGroupSize.x) {
        ++iterations;
        uint shaded = 0u;
        uvec2 at = segment_pixel(b, 8u, lanes);
        uint col = bx * 8u + at.x;
        uint row = row0 + by * 8u + at.y;
        bool valid = col < pc.width && row < pc.height;
        vec2 p = pixel_center(col, row, pc.width, pc.height);
        // The box of this subgroup's pixel centres inside the image: a lane past the image's
        // edge writes nothing, so its centre need not be in the box (a face that misses the
        // box changes no pixel that is written, the same bits).
        vec2 lo = lane_min(valid ? p : vec2(inf));
        vec2 hi = lane_max(valid ? p : vec2(-inf));

        uint pixel = (pc.first_view + view) * pc.width * pc.height + row * pc.width + col;
        PixelState s = begin > 0u && valid ? carry_load(pixel) : pixel_init();
        for (uint start = range.x + begin; start < range.x + end; start += lanes) {
            ++iterations;
            uint k = start + lane;
            Face f = face_none();
            uint face = 0u;
            if (k < range.x + end && lane < lanes) {
                face = pair_items[pairs[k]];
                f = load_face(setup_base + face);
            }
            fold_batch(s, p, lo, hi, f, face, iterations, shaded);
        }
        if (COUNT_LOOPS != 0u) {
            if (valid) {
                image[pixel] = vec4(float(iterations), float(shaded), 0.0, 0.0);
            }
        } else if (valid && end < run) {
            carry_store(s, pixel);
        } else if (valid) {
            pixel_finish(s, pixel);
        }
    }
}
