#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
// The hard rasterizer, step 3 (after setup and binning): the nearest surface of every pixel, as
// its depth key (z/w bits, triangle + 1) in `keys` (zero: none; the host clears them before the
// first pass). Eight invocations per 8×8 tile (rows counted from the image's top, as the
// binning's), each one row of it: its eight pixels' keys are held in registers. The invocations
// of a tile form clusters of `m = min(8, subgroup size)` lanes (one cluster on llvmpipe's 8
// lanes, two of 4, a quarter of a 32-lane subgroup), each cluster walking the tile's run of
// binned items `m` at a time: each lane loads one item and stages it — for a snapped item, each
// edge's function at the tile's first sample (exact in 64 bits, then clamped to ±2^30, which
// keeps its sign over the tile: snapped corners are within 2^21 units, so an edge's step across
// the tile is below 2^30) plus its fill-rule bit, its steps per column and per row, and its
// depth plane — and shuffles broadcast each staged item to the cluster, whose lanes test it at
// all eight pixels of their rows: a snapped item covers a centre when all three
// `E + inclusive > 0` (`Snapped::covers`), its z/w from its depth plane C + A x + B y. So an
// item is loaded and staged once per tile (per cluster) and every test is plain vector
// arithmetic with no branch (on llvmpipe an `if` runs both sides under a mask, a load in a loop
// is a scalar loop over the lanes, a shuffle one permute). Homogeneous items (rare: those the
// snapping cannot hold) go through a loop of their own over the ballot of the batch's ones,
// compiled in only when the set-up counted any (`HOMOGENEOUS`): `homogeneous_covers`, z/w = Σ z_k a_k / Σ w_k a_k. The key kept is the first in the pixel's
// depth order (nearest z/w, then the highest triangle: `DepthKey::before`), whatever the order
// items come in, so neither the lanes nor the workgroup shape change a bit. Not finite z/w: not
// drawn. With `PEEL`, only surfaces after the previous layer's key count (`prev_keys`), and a
// pixel with none there stays empty. A crowded tile's run is visited in passes over consecutive
// parts [pass_begin, pass_end) (the driver's loop cap), each resuming from the keys the last
// left. Twin: `reference::rasterize`.
#include "common.glsl"

