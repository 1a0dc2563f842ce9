#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
// The hard rasterizer, step 3 (after setup and binning): the nearest surface of every pixel, as
// its depth key (z/w bits, triangle + 1) in `keys` (zero: none; the host clears them before the
// first pass). One workgroup per 8×8 tile (rows counted from the image's top, as the binning's),
// one invocation per pixel, each subgroup on its own compact block of the tile's pixels
// (`segment_pixel`). Per batch of as many binned items as it has lanes, each lane loads one and
// stages it: for a snapped item, each edge's function at the tile's first sample (exact in 64
// bits, then clamped to ±2^30, which keeps its sign over the tile: snapped corners are within
// 2^21 units, so an edge's step across the tile is below 2^30) plus its fill-rule bit, and its
// steps per column and per row; a ballot keeps the items whose snapped box meets the box of the
// subgroup's samples (every homogeneous item), and the loop over its bits broadcasts each kept
// item with shuffles (on llvmpipe a shuffle is one permute, a load in a loop a scalar loop over
// the lanes, a barrier a coroutine switch). Each pixel tests it: a snapped item covers the
// centre when all three `E + inclusive > 0` (`Snapped::covers`), its z/w from its depth plane
// C + A x + B y; a homogeneous one by `homogeneous_covers`, z/w = Σ z_k a_k / Σ w_k a_k. The
// key kept is the first in the pixel's depth order (nearest z/w, then the highest triangle:
// `DepthKey::before`), whatever the order items come in, so neither the lanes nor the
// workgroup shape change a bit. Not finite z/w: not drawn. With `peel`, only surfaces after
// the previous layer's key count (`prev_keys`), and a pixel with none there stays empty. A
// crowded tile's run is visited in passes over consecutive parts [pass_begin, pass_end) (the
// driver's loop cap), each resuming from the keys the last left. Twin: `reference::rasterize`.
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

// What a lane stages of its item.
struct Staged {
    ivec3 start; // per edge: E at the tile's first sample + inclusive bit (snapped)
    ivec3 col;   // per edge: E's step to the next column (+16 units in x)
    ivec3 row;   // per edge: E's step to the next row down (−16 units in y)
    vec3 plane;  // z/w = C + A x + B y (snapped)
    uvec2 tri;   // (triangle, mode)
};

// Whether key (zw, id) comes before `k` in a pixel's depth order; `k.y == 0` is none.
bool key_before(float zw, uint id, uvec2 k) {
    if (k.y == 0u) {
        return true;
    }
    float kz = uintBitsToFloat(k.x);
    return zw < kz || (zw == kz && id > k.y);
}

// The subgroup size when the host knows it (`known_subgroup_size`): as a constant it lets the
// driver unroll the loops over lanes and ballot words. 0: unknown, the built-in decides.
layout(constant_id = 0) const uint SUBGROUP_SIZE = 0u;

// Lanes of this subgroup within the 64-invocation workgroup.
uint lanes() {
    return min(SUBGROUP_SIZE != 0u ? SUBGROUP_SIZE : gl_SubgroupSize, 64u);
}

