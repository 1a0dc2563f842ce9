// nvdiffrast's primitives (`softvk::raster::hard`), what their kernels share: the push
// constants, the pixel grid (row 0 at the bottom, centres at NDC ((2x + 1)/W − 1, (2y + 1)/H − 1)),
// reading clip-space corners, and the per-pixel arithmetic of `reference::shade`, in f32 on
// softvk's maths, every intermediate `precise`. Twin: `src/raster/hard/reference/` (f64).
#ifndef SOFTVK_HARD_GLSL
#define SOFTVK_HARD_GLSL

// Twin of `HardPush` (src/raster/hard/gpu.rs); every kernel of the family takes it.
layout(push_constant) uniform Push {
    uint width;           // W, H: the image
    uint height;
    uint batch;           // B: minibatch items
    uint tri_count;       // T
    uint vertex_count;    // V (per item when instanced)
    uint items_per_view;  // rasterizer items per minibatch item (T, or the longest range)
    uint instanced;       // 1: pos [B, V, 4]; 0: pos [V, 4] with ranges
    uint peel;            // 1: the previous layer's keys bound the search (hard_depth's PEEL)
    uint tiles_x;         // 8-pixel tiles
    uint tiles_y;
    uint pass_begin;      // depth: this pass's part [pass_begin, pass_end) of each tile's run
    uint pass_end;
    float box_scale;      // 1 / (8 min(W, H)): snapped units to the binning's coordinates
    float ndc_dx;         // 2 / W and 2 / H (f64 on the host, rounded once)
    float ndc_dy;
    uint rows;            // gradients: output rows (vertex sets × V)
    uint slots;           // gradients: (item, tile) slots
    uint dims;            // gradients: floats per item (3 corners × per-vertex floats)
    uint attr_count;      // interpolate: A
    uint diff_count;      // interpolate: N differentiated attributes
    uint grow;            // gradients: pixels a visible box is widened by
    uint channels;        // antialias: C
    uint items;           // gradients: items (B × items per view)
    uint pad0;
} pc;

// A rasterizer item (one per (minibatch item, triangle slot)): the binning's box and flag (words
// 0–4), the triangle (5), how its coverage is tested (6), its edges' fill-rule bits (7), its
// snapped corners (8–13) and, snapped, its depth plane z/w = C + A x + B y in NDC (14–16: A, B,
// C). Twin: `ITEM_WORDS` in gpu.rs.
const uint ITEM_WORDS = 20u;
const uint ITEM_BINNED = 1u;
const uint MODE_SNAPPED = 0u;     // integer edge functions on corners snapped to 1/16 pixel
const uint MODE_HOMOGENEOUS = 1u; // homogeneous edge functions, w > 0 and |z/w| <= 1

// Sub-pixel units a snapped coordinate may reach from the viewport centre (`SNAP_LIMIT`).
const float SNAP_LIMIT = 2097152.0; // 2^21

// Pixel (x, y)'s centre in NDC.
vec2 pixel_ndc(uint x, uint y) {
    precise float fx = fm_div_rn(float(2u * x + 1u), float(pc.width)) - 1.0;
    precise float fy = fm_div_rn(float(2u * y + 1u), float(pc.height)) - 1.0;
    return vec2(fx, fy);
}

// a·b − c·d exactly, as the high word and low word of a two's-complement 64-bit integer.
void mul_sub64(int a, int b, int c, int d, out int hi, out uint lo) {
    int h1;
    int l1;
    int h2;
    int l2;
    imulExtended(a, b, h1, l1);
    imulExtended(c, d, h2, l2);
    uint borrow;
    lo = usubBorrow(uint(l1), uint(l2), borrow);
    hi = h1 - h2 - int(borrow);
}

// A 64-bit integer clamped to [−2^30, 2^30].
int saturate64(int hi, uint lo) {
    if (hi > 0 || (hi == 0 && lo >= 0x40000000u)) {
        return 0x40000000;
    }
    if (hi < -1 || (hi == -1 && lo < 0xC0000000u)) {
        return -0x40000000;
    }
    return int(lo);
}

#ifndef HARD_NO_POSITIONS
// Corner k of triangle t of minibatch item b, in clip space.
vec4 corner(uint b, uint t, uint k) {
    uint v = tri[3u * t + k];
    if (pc.instanced != 0u) {
        v += b * pc.vertex_count;
    }
    return vec4(pos[4u * v], pos[4u * v + 1u], pos[4u * v + 2u], pos[4u * v + 3u]);
}
#endif

// The homogeneous edge functions of the pixel centre f: a_0 = p_1' × p_2', a_1 = p_2' × p_0',
// a_2 = p_0' × p_1' with p_k' = (x_k − f_x w_k, y_k − f_y w_k).
vec3 edge_areas(vec4 p0, vec4 p1, vec4 p2, vec2 f) {
    precise vec2 r0 = vec2(p0.x - f.x * p0.w, p0.y - f.y * p0.w);
    precise vec2 r1 = vec2(p1.x - f.x * p1.w, p1.y - f.y * p1.w);
    precise vec2 r2 = vec2(p2.x - f.x * p2.w, p2.y - f.y * p2.w);
    precise float a0 = r1.x * r2.y - r1.y * r2.x;
    precise float a1 = r2.x * r0.y - r2.y * r0.x;
    precise float a2 = r0.x * r1.y - r0.y * r1.x;
    return vec3(a0, a1, a2);
}

// Σ z_k a_k and Σ w_k a_k, in that order of terms.
vec2 depth_sums(vec4 p0, vec4 p1, vec4 p2, vec3 a) {
    precise float z = p0.z * a.x + p1.z * a.y + p2.z * a.z;
    precise float w = p0.w * a.x + p1.w * a.y + p2.w * a.z;
    return vec2(z, w);
}

// The homogeneous coverage test (`reference::homogeneous_covers`).
bool homogeneous_covers(vec3 a, vec2 zw_sums) {
    precise float at = a.x + a.y + a.z;
    precise float s0 = a.x * at;
    precise float s1 = a.y * at;
    precise float s2 = a.z * at;
    precise float sw = zw_sums.y * at;
    return at != 0.0 && s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0 && sw > 0.0
        && abs(zw_sums.x) <= abs(zw_sums.y);
}

#endif
