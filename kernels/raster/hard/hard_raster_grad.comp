#version 460
#extension GL_GOOGLE_include_directive : require
// The rasterizer's backward, the slot kernel (`hard_grads.glsl`): per (item, tile) slot, the sum
// in pixel order over the tile's pixels that show the item of the gradient of
// dy·(u, v) + ddb·rast_db to the triangle's corners (x, y, 0, w each: z/w and the id carry
// none), the reverse of `hard_shade.comp`'s arithmetic (clamps pass nothing where they bind).
// `pc.diff_count` = 1: ddb is given. Twin: `reference::rasterize_grad` (dual numbers).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Pos { float pos[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
layout(std430, set = 0, binding = 2) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, set = 0, binding = 3) readonly buffer Rast { vec4 rast[]; };
layout(std430, set = 0, binding = 4) readonly buffer Dy { vec4 dy[]; };
layout(std430, set = 0, binding = 5) readonly buffer Ddb { vec4 ddb[]; };
layout(std430, set = 0, binding = 6) readonly buffer Boxes { uint boxes[]; };
layout(std430, set = 0, binding = 7) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 8) writeonly buffer Partials { float partials[]; };

#define HARD_GRADS_SLOTS
#include "hard.glsl"
#include "hard_grads.glsl"

// Adds the gradient of gu·u + gv·v + gdb·rast_db at NDC f to the corners' g0, g1, g2.
void shade_adjoint(vec4 p0, vec4 p1, vec4 p2, vec2 f, float gu, float gv, vec4 gdb,
                   inout vec4 g0, inout vec4 g1, inout vec4 g2) {
    vec4 p[3] = vec4[3](p0, p1, p2);
    precise vec2 r[3];
    for (int k = 0; k < 3; ++k) {
        r[k] = vec2(p[k].x - f.x * p[k].w, p[k].y - f.y * p[k].w);
    }
    vec3 a = edge_areas(p0, p1, p2, f);
    precise float at = a.x + a.y + a.z;
    float iw = fm_rcp(at);
    precise float b0 = a.x * iw;
    precise float b1 = a.y * iw;
    bool m0 = b0 >= 0.0 && b0 <= 1.0;
    bool m1 = b1 >= 0.0 && b1 <= 1.0;
    float c0 = clamp(b0, 0.0, 1.0);
    float c1 = clamp(b1, 0.0, 1.0);
    precise float s = c0 + c1;
    bool big = s > 1.0;
    float sc = big ? fm_rcp(s) : 1.0;
    precise float u = c0 * sc;
    precise float v = c1 * sc;
    // D_k = ∂a_k/∂f for (i, j) = (1, 2), (2, 0), (0, 1).
    const ivec2 pairs[3] = ivec2[3](ivec2(1, 2), ivec2(2, 0), ivec2(0, 1));
    precise vec2 d[3];
    for (int k = 0; k < 3; ++k) {
        vec4 pi = p[pairs[k].x];
        vec4 pj = p[pairs[k].y];
        d[k] = vec2(pi.y * pj.w - pi.w * pj.y, pi.w * pj.x - pi.x * pj.w);
    }
    precise vec2 dt = d[0] + d[1] + d[2];
    precise float sx = pc.ndc_dx * iw;
    precise float sy = pc.ndc_dy * iw;
    // Reverse of rast_db = (sx (D0.x − u T.x), sy (D0.y − u T.y), sx (D1.x − v T.x), sy (D1.y − v T.y)).
    precise float gsx = gdb.x * (d[0].x - u * dt.x) + gdb.z * (d[1].x - v * dt.x);
    precise float gsy = gdb.y * (d[0].y - u * dt.y) + gdb.w * (d[1].y - v * dt.y);
    precise vec2 gd[3];
    precise vec2 gt = vec2(-(gdb.x * sx * u + gdb.z * sx * v), -(gdb.y * sy * u + gdb.w * sy * v));
    gd[0] = vec2(gdb.x * sx, gdb.y * sy) + gt;
    gd[1] = vec2(gdb.z * sx, gdb.w * sy) + gt;
    gd[2] = gt;
    precise float gu2 = gu - (gdb.x * sx * dt.x + gdb.y * sy * dt.y);
    precise float gv2 = gv - (gdb.z * sx * dt.x + gdb.w * sy * dt.y);
    precise float giw = pc.ndc_dx * gsx + pc.ndc_dy * gsy;
    // (u, v) from the clamped c0, c1.
    precise float gc0 = gu2;
    precise float gc1 = gv2;
    if (big) {
        precise float gs = -(gu2 * c0 + gv2 * c1) * sc * sc;
        gc0 = gu2 * sc + gs;
        gc1 = gv2 * sc + gs;
    }
    precise float gb0 = m0 ? gc0 : 0.0;
    precise float gb1 = m1 ? gc1 : 0.0;
    giw += gb0 * a.x + gb1 * a.y;
    precise float gat = -giw * iw * iw;
    precise vec3 ga = vec3(gb0 * iw + gat, gb1 * iw + gat, gat);
    // a_k = r_i × r_j.
    precise vec2 gr[3] = vec2[3](vec2(0.0), vec2(0.0), vec2(0.0));
    for (int k = 0; k < 3; ++k) {
        int i = pairs[k].x;
        int j = pairs[k].y;
        gr[i] += ga[k] * vec2(r[j].y, -r[j].x);
        gr[j] += ga[k] * vec2(-r[i].y, r[i].x);
    }
    precise vec4 g[3] = vec4[3](vec4(0.0), vec4(0.0), vec4(0.0));
    for (int k = 0; k < 3; ++k) {
        g[k] += vec4(gr[k].x, gr[k].y, 0.0, -(f.x * gr[k].x + f.y * gr[k].y));
    }
    // D_k = (y_i w_j − w_i y_j, w_i x_j − x_i w_j).
    for (int k = 0; k < 3; ++k) {
        int i = pairs[k].x;
        int j = pairs[k].y;
        vec4 pi = p[i];
        vec4 pj = p[j];
        g[i] += vec4(-gd[k].y * pj.w, gd[k].x * pj.w, 0.0, -gd[k].x * pj.y + gd[k].y * pj.x);
        g[j] += vec4(gd[k].y * pi.w, -gd[k].x * pi.w, 0.0, gd[k].x * pi.y - gd[k].y * pi.x);
    }
    g0 += g[0];
    g1 += g[1];
    g2 += g[2];
}

