#version 460
#extension GL_GOOGLE_include_directive : require
// nvdiffrast's `antialias`, step 1 (forward and backward): per pixel, the decisions of its right
// pair and of its next-row pair, written to the work list (`hard_antialias.glsl`). A pair is
// examined when its two ids differ (as floats); the triangle is the only pixel's with one (id in
// [1, T]), or of two the one with the strictly smaller z/w, a tie going to pixel 1 (an id past T
// skips the pair); the geometry is measured in pixels from that pixel's centre, x and y swapped
// for a next-row pair. The edge is the one, of those whose ends lie on either side of the axis
// (sign bits), whose crossing σ·x_c lies farthest toward the other pixel (fractions compared by
// cross-multiplication, nvdiffrast's tie rule); it must be a silhouette edge (no opposite vertex,
// or one on the same side as the triangle's own by the sign bits of the signed areas) with
// |Δy| ≥ |Δx|, and its crossing r = σ·x_c must lie in (−1/16, 1 + 1/16); then
// α = σ·(1/2 − clamp(r, 0, 1)). Every decision as the twin takes it, in f32 on softvk's maths
// (1/W_c and r correctly rounded). One writer per record: no order to fix.
// Twin: `antialias::find_edge_pairs` (`analyse_pair`).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Pos { float pos[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
// Per triangle and edge k, the vertex across it (within the item's set), or AA_NO_VERTEX.
layout(std430, set = 0, binding = 2) readonly buffer Opposites { uint opposites[]; };
layout(std430, set = 0, binding = 3) readonly buffer Rast { vec4 rast[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Pairs { uvec4 pairs[]; };

#include "hard.glsl"
#include "hard_antialias.glsl"

// Whether a and b have the same sign bit (+0 and −0 differ).
bool same_sign(float a, float b) {
    return ((floatBitsToUint(a) ^ floatBitsToUint(b)) & 0x80000000u) == 0u;
}

// Twice the signed area of (a, b, c), measured from a.
float signed_area(vec2 a, vec2 b, vec2 c) {
    precise float s = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
    return s;
}

// na/da > nb/db by cross-multiplication, flipped when the denominators' signs differ.
bool fraction_greater(float na, float da, float nb, float db) {
    precise float l = na * db;
    precise float r = nb * da;
    bool greater = l > r;
    return same_sign(da, db) ? greater : !greater;
}

// The record (α bits, info) of the pair from pixel i = (x, y) of item b to its right neighbour
// (vertical false) or its next-row neighbour (true).
uvec2 analyse_pair(uint i, uint b, uint x, uint y, bool vertical) {
    uint i1 = i + (vertical ? pc.width : 1u);
    vec4 r0 = rast[i];
    vec4 r1 = rast[i1];
    if (r0.w == r1.w) {
        return uvec2(0u);
    }
    bool has0 = r0.w >= 1.0;
    bool has1 = r1.w >= 1.0;
    if (!has0 && !has1) {
        return uvec2(0u);
    }
    bool second = (has0 && has1) ? !(r0.z < r1.z) : has1;
    float id = second ? r1.w : r0.w;
    if (!(id <= float(pc.tri_count))) {
        return uvec2(0u);
    }
    uint t = uint(id) - 1u;
    uint cx = x + ((second && !vertical) ? 1u : 0u);
    uint cy = y + ((second && vertical) ? 1u : 0u);
    vec2 q[3];
    for (uint k = 0u; k < 3u; ++k) {
        q[k] = aa_frame(aa_vertex(b, tri[3u * t + k]), cx, cy);
    }
    // Silhouette test per edge, before the swap.
    float own = signed_area(q[0], q[1], q[2]);
    bool silhouette[3];
    for (uint k = 0u; k < 3u; ++k) {
        uint o = opposites[3u * t + k];
        bool sil = true;
        if (o != AA_NO_VERTEX) {
            vec2 qo = aa_frame(aa_vertex(b, o), cx, cy);
            sil = same_sign(signed_area(qo, q[(k + 1u) % 3u], q[(k + 2u) % 3u]), own);
        }
        silhouette[k] = sil;
    }
    if (vertical) {
        for (uint k = 0u; k < 3u; ++k) {
            q[k] = q[k].yx;
        }
    }
    float sigma = second ? -1.0 : 1.0;
    bool straddles[3];
    float num[3];
    float den[3];
    float along[3];
    for (uint k = 0u; k < 3u; ++k) {
        vec2 a = q[(k + 1u) % 3u];
        vec2 e = q[(k + 2u) % 3u];
        straddles[k] = !same_sign(a.y, e.y);
        precise float n = sigma * (a.x * (e.y - a.y) - a.y * (e.x - a.x));
        precise float d = e.y - a.y;
        precise float l = e.x - a.x;
        num[k] = n;
        den[k] = d;
        along[k] = l;
    }
    // Edge m's crossing lies farther toward the other pixel than edge n's.
    bool b20 = straddles[2] && (!straddles[0] || fraction_greater(num[2], den[2], num[0], den[0]));
    bool b21 = straddles[2] && (!straddles[1] || fraction_greater(num[2], den[2], num[1], den[1]));
    bool b10 = straddles[1] && (!straddles[0] || fraction_greater(num[1], den[1], num[0], den[0]));
    uint k = (b20 && b21) ? 2u : (b10 ? 1u : 0u);
    if (!straddles[k] || !silhouette[k] || abs(den[k]) < abs(along[k])) {
        return uvec2(0u);
    }
    float reach = fm_div_rn(num[k], den[k]);
    if (!(reach > -0.0625 && reach < 1.0625)) {
        return uvec2(0u);
    }
    precise float alpha = sigma * (0.5 - clamp(reach, 0.0, 1.0));
    uint info = 1u | (second ? 2u : 0u) | (k << 2);
    return uvec2(floatBitsToUint(alpha), info);
}

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (i >= pc.batch * pixels) {
        return;
    }
    uint b = i / pixels;
    uint p = i - b * pixels;
    uint y = p / pc.width;
    uint x = p - y * pc.width;
    uvec2 right = x + 1u < pc.width ? analyse_pair(i, b, x, y, false) : uvec2(0u);
    uvec2 up = y + 1u < pc.height ? analyse_pair(i, b, x, y, true) : uvec2(0u);
    pairs[i] = uvec4(right, up);
}
