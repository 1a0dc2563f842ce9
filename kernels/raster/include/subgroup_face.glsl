// Broadcasting one lane's face or pixel to its whole subgroup, one shuffle per 32-bit word: how
// the tiled kernels share work without shared memory or barriers. (On llvmpipe a barrier is a
// coroutine switch per 8-lane vector, and a load inside a loop is a scalar loop over the lanes,
// while a shuffle is one permute.) Includers enable GL_KHR_shader_subgroup_shuffle.
#ifndef SOFTVK_SUBGROUP_FACE_GLSL
#define SOFTVK_SUBGROUP_FACE_GLSL

#include "raster.glsl"

// Lane `i`'s face.
Face face_shuffle(Face f, uint i) {
    Face g;
    g.v[0] = subgroupShuffle(f.v[0], i);
    g.v[1] = subgroupShuffle(f.v[1], i);
    g.v[2] = subgroupShuffle(f.v[2], i);
    g.inv[0] = subgroupShuffle(f.inv[0], i);
    g.inv[1] = subgroupShuffle(f.inv[1], i);
    g.inv[2] = subgroupShuffle(f.inv[2], i);
    g.bbox = subgroupShuffle(f.bbox, i);
    g.flags = subgroupShuffle(f.flags, i);
    g.mesh = subgroupShuffle(f.mesh, i);
    g.det = subgroupShuffle(f.det, i);
    g.inv_z = subgroupShuffle(f.inv_z, i);
    g.inv_len2 = subgroupShuffle(f.inv_len2, i);
    g.inv_det = subgroupShuffle(f.inv_det, i);
    return g;
}

// Whether face `f` may touch a pixel centred in the box [lo, hi] (a subgroup's pixel centres):
// the tiled kernels' per-batch test, whose ballot keeps the faces a segment folds.
bool face_meets_box(Face f, vec2 lo, vec2 hi) {
    return (f.flags & FACE_FINITE) != 0u
        && !(hi.x < f.bbox.x || hi.y < f.bbox.y || lo.x > f.bbox.z || lo.y > f.bbox.w);
}

// The subgroup size, when the host knows it (constant_id 4, after the fine modes): the device's
// `subgroupSize`, which a SPIR-V 1.5 pipeline without size control sees as gl_SubgroupSize. As a
// constant it lets the driver unroll the loops over lanes and ballot words (llvmpipe learns its
// own size only after its loop unrolling). 0: unknown, and the built-ins decide.
layout(constant_id = 4) const uint SUBGROUP_SIZE = 0u;

// Lanes this subgroup has in the 64-invocation workgroup: at most 64 (a subgroup may be wider).
// Never a fixed number: 8 on llvmpipe with AVX2, 32 on NVIDIA, 64 or 32 on AMD.
uint subgroup_lanes() {
    return min(SUBGROUP_SIZE != 0u ? SUBGROUP_SIZE : gl_SubgroupSize, 64u);
}

// The block of pixels (width, height) that `lanes` lanes cover together: as square as a power
// of two allows (8 lanes: 4 × 2; 32: 8 × 4; 64: 8 × 8), since the kernels skip a face for the
// whole subgroup only where its box misses the box of the subgroup's pixels, and a squarer
// block meets fewer of the small boxes that most faces have (row segments of 8 visited about a
// fifth more pairs on spot-256). (0, 0) when `lanes` is not a power of two up to 64: rows.
uvec2 segment_shape(uint lanes) {
    if (lanes == 0u || lanes > 64u || (lanes & (lanes - 1u)) != 0u) {
        return uvec2(0u);
    }
    uint w = 1u << ((uint(findMSB(lanes)) + 1u) / 2u);
    return uvec2(w, lanes / w);
}

// Where pixel `i` of a `size`-wide square (a multiple of 8 pixels, `size`² a multiple of
// `lanes`) lies when its pixels go to lanes `lanes` at a time, each run of `lanes` one
// `segment_shape` block, blocks row-major (or pixels row-major when the shape is (0, 0)).
uvec2 segment_pixel(uint i, uint size, uint lanes) {
    uvec2 shape = segment_shape(lanes);
    if (shape.x == 0u) {
        return uvec2(i % size, i / size);
    }
    uint segment = i / lanes;
    uint lane = i - segment * lanes;
    uint per_row = size / shape.x;
    return uvec2((segment % per_row) * shape.x + lane % shape.x,
                 (segment / per_row) * shape.y + lane / shape.x);
}