void main() {
    uint slot = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (slot >= pc.slots) {
        return;
    }
    uvec3 st = slot_tile(slot);
    uint item = st.x;
    uint b = item / pc.items_per_view;
    uint t = ranges[b].x + (item - b * pc.items_per_view);
    vec4 p0 = corner(b, t, 0u);
    vec4 p1 = corner(b, t, 1u);
    vec4 p2 = corner(b, t, 2u);
    precise vec4 g0 = vec4(0.0);
    precise vec4 g1 = vec4(0.0);
    precise vec4 g2 = vec4(0.0);
    uint x0 = 8u * st.y;
    uint y0 = 8u * st.z;
    for (uint y = y0; y < min(y0 + 8u, pc.height); ++y) {
        for (uint x = x0; x < min(x0 + 8u, pc.width); ++x) {
            uint i = (b * pc.height + y) * pc.width + x;
            uint tt;
            if (pixel_item(i, rast[i].w, tt) != item) {
                continue;
            }
            vec4 up = dy[i];
            vec4 gdb = pc.diff_count != 0u ? ddb[i] : vec4(0.0);
            shade_adjoint(p0, p1, p2, pixel_ndc(x, y), up.x, up.y, gdb, g0, g1, g2);
        }
    }
    uint o = slot * 12u;
    for (int c = 0; c < 4; ++c) {
        partials[o + uint(c)] = g0[c];
        partials[o + 4u + uint(c)] = g1[c];
        partials[o + 8u + uint(c)] = g2[c];
    }
}
