#version 460
#extension GL_GOOGLE_include_directive : require
// The hard rasterizer, step 3 (after setup and binning): the nearest surface of every pixel, as
// its depth key (z/w bits, triangle + 1) in `keys` (zero: none; the host clears them before the
// first pass). One workgroup per 8×8 tile (rows counted from the image's top, as the binning's),
// one invocation per pixel. The tile's binned items are staged 64 at a time in shared memory,
// one per invocation: for a snapped item, each edge's function at the tile's first sample
// (exact in 64 bits, then clamped to ±2^30, which keeps its sign over the tile: snapped
// corners are within 2^21 units, so an edge's step across the tile is below 2^30) plus its
// fill-rule bit, and its steps per column and per row; for every item its clip-space corners.
// Each pixel then tests them in order: a snapped item covers the centre when all three
// `E + inclusive > 0` (`Snapped::covers`), a homogeneous one by `homogeneous_covers`; a covered
// centre's z/w = Σ z_k a_k / Σ w_k a_k, and the key (nearest z/w, then the highest triangle)
// is kept (`DepthKey::before`). Not finite z/w: not drawn. With `peel`, only surfaces after
// the previous layer's key count (`prev_keys`), and a pixel with none there stays empty.
// A crowded tile's run is visited in passes over consecutive parts [pass_begin, pass_end)
// (the driver's loop cap), each resuming from the keys the last left. Twin:
// `reference::rasterize`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Pos { float pos[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
layout(std430, set = 0, binding = 2) readonly buffer Items { float items[]; };
// Bin entries sorted by tile: each holds its item-major slot.
layout(std430, set = 0, binding = 3) readonly buffer Pairs { uint pairs[]; };
// The item (triangle slot within its minibatch item) of every item-major slot.
layout(std430, set = 0, binding = 4) readonly buffer PairItems { uint pair_items[]; };
// [start, end) of every tile's run of sorted entries, minibatch-major.
layout(std430, set = 0, binding = 5) readonly buffer TileRanges { uvec2 tile_ranges[]; };
// Per pixel [B, H, W] (row 0 at the bottom): (z/w bits, triangle + 1).
layout(std430, set = 0, binding = 6) buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 7) readonly buffer PrevKeys { uvec2 prev_keys[]; };

#include "hard.glsl"

shared ivec3 s_start[64]; // per edge: E at the tile's first sample + inclusive bit
shared ivec3 s_col[64];   // per edge: E's step to the next column (+16 units in x)
shared ivec3 s_row[64];   // per edge: E's step to the next row down (−16 units in y)
shared vec4 s_p0[64];
shared vec4 s_p1[64];
shared vec4 s_p2[64];
shared uvec2 s_tri[64];   // (triangle, mode)

// Whether key (zw, id) comes before `k` in a pixel's depth order; `k.y == 0` is none.
bool key_before(float zw, uint id, uvec2 k) {
    if (k.y == 0u) {
        return true;
    }
    float kz = uintBitsToFloat(k.x);
    return zw < kz || (zw == kz && id > k.y);
}

void stage(uint e, uint b, ivec2 first) {
    uint item = b * pc.items_per_view + pair_items[pairs[e]];
    uint o = item * ITEM_WORDS;
    uint t = floatBitsToUint(items[o + 5u]);
    uint mode = floatBitsToUint(items[o + 6u]);
    uint inc = floatBitsToUint(items[o + 7u]);
    uint l = gl_LocalInvocationIndex;
    if (mode == MODE_SNAPPED) {
        ivec2 q[3] = ivec2[3](
            ivec2(floatBitsToInt(items[o + 8u]), floatBitsToInt(items[o + 9u])),
            ivec2(floatBitsToInt(items[o + 10u]), floatBitsToInt(items[o + 11u])),
            ivec2(floatBitsToInt(items[o + 12u]), floatBitsToInt(items[o + 13u])));
        ivec3 start;
        ivec3 col;
        ivec3 row;
        for (int k = 0; k < 3; ++k) {
            ivec2 a = q[k];
            ivec2 c = q[(k + 1) % 3];
            int dx = c.x - a.x;
            int dy = c.y - a.y;
            // E(s) = dx (s.y − a.y) − dy (s.x − a.x).
            int hi;
            uint lo;
            mul_sub64(dx, first.y - a.y, dy, first.x - a.x, hi, lo);
            start[k] = saturate64(hi, lo) + int((inc >> uint(k)) & 1u);
            col[k] = -16 * dy;
            row[k] = -16 * dx;
        }
        s_start[l] = start;
        s_col[l] = col;
        s_row[l] = row;
    }
    s_p0[l] = corner(b, t, 0u);
    s_p1[l] = corner(b, t, 1u);
    s_p2[l] = corner(b, t, 2u);
    s_tri[l] = uvec2(t, mode);
}