// The compact block of pixels lane runs of `n` lanes cover (4 × 2 for 8 lanes, ...).
uvec2 block_pixel(uint i, uint n) {
    uint w = 1u << ((uint(findMSB(n)) + 1u) / 2u);
    uint h = n / w;
    uint segment = i / n;
    uint lane = i - segment * n;
    uint per_row = 8u / w;
    return uvec2((segment % per_row) * w + lane % w, (segment / per_row) * h + lane / w);
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
    uint n = lanes();
    uint lane = gl_SubgroupInvocationID;
    bool pow2 = n <= 64u && (n & (n - 1u)) == 0u && n >= 1u;
    uvec2 at = pow2 ? block_pixel(gl_LocalInvocationIndex, n)
                    : uvec2(gl_LocalInvocationIndex & 7u, gl_LocalInvocationIndex >> 3u);
    uint lx = at.x;
    uint ly = at.y;
    uint col = 8u * tx + lx;
    uint row_top = 8u * ty + ly;
    bool valid = col < pc.width && row_top < pc.height;
    uint y = valid ? pc.height - 1u - row_top : 0u;
    uint i = (b * pc.height + y) * pc.width + col;
    uvec2 best = valid ? keys[i] : uvec2(0u);
    uvec2 prev = (valid && pc.peel != 0u) ? prev_keys[i] : uvec2(0u);
    bool live = valid && (pc.peel == 0u || prev.y != 0u);
    // The centre in NDC for the depth planes and the homogeneous test, as (x + ½)·(2/W) − 1:
    // within an ulp of `pixel_ndc`'s correctly rounded one, which `hard_shade.comp` uses for the
    // outputs (the depth kernel only orders surfaces; the twin flags pixels this can decide
    // otherwise).
    precise vec2 f = vec2((float(col) + 0.5) * pc.ndc_dx - 1.0, (float(y) + 0.5) * pc.ndc_dy - 1.0);
    // The tile's first sample: its top-left pixel, in sub-pixel units from the centre.
    ivec2 first = ivec2(16 * int(8u * tx) + 8 - 8 * int(pc.width),
                        16 * int(pc.height - 1u - 8u * ty) + 8 - 8 * int(pc.height));
    // The box of the subgroup's samples (pixels past the image's edge count where they lie):
    // its block's, from the block's shape (no subgroup operation: on llvmpipe a subgroup
    // min or max is a scalar loop over the lanes).
    uvec2 block = pow2 ? uvec2(1u << ((uint(findMSB(n)) + 1u) / 2u), 0u) : uvec2(8u, 1u);
    block.y = pow2 ? n / block.x : 1u;
    uvec2 corner0 = (at / block) * block;
    ivec2 slo = first + ivec2(16 * int(corner0.x), -16 * int(corner0.y + block.y - 1u));
    ivec2 shi = first + ivec2(16 * int(corner0.x + block.x - 1u), -16 * int(corner0.y));
    ivec3 lxv = ivec3(int(lx));
    ivec3 lyv = ivec3(int(ly));
    uint begin = range.x + pc.pass_begin;
    uint end = range.x + min(pc.pass_end, run);
    for (uint start = begin; start < end; start += n) {
        uint e = start + lane;
        Staged s;
        s.start = ivec3(0);
        s.col = ivec3(0);
        s.row = ivec3(0);
        s.plane = vec3(0.0);
        s.tri = uvec2(0u);
        bool touches = false;
        if (e < end && lane < n) {
            uint item = b * pc.items_per_view + pair_items[pairs[e]];
            uint o = item * ITEM_WORDS;
            s.tri = uvec2(floatBitsToUint(items[o + 5u]), floatBitsToUint(items[o + 6u]));
            if (s.tri.y == MODE_SNAPPED) {
                uint inc = floatBitsToUint(items[o + 7u]);
                ivec2 q[3] = ivec2[3](
                    ivec2(floatBitsToInt(items[o + 8u]), floatBitsToInt(items[o + 9u])),
                    ivec2(floatBitsToInt(items[o + 10u]), floatBitsToInt(items[o + 11u])),
                    ivec2(floatBitsToInt(items[o + 12u]), floatBitsToInt(items[o + 13u])));
                for (int k = 0; k < 3; ++k) {
                    ivec2 a = q[k];
                    ivec2 c = q[(k + 1) % 3];
                    int dx = c.x - a.x;
                    int dy = c.y - a.y;
                    // E(s) = dx (s.y − a.y) − dy (s.x − a.x).
                    int hi;
                    uint lo;
                    mul_sub64(dx, first.y - a.y, dy, first.x - a.x, hi, lo);
                    s.start[k] = saturate64(hi, lo) + int((inc >> uint(k)) & 1u);
                    s.col[k] = -16 * dy;
                    s.row[k] = -16 * dx;
                }
                s.plane = vec3(items[o + 14u], items[o + 15u], items[o + 16u]);
                ivec2 qlo = min(q[0], min(q[1], q[2]));
                ivec2 qhi = max(q[0], max(q[1], q[2]));
                touches = !(shi.x < qlo.x || shi.y < qlo.y || slo.x > qhi.x || slo.y > qhi.y);
            } else {
                touches = true;
            }
        }
        uvec4 kept = subgroupBallot(touches);
        uint words = ((SUBGROUP_SIZE != 0u ? SUBGROUP_SIZE : gl_SubgroupSize) + 31u) / 32u;
        for (uint word = 0u; word < words; ++word) {
            uint mask = kept[word];
            while (mask != 0u) {
                uint src = 32u * word + uint(findLSB(mask));
                mask &= mask - 1u;
                uvec2 tm = subgroupShuffle(s.tri, src);
                uint id = tm.x + 1u;
                bool covered;
                float zw;
                if (tm.y == MODE_SNAPPED) {
                    ivec3 st = subgroupShuffle(s.start, src);
                    ivec3 sc = subgroupShuffle(s.col, src);
                    ivec3 sr = subgroupShuffle(s.row, src);
                    vec3 pl = subgroupShuffle(s.plane, src);
                    ivec3 e3 = st + sc * lxv + sr * lyv;
                    covered = all(greaterThan(e3, ivec3(0)));
                    precise float z = pl.z + pl.x * f.x + pl.y * f.y;
                    zw = z;
                } else {
                    vec4 p0 = corner(b, tm.x, 0u);
                    vec4 p1 = corner(b, tm.x, 1u);
                    vec4 p2 = corner(b, tm.x, 2u);
                    vec3 a = edge_areas(p0, p1, p2, f);
                    vec2 sums = depth_sums(p0, p1, p2, a);
                    covered = homogeneous_covers(a, sums);
                    zw = fm_div(sums.x, sums.y);
                }
                if (!live || !covered || isnan(zw) || isinf(zw)) {
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
    }
    if (valid) {
        keys[i] = best;
    }
}