// Invocations per workgroup, 8 per tile: 8 on a CPU device (one tile, one llvmpipe subgroup),
// 64 elsewhere (`depth_tiles_per_group` in src/raster/hard/gpu.rs).
layout(local_size_x = 64, local_size_x_id = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Pos { float pos[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
// The items (`ITEM_WORDS` words each, five texels), fetched as texels: on llvmpipe a texel
// fetch is one gather of four words, where a load in a loop is a scalar loop over the lanes.
layout(set = 0, binding = 2, rgba32ui) uniform readonly restrict uimageBuffer items;
// Bin entries sorted by tile: each holds its item-major slot (four a texel).
layout(set = 0, binding = 3, rgba32ui) uniform readonly restrict uimageBuffer pairs;
// The item (triangle slot within its minibatch item) of every item-major slot (four a texel).
layout(set = 0, binding = 4, rgba32ui) uniform readonly restrict uimageBuffer pair_items;
// [start, end) of every tile's run of sorted entries, minibatch-major.
layout(std430, set = 0, binding = 5) readonly buffer TileRanges { uvec2 tile_ranges[]; };
// Per pixel [B, H, W] (row 0 at the bottom): (z/w bits, triangle + 1).
layout(std430, set = 0, binding = 6) buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 7) readonly buffer PrevKeys { uvec2 prev_keys[]; };

#include "hard.glsl"

// The subgroup size when the host knows it (`known_subgroup_size`): as a constant it makes the
// cluster size constant, so the driver unrolls the loop over a batch. 0: unknown, the built-in
// decides.
layout(constant_id = 0) const uint SUBGROUP_SIZE = 0u;
// 1: depth peeling (only surfaces after `prev_keys` count). A constant, so that the first layer
// carries none of its arithmetic.
layout(constant_id = 2) const uint PEEL = 0u;
// 1: some item may be homogeneous (the host knows from the set-up's count). On llvmpipe a loop
// runs its body at least once, masked or not, so without any the loop over them is left out.
layout(constant_id = 3) const uint HOMOGENEOUS = 1u;

// An edge that never passes: what a homogeneous item or a batch's empty place stages.
const int NEVER = -0x40000000;
const float MAX_FINITE = uintBitsToFloat(0x7F7FFFFFu);
// What a pixel holds while no surface is found: (+∞, none), before which every finite z/w
// comes; and a pixel outside the image, or with no surface in the previous layer, (−∞, none),
// before which none does. Both are stored as (0, 0).
const uvec2 EMPTY = uvec2(0x7F800000u, 0u);
const uvec2 CLOSED = uvec2(0xFF800000u, 0u);

// Whether candidate (zw, id) replaces key `k` (none: `EMPTY` or `CLOSED`): a finite z/w first in
// the pixel's depth order (nearer, or as near and a higher triangle), and with `PEEL` after the
// previous layer's key `p`. Every term a plain comparison, so that no branch is left to mask.
bool wins(float zw, uint id, uvec2 k, uvec2 p) {
    float kz = uintBitsToFloat(k.x);
    bool finite = abs(zw) <= MAX_FINITE;
    bool nearer = zw < kz;
    bool tie = zw == kz;
    bool higher = id > k.y;
    bool first = nearer || (tie && higher);
    if (PEEL == 0u) {
        return finite && first;
    }
    float pz = uintBitsToFloat(p.x);
    bool behind = pz < zw;
    bool ptie = pz == zw;
    bool lower = p.y > id;
    bool after = behind || (ptie && lower);
    return finite && first && after;
}

void main() {
    uint n = SUBGROUP_SIZE != 0u ? SUBGROUP_SIZE : gl_SubgroupSize;
    uint m = min(n, 8u);
    uint lane = gl_SubgroupInvocationID;
    // The invocation's place, from its subgroup's: a cluster's lanes share one tile.
    uint inv = gl_SubgroupID * n + lane;
    uint tiles = pc.tiles_x * pc.tiles_y;
    uint global_tile = linear_group_id() * (gl_WorkGroupSize.x / 8u) + inv / 8u;
    uint b = global_tile / tiles;
    if (b >= pc.batch) {
        return; // uniform across a tile's invocations
    }
    uint tile = global_tile - b * tiles;
    uvec2 range = tile_ranges[b * tiles + tile];
    uint run = range.y - range.x;
    if (pc.pass_begin > 0u && pc.pass_begin >= run) {
        return; // the tile's run ended in an earlier pass: uniform across the tile
    }
    uint ty = tile / pc.tiles_x;
    uint tx = tile - ty * pc.tiles_x;
    uint ly = inv % 8u;
    // The cluster's first lane (a constant where the subgroup is one cluster).
    uint cluster = n <= 8u ? 0u : lane & ~(m - 1u);
    uint row_top = 8u * ty + ly;
    bool row_valid = row_top < pc.height;
    uint y = row_valid ? pc.height - 1u - row_top : 0u;
    uint cols = min(8u, pc.width - 8u * tx); // the tile's columns inside the image
    uint row_base = (b * pc.height + y) * pc.width + 8u * tx;
    // Pixel centres in NDC for the depth planes and the homogeneous test, as (x + ½)·(2/W) − 1:
    // within an ulp of `pixel_ndc`'s correctly rounded one, which `hard_shade.comp` uses for
    // the outputs (the depth kernel only orders surfaces; the twin flags pixels this can decide
    // otherwise).
    precise float fy = (float(y) + 0.5) * pc.ndc_dy - 1.0;
    float fx[8];
    uvec2 best[8];
    uvec2 prev[8];
    for (uint c = 0u; c < 8u; ++c) {
        precise float x = (float(8u * tx + c) + 0.5) * pc.ndc_dx - 1.0;
        fx[c] = x;
        bool valid = row_valid && c < cols;
        uvec2 k = valid ? keys[row_base + c] : uvec2(0u);
        prev[c] = (valid && PEEL != 0u) ? prev_keys[row_base + c] : uvec2(0u);
        bool live = valid && (PEEL == 0u || prev[c].y != 0u);
        best[c] = !live ? CLOSED : (k.y == 0u ? EMPTY : k);
    }
    // The tile's first sample: its top-left pixel, in sub-pixel units from the centre.
    ivec2 first = ivec2(16 * int(8u * tx) + 8 - 8 * int(pc.width),
                        16 * int(pc.height - 1u - 8u * ty) + 8 - 8 * int(pc.height));
    int lyi = int(ly);
    uint begin = range.x + pc.pass_begin;
    uint end = range.x + min(pc.pass_end, run);
    for (uint start = begin; start < end; start += m) {
        // Stage this lane's item of the batch.
        uint e = start + (lane - cluster);
        ivec3 st = ivec3(NEVER);
        ivec3 sc = ivec3(0);
        ivec3 sr = ivec3(0);
        vec3 pl = vec3(0.0);
        uint t = 0u;
        bool homogeneous = false;
        if (e < end) {
            uint slot = ENTRY_WORD(pairs, e);
            uint item = b * pc.items_per_view + ENTRY_WORD(pair_items, slot);
            int o = int(item * (ITEM_WORDS / 4u));
            uvec4 w1 = imageLoad(items, o + 1).xyzw; // flag, triangle, mode, fill-rule bits
            ivec4 w2 = ivec4(imageLoad(items, o + 2)); // corners 0 and 1
            uvec4 w3 = imageLoad(items, o + 3).xyzw; // corner 2, plane A, B
            uint w4 = imageLoad(items, o + 4).x;      // plane C
            t = w1.y;
            homogeneous = w1.z != MODE_SNAPPED;
            ivec2 q[3] = ivec2[3](w2.xy, w2.zw, ivec2(w3.xy));
            for (int k = 0; k < 3; ++k) {
                ivec2 a = q[k];
                ivec2 d = q[(k + 1) % 3] - a;
                // E(s) = dx (s.y − a.y) − dy (s.x − a.x).
                int hi;
                uint lo;
                mul_sub64(d.x, first.y - a.y, d.y, first.x - a.x, hi, lo);
                st[k] = homogeneous ? NEVER : saturate64(hi, lo) + int((w1.w >> uint(k)) & 1u);
                sc[k] = homogeneous ? 0 : -16 * d.y;
                sr[k] = homogeneous ? 0 : -16 * d.x;
            }
            pl = vec3(uintBitsToFloat(w3.z), uintBitsToFloat(w3.w), uintBitsToFloat(w4));
        }
        // Every item of the batch at every pixel of the row (a homogeneous one never passes).
        for (uint j = 0u; j < m; ++j) {
            uint src = cluster + j;
            ivec3 e3 = subgroupShuffle(st, src) + subgroupShuffle(sr, src) * lyi;
            ivec3 step = subgroupShuffle(sc, src);
            vec3 p = subgroupShuffle(pl, src);
            uint id = subgroupShuffle(t, src) + 1u;
            // The plane's row term, rounded once as in C + A x + B y.
            precise float rowz = p.y * fy;
            for (uint c = 0u; c < 8u; ++c) {
                precise float zw = (p.z + p.x * fx[c]) + rowz;
                bool covers = min(e3.x, min(e3.y, e3.z)) > 0;
                bool replaces = wins(zw, id, best[c], prev[c]);
                best[c] = covers && replaces ? uvec2(floatBitsToUint(zw), id) : best[c];
                e3 += step;
            }
        }
        if (HOMOGENEOUS != 0u) {
            // The batch's homogeneous items.
            uvec4 ballot = subgroupBallot(homogeneous);
            uint mine = (ballot[cluster / 32u] >> (cluster % 32u)) & ((1u << m) - 1u);
            while (mine != 0u) {
                uint src = cluster + uint(findLSB(mine));
                mine &= mine - 1u;
                uint ht = subgroupShuffle(t, src);
                uint hid = ht + 1u;
                vec4 p0 = corner(b, ht, 0u);
                vec4 p1 = corner(b, ht, 1u);
                vec4 p2 = corner(b, ht, 2u);
                for (uint c = 0u; c < 8u; ++c) {
                    vec3 a = edge_areas(p0, p1, p2, vec2(fx[c], fy));
                    vec2 sums = depth_sums(p0, p1, p2, a);
                    float zw = fm_div(sums.x, sums.y);
                    bool covers = homogeneous_covers(a, sums);
                    bool replaces = wins(zw, hid, best[c], prev[c]);
                    best[c] = covers && replaces ? uvec2(floatBitsToUint(zw), hid) : best[c];
                }
            }
        }
    }
    for (uint c = 0u; c < 8u; ++c) {
        if (row_valid && c < cols) {
            keys[row_base + c] = best[c].y == 0u ? uvec2(0u) : best[c];
        }
    }
}