void main() {
    uint tiles = pc.tiles_x * pc.tiles_y;
    uint g = linear_group_id();
    uint b = g / tiles;
    if (b >= pc.batch) {
        return; // uniform across the workgroup
    }
    uint tile = g - b * tiles;
    uint ty = tile / pc.tiles_x;
    uint tx = tile - ty * pc.tiles_x;
    uvec2 range = tile_ranges[b * tiles + tile];
    uint run = range.y - range.x;
    if (pc.pass_begin > 0u && pc.pass_begin >= run) {
        return; // the tile's run ended in an earlier pass: uniform
    }
    uint lx = gl_LocalInvocationIndex & 7u;
    uint ly = gl_LocalInvocationIndex >> 3u;
    uint col = 8u * tx + lx;
    uint row_top = 8u * ty + ly;
    bool valid = col < pc.width && row_top < pc.height;
    uint y = valid ? pc.height - 1u - row_top : 0u;
    uint i = (b * pc.height + y) * pc.width + col;
    uvec2 best = valid ? keys[i] : uvec2(0u);
    uvec2 prev = (valid && pc.peel != 0u) ? prev_keys[i] : uvec2(0u);
    bool live = valid && (pc.peel == 0u || prev.y != 0u);
    vec2 f = pixel_ndc(col, y);
    // The tile's first sample: its top-left pixel, in sub-pixel units from the centre.
    ivec2 first = ivec2(16 * int(8u * tx) + 8 - 8 * int(pc.width),
                        16 * int(pc.height - 1u - 8u * ty) + 8 - 8 * int(pc.height));
    ivec3 lxv = ivec3(int(lx));
    ivec3 lyv = ivec3(int(ly));
    uint begin = range.x + pc.pass_begin;
    uint end = range.x + min(pc.pass_end, run);
    for (uint batch = begin; batch < end; batch += 64u) {
        uint e = batch + gl_LocalInvocationIndex;
        if (e < end) {
            stage(e, b, first);
        }
        barrier();
        uint n = min(64u, end - batch);
        if (live) {
            for (uint k = 0u; k < n; ++k) {
                uvec2 tm = s_tri[k];
                vec4 p0 = s_p0[k];
                vec4 p1 = s_p1[k];
                vec4 p2 = s_p2[k];
                bool covered;
                vec3 a;
                vec2 sums;
                if (tm.y == MODE_SNAPPED) {
                    ivec3 e3 = s_start[k] + s_col[k] * lxv + s_row[k] * lyv;
                    covered = all(greaterThan(e3, ivec3(0)));
                    if (covered) {
                        a = edge_areas(p0, p1, p2, f);
                        sums = depth_sums(p0, p1, p2, a);
                    }
                } else {
                    a = edge_areas(p0, p1, p2, f);
                    sums = depth_sums(p0, p1, p2, a);
                    covered = homogeneous_covers(a, sums);
                }
                if (!covered) {
                    continue;
                }
                float zw = fm_div(sums.x, sums.y);
                uint id = tm.x + 1u;
                if (isnan(zw) || isinf(zw)) {
                    continue;
                }
                if (pc.peel != 0u) {
                    // Only surfaces after the previous layer's.
                    float pz = uintBitsToFloat(prev.x);
                    if (!(pz < zw || (pz == zw && prev.y > id))) {
                        continue;
                    }
                }
                if (key_before(zw, id, best)) {
                    best = uvec2(floatBitsToUint(zw), id);
                }
            }
        }
        barrier();
    }
    if (valid) {
        keys[i] = best;
    }
}
