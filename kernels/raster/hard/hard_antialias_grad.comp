#version 460
#extension GL_GOOGLE_include_directive : require
// nvdiffrast's `antialias` backward, the slot kernel (`hard_grads.glsl`, boxes widened by one
// pixel: a pair's pixel 0 may lie one left of or below the pixels that show its triangle): per
// (item, tile) slot, over the tile's pixels in pixel order (rows from the bottom, columns left to
// right), each pixel's right pair then its next-row pair from the work list
// (`hard_antialias_pairs.comp`) whose triangle is the slot's item, the gradient of the loss to the
// triangle's corners (x, y, 0, w each; 12 floats a slot), the edge's start vertex before its end.
// A pair counts unless α is +0.0, |α| ≥ 1/2 (r clamped) or dL/dα = Σ_ch dy[target]·(color[pixel
// 1] − color[pixel 0]) (channel order) is 0; then with dL/dx_c = −dL/dα, x_c = (a_x Δy −
// a_y Δx)·inv and inv = 1/(Δy + 10⁻³·sign Δy) (in the pair's frame, x and y swapped for a
// next-row pair), the derivatives of x_c to the edge's ends, chained through the projection
// x = X·(1/W_c)·W/2 + …, y likewise, to X, Y and W_c. Twin: `antialias::antialias_backward`
// (positions; `pos_gradient_boost` is applied after the gather, `hard_antialias_scale.comp`).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Pos { float pos[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
layout(std430, set = 0, binding = 2) readonly buffer Rast { vec4 rast[]; };
layout(std430, set = 0, binding = 3) readonly buffer Color { float color[]; };
layout(std430, set = 0, binding = 4) readonly buffer Dy { float dy[]; };
layout(std430, set = 0, binding = 5) readonly buffer Pairs { uvec4 pairs[]; };
layout(std430, set = 0, binding = 6) readonly buffer Boxes { uint boxes[]; };
layout(std430, set = 0, binding = 7) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 8) writeonly buffer Partials { float partials[]; };

#define HARD_GRADS_SLOTS
#define HARD_GRADS_NO_RANGES
#include "hard.glsl"
#include "hard_grads.glsl"
#include "hard_antialias.glsl"

// nvdiffrast's guard on 1/Δy (`GRADIENT_DY_EPSILON`, pixels).
const float DY_EPSILON = 1e-3;

// The gradient g (pixel frame) of corner p, chained to its clip (x, y, 0, w).
vec4 clip_gradient(vec4 p, vec2 g) {
    precise float hx = 0.5 * float(pc.width);
    precise float hy = 0.5 * float(pc.height);
    float inv_w = fm_div_rn(1.0, p.w);
    precise float gx = (g.x * hx) * inv_w;
    precise float gy = (g.y * hy) * inv_w;
    precise float gw = -((p.x * gx + p.y * gy) * inv_w);
    return vec4(gx, gy, 0.0, gw);
}

void main() {
    uint slot = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (slot >= pc.slots) {
        return;
    }
    uvec3 st = slot_tile(slot);
    uint item = st.x;
    uint b = item / pc.items_per_view;
    // Every minibatch item's range is all the triangles: the item's slot is its triangle.
    uint t = item - b * pc.items_per_view;
    vec4 p[3];
    for (uint k = 0u; k < 3u; ++k) {
        p[k] = corner(b, t, k);
    }
    precise vec4 g[3] = vec4[3](vec4(0.0), vec4(0.0), vec4(0.0));
    uint x0 = 8u * st.y;
    uint y0 = 8u * st.z;
    for (uint y = y0; y < min(y0 + 8u, pc.height); ++y) {
        for (uint x = x0; x < min(x0 + 8u, pc.width); ++x) {
            uint i = (b * pc.height + y) * pc.width + x;
            uvec4 rec = pairs[i];
            for (uint dir = 0u; dir < 2u; ++dir) {
                bool vertical = dir == 1u;
                uvec2 r = vertical ? rec.zw : rec.xy;
                if (!aa_blended(r.y) || r.x == 0u) {
                    continue;
                }
                bool second = aa_from_second(r.y);
                uint i1 = i + (vertical ? pc.width : 1u);
                if (uint(rast[second ? i1 : i].w) - 1u != t) {
                    continue;
                }
                float alpha = uintBitsToFloat(r.x);
                uint target = aa_targets_first(alpha) ? i : i1;
                precise float dl = 0.0;
                for (uint ch = 0u; ch < pc.channels; ++ch) {
                    precise float d = color[i1 * pc.channels + ch] - color[i * pc.channels + ch];
                    dl += dy[target * pc.channels + ch] * d;
                }
                if (dl == 0.0 || abs(alpha) >= 0.5) {
                    continue;
                }
                uint k = aa_edge(r.y);
                uint ia = (k + 1u) % 3u;
                uint ib = (k + 2u) % 3u;
                uint cx = x + ((second && !vertical) ? 1u : 0u);
                uint cy = y + ((second && vertical) ? 1u : 0u);
                vec2 a = aa_frame(p[ia], cx, cy);
                vec2 e = aa_frame(p[ib], cx, cy);
                if (vertical) {
                    a = a.yx;
                    e = e.yx;
                }
                precise float ex = e.x - a.x;
                precise float ey = e.y - a.y;
                bool negative = (floatBitsToUint(ey) & 0x80000000u) != 0u;
                precise float guarded = ey + (negative ? -DY_EPSILON : DY_EPSILON);
                float inv = fm_div_rn(1.0, guarded);
                precise float xc = (a.x * ey - a.y * ex) * inv;
                precise float gl = -dl;
                precise vec2 ga = vec2((gl * e.y) * inv, (gl * (xc - e.x)) * inv);
                precise vec2 gb = vec2(((-gl) * a.y) * inv, (gl * (a.x - xc)) * inv);
                if (vertical) {
                    ga = ga.yx;
                    gb = gb.yx;
                }
                g[ia] += clip_gradient(p[ia], ga);
                g[ib] += clip_gradient(p[ib], gb);
            }
        }
    }
    uint o = slot * 12u;
    for (uint k = 0u; k < 3u; ++k) {
        for (uint c = 0u; c < 4u; ++c) {
            partials[o + 4u * k + c] = g[k][c];
        }
    }
}