// Pixel `i` of a `size`-wide tile (a multiple of 8) in the backward's fixed order: 8 × 8 blocks
// row-major, and in a block the Z (Morton) order of its 64 pixels (bits x0 y0 x1 y1 x2 y2). Any
// power-of-two `lanes` from 4 to 64 then takes, `lanes` at a time, one `segment_shape` block (4
// lanes: 2 × 2, 8: 4 × 2, 16: 4 × 4, ...), and the order of the pixels, which decides the order
// of the sums, is the same whatever the lanes.
uvec2 morton_pixel(uint i, uint size) {
    uint block = i >> 6u;
    uint m = i & 63u;
    uint per_row = size / 8u;
    uint x = (m & 1u) | ((m >> 1u) & 2u) | ((m >> 2u) & 4u);
    uint y = ((m >> 1u) & 1u) | ((m >> 2u) & 2u) | ((m >> 3u) & 4u);
    return uvec2((block % per_row) * 8u + x, (block / per_row) * 8u + y);
}

// -0.0, the exact identity of float addition: x + -0.0 == x for every x (+0.0 turns a -0.0 into
// +0.0). What a lane with nothing to add adds, so that adding nothing changes no bit.
#define NEG_ZERO uintBitsToFloat(0x80000000u)

// The sum of `v` over each quad of lanes (lanes 4k .. 4k + 3), the same bits in its four lanes:
// (v0 + v1) + (v2 + v3). With `morton_pixel`'s order a quad is the same 2 × 2 pixels for any
// subgroup size, so its sum is too.
#define SOFTVK_QUAD_SUM(T)                                                     \
    T quad_sum(T v) {                                                          \
        uint lane = gl_SubgroupInvocationID;                                   \
        v += subgroupShuffle(v, lane ^ 1u);                                    \
        v += subgroupShuffle(v, lane ^ 2u);                                    \
        return v;                                                              \
    }
SOFTVK_QUAD_SUM(vec2)
SOFTVK_QUAD_SUM(vec3)

// Words of a subgroup ballot in use.
uint ballot_words() {
    return ((SUBGROUP_SIZE != 0u ? SUBGROUP_SIZE : gl_SubgroupSize) + 31u) / 32u;
}

// The bitwise or of `v` over the subgroup, the same in every lane. With a known size, a
// butterfly of shuffles: on llvmpipe a shuffle is one permute while `subgroupOr` is a scalar
// loop over the lanes with a branch per lane. Unrolled by hand: a constant condition is gone
// after specialization, while a loop over `m <<= 1` is not unrolled.
uint lane_or(uint v) {
    if (SUBGROUP_SIZE == 0u) {
        return subgroupOr(v);
    }
    uint lane = gl_SubgroupInvocationID;
    if (SUBGROUP_SIZE > 1u) v |= subgroupShuffle(v, lane ^ 1u);
    if (SUBGROUP_SIZE > 2u) v |= subgroupShuffle(v, lane ^ 2u);
    if (SUBGROUP_SIZE > 4u) v |= subgroupShuffle(v, lane ^ 4u);
    if (SUBGROUP_SIZE > 8u) v |= subgroupShuffle(v, lane ^ 8u);
    if (SUBGROUP_SIZE > 16u) v |= subgroupShuffle(v, lane ^ 16u);
    if (SUBGROUP_SIZE > 32u) v |= subgroupShuffle(v, lane ^ 32u);
    return v;
}

// The minimum and maximum of `v` over the subgroup, by the same butterfly (min and max are
// exact in any order): on llvmpipe `subgroupMin`/`subgroupMax` are scalar loops over the lanes.
// Every lane must be active.
vec2 lane_min(vec2 v) {
    if (SUBGROUP_SIZE == 0u) {
        return subgroupMin(v);
    }
    uint lane = gl_SubgroupInvocationID;
    if (SUBGROUP_SIZE > 1u) v = min(v, subgroupShuffle(v, lane ^ 1u));
    if (SUBGROUP_SIZE > 2u) v = min(v, subgroupShuffle(v, lane ^ 2u));
    if (SUBGROUP_SIZE > 4u) v = min(v, subgroupShuffle(v, lane ^ 4u));
    if (SUBGROUP_SIZE > 8u) v = min(v, subgroupShuffle(v, lane ^ 8u));
    if (SUBGROUP_SIZE > 16u) v = min(v, subgroupShuffle(v, lane ^ 16u));
    if (SUBGROUP_SIZE > 32u) v = min(v, subgroupShuffle(v, lane ^ 32u));
    return v;
}

vec2 lane_max(vec2 v) {
    return -lane_min(-v);
}

#endif
