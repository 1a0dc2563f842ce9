#version 460
#extension GL_GOOGLE_include_directive : require
// PyTorch3D's rasterizer backward, step 1: one invocation per (face, tile) entry of the
// forward's binning, at its item-major slot. It adds, pixel by pixel of the tile in row-major
// order, the gradient of the face's entry in that pixel's list (a face is in a list at most
// once) to the face's vertices, and writes the sum as the entry's partial; `frag_reduce.comp`
// adds each face's partials in slot order. No float atomics, a fixed order: deterministic.
//
// Per (pixel, face): PyTorch3D's `RasterizeMeshesBackwardCpu`, operation for operation: the
// `dists` gradient through the nearest edge's point-segment distance (the nearest point held
// fixed; sign flipped inside), the `zbuf` gradient to the clipped barycentrics (z_k) and to
// the depths (w̃_k), the barycentrics' through the clip and the perspective correction (which
// also reaches the depths) to the edge functions and the area.
//
// Loop iterations per invocation: the binary search for the slot's item (log2 of the items),
// then per pixel of the tile one, and one per list entry it reads (at most K + 1).
// Twin: `reference::rasterize_grad`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer FaceVerts { float face_verts[]; };
layout(std430, set = 0, binding = 1) readonly buffer Meshes { uvec2 meshes[]; };
layout(std430, set = 0, binding = 2) readonly buffer Items { float items[]; };
// The item-major exclusive offsets of the entries, then the total.
layout(std430, set = 0, binding = 3) readonly buffer Offsets { uint offsets[]; };
// [views, H, W, K] int64 as (low word, high word); only the low word is read.
layout(std430, set = 0, binding = 4) readonly buffer PixToFace { int pix_to_face[]; };
layout(std430, set = 0, binding = 5) readonly buffer GradZbuf { float grad_zbuf[]; };
layout(std430, set = 0, binding = 6) readonly buffer GradBary { float grad_bary[]; };
layout(std430, set = 0, binding = 7) readonly buffer GradDists { float grad_dists[]; };
// Nine floats per entry: the three vertices' (x, y, z).
layout(std430, set = 0, binding = 8) writeonly buffer Partials { float partials[]; };

#include "fragments.glsl"
#define BINNING_TILE_RECT_ONLY
#include "binning.glsl"

// `EdgeFunctionBackward`'s gradients to v0 and v1, times g.
void edge_back(vec2 p, vec2 v0, vec2 v1, float g, out vec2 d_v0, out vec2 d_v1) {
    precise vec2 a = vec2(g * (p.y - v1.y), g * (v1.x - p.x));
    precise vec2 b = vec2(g * (v0.y - p.y), g * (p.x - v0.x));
    d_v0 = a;
    d_v1 = b;
}

// `BarycentricCoordsBackward`: the upstream gradient of the barycentrics to the vertices.
void bary_backward(vec2 p, vec2 v0, vec2 v1, vec2 v2, vec3 g, out vec2 d0, out vec2 d1,
                   out vec2 d2) {
    precise float area = edge_fn(v2, v0, v1) + P3D_EPS;
    precise float area2 = area * area;
    precise float area_inv = fm_div_rn(1.0, area);
    precise float e0 = edge_fn(p, v1, v2);
    precise float e1 = edge_fn(p, v2, v0);
    precise float e2 = edge_fn(p, v0, v1);
    vec2 a;
    vec2 b;
    vec2 c;
    vec2 d;
    // w0 = e0(p, v1, v2) / area(v2, v0, v1).
    precise float g_area0 = g.x * fm_div_rn(-e0, area2);
    precise float g_e0 = g.x * area_inv;
    edge_back(p, v1, v2, g_e0, a, b);
    // area's gradients: EdgeFunctionBackward(v2, v0, v1) gives (d v2, d v0, d v1).
    precise vec2 ar2_0 = vec2(g_area0 * (v1.y - v0.y), g_area0 * (v0.x - v1.x));
    edge_back(v2, v0, v1, g_area0, c, d);
    precise vec2 dw0_v0 = c;
    precise vec2 dw0_v1 = a + d;
    precise vec2 dw0_v2 = b + ar2_0;
    // w1 = e1(p, v2, v0) / area.
    precise float g_area1 = g.y * fm_div_rn(-e1, area2);
    precise float g_e1 = g.y * area_inv;
    edge_back(p, v2, v0, g_e1, a, b);
    precise vec2 ar2_1 = vec2(g_area1 * (v1.y - v0.y), g_area1 * (v0.x - v1.x));
    edge_back(v2, v0, v1, g_area1, c, d);
    precise vec2 dw1_v0 = b + c;
    precise vec2 dw1_v1 = d;
    precise vec2 dw1_v2 = a + ar2_1;
    // w2 = e2(p, v0, v1) / area.
    precise float g_area2 = g.z * fm_div_rn(-e2, area2);
    precise float g_e2 = g.z * area_inv;
    edge_back(p, v0, v1, g_e2, a, b);
    precise vec2 ar2_2 = vec2(g_area2 * (v1.y - v0.y), g_area2 * (v0.x - v1.x));
    edge_back(v2, v0, v1, g_area2, c, d);
    precise vec2 dw2_v0 = a + c;
    precise vec2 dw2_v1 = b + d;
    precise vec2 dw2_v2 = ar2_2;
    precise vec2 s0 = dw0_v0 + dw1_v0 + dw2_v0;
    precise vec2 s1 = dw0_v1 + dw1_v1 + dw2_v1;
    precise vec2 s2 = dw0_v2 + dw1_v2 + dw2_v2;
    d0 = s0;
    d1 = s1;
    d2 = s2;
}

// `BarycentricPerspectiveCorrectionBackward`: to the uncorrected barycentrics and the depths.
void perspective_backward(vec3 b, vec3 z, vec3 g, out vec3 d_b, out vec3 d_z) {
    precise float t0 = b.x * z.y * z.z;
    precise float t1 = b.y * z.x * z.z;
    precise float t2 = b.z * z.x * z.y;
    precise float denom = max(t0 + t1 + t2, P3D_EPS);
    precise float g_denom_top = -t0 * g.x - t1 * g.y - t2 * g.z;
    precise float g_denom = fm_div_rn(g_denom_top, denom * denom);
    precise float g0 = g_denom + fm_div_rn(g.x, denom);
    precise float g1 = g_denom + fm_div_rn(g.y, denom);
    precise float g2 = g_denom + fm_div_rn(g.z, denom);
    precise vec3 db = vec3(g0 * z.y * z.z, g1 * z.x * z.z, g2 * z.x * z.y);
    precise vec3 dz = vec3(g1 * b.y * z.z + g2 * b.z * z.y, g0 * b.x * z.z + g2 * b.z * z.x,
                           g0 * b.x * z.y + g1 * b.y * z.x);
    d_b = db;
    d_z = dz;
}

// `BarycentricClipBackward`.
vec3 clip_backward(vec3 b, vec3 g) {
    precise vec3 w = max(b, vec3(0.0));
    precise float sum = w.x + w.y + w.z;
    float through_sum = 1.0;
    if (sum < 1e-5) {
        through_sum = 0.0;
        sum = 1e-5;
    }
    precise float sum2 = sum * sum;
    precise vec3 gs = vec3(fm_div_rn(-w.x, sum2) * through_sum, fm_div_rn(-w.y, sum2) * through_sum,
                           fm_div_rn(-w.z, sum2) * through_sum);
    precise float inv = fm_div_rn(1.0, sum);
    precise float gx = g.x * (inv + gs.x) + g.y * gs.y + g.z * gs.z;
    precise float gy = g.y * (inv + gs.y) + g.x * gs.x + g.z * gs.z;
    precise float gz = g.z * (inv + gs.z) + g.x * gs.x + g.y * gs.y;
    return vec3(b.x < 0.0 ? 0.0 : gx, b.y < 0.0 ? 0.0 : gy, b.z < 0.0 ? 0.0 : gz);
}

// `PointLineDistanceBackward`'s gradients to v0 and v1.
void segment_back(vec2 p, vec2 v0, vec2 v1, float g, out vec2 d_v0, out vec2 d_v1) {
    precise vec2 d = v1 - v0;
    precise vec2 pv = p - v0;
    precise float t = fm_div_rn(d.x * pv.x + d.y * pv.y, d.x * d.x + d.y * d.y);
    float tt = min(max(t, 0.0), 1.0);
    precise vec2 proj = (1.0 - tt) * v0 + tt * v1;
    precise vec2 r = proj - p;
    precise vec2 a = g * (1.0 - tt) * 2.0 * r;
    precise vec2 b = g * tt * 2.0 * r;
    d_v0 = a;
    d_v1 = b;
}

// `PointTriangleDistanceBackward`: through the nearest edge (ties: 01, then 02, then 12).
void dist_backward(vec2 p, vec2 v0, vec2 v1, vec2 v2, float g, out vec2 d0, out vec2 d1,
                   out vec2 d2) {
    vec3 e = edge_dists(p, v0, v1, v2);
    d0 = vec2(0.0);
    d1 = vec2(0.0);
    d2 = vec2(0.0);
    if (e.x <= e.y && e.x <= e.z) {
        segment_back(p, v0, v1, g, d0, d1);
    } else if (e.y <= e.x && e.y <= e.z) {
        segment_back(p, v0, v2, g, d0, d2);
    } else if (e.z <= e.x && e.z <= e.y) {
        segment_back(p, v1, v2, g, d1, d2);
    }
}

void main() {
    uint s = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (s >= pc.entries) {
        return;
    }
    // The item whose entries hold slot s: the last with offsets[item] <= s.
    uint items_total = pc.views * pc.items_per_view;
    uint lo = 0u;
    uint hi = items_total;
    while (hi - lo > 1u) {
        uint mid = (lo + hi) / 2u;
        if (offsets[mid] <= s) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    uint item = lo;
    uint view = item / pc.items_per_view;
    uint face = meshes[view].x + (item - view * pc.items_per_view);
    vec4 box = vec4(items[item * ITEM_WORDS], items[item * ITEM_WORDS + 1u],
                    items[item * ITEM_WORDS + 2u], items[item * ITEM_WORDS + 3u]);
    uvec4 pixels;
    pixel_rect(box, pixels); // binned, so the rectangle exists
    uvec4 rect = pixels / pc.tile_size;
    uint index = s - offsets[item];
    uint rw = rect.z - rect.x + 1u;
    uint ty = rect.y + index / rw;
    uint tx = rect.x + index - (index / rw) * rw;

    vec3 q0;
    vec3 q1;
    vec3 q2;
    load_face_verts(face, q0, q1, q2);
    vec2 v0 = q0.xy;
    vec2 v1 = q1.xy;
    vec2 v2 = q2.xy;
    vec3 z = vec3(q0.z, q1.z, q2.z);
    precise vec3 g0 = vec3(0.0);
    precise vec3 g1 = vec3(0.0);
    precise vec3 g2 = vec3(0.0);
    // The tile's pixels that the face's grown box can hold (binning's pixel rectangle): only
    // they can list the face.
    uint row_end = min((ty + 1u) * pc.tile_size, pixels.w + 1u);
    uint col_end = min((tx + 1u) * pc.tile_size, pixels.z + 1u);
    for (uint row = max(ty * pc.tile_size, pixels.y); row < row_end; ++row) {
        for (uint col = max(tx * pc.tile_size, pixels.x); col < col_end; ++col) {
            uint base = ((view * pc.height + row) * pc.width + col) * pc.k;
            uint slot = 0u;
            bool found = false;
            for (uint i = 0u; i < pc.k; ++i) {
                int f = pix_to_face[2u * (base + i)];
                if (f == int(face)) {
                    slot = base + i;
                    found = true;
                    break;
                }
                if (f < 0) {
                    break;
                }
            }
            if (!found) {
                continue;
            }
            vec2 p = frag_pixel(row, col);
            vec3 w0;
            vec3 w;
            vec3 w_clip;
            frag_barycentrics(p, q0, q1, q2, w0, w, w_clip);
            bool inside = w.x > 0.0 && w.y > 0.0 && w.z > 0.0;
            float sign = inside ? -1.0 : 1.0;
            vec2 dd0;
            vec2 dd1;
            vec2 dd2;
            dist_backward(p, v0, v1, v2, sign * grad_dists[slot], dd0, dd1, dd2);
            float gz = grad_zbuf[slot];
            vec3 gb = vec3(grad_bary[3u * slot], grad_bary[3u * slot + 1u],
                           grad_bary[3u * slot + 2u]);
            precise vec3 g = gb + gz * z;
            if ((pc.flags & FRAG_CLIP) != 0u) {
                g = clip_backward(w, g);
            }
            if ((pc.flags & FRAG_PERSPECTIVE) != 0u) {
                vec3 d_b;
                vec3 d_z;
                perspective_backward(w0, z, g, d_b, d_z);
                g = d_b;
                g0.z += d_z.x;
                g1.z += d_z.y;
                g2.z += d_z.z;
            }
            vec2 db0;
            vec2 db1;
            vec2 db2;
            bary_backward(p, v0, v1, v2, g, db0, db1, db2);
            g0 += vec3(db0 + dd0, gz * w_clip.x);
            g1 += vec3(db1 + dd1, gz * w_clip.y);
            g2 += vec3(db2 + dd2, gz * w_clip.z);
        }
    }
    uint o = 9u * s;
    partials[o] = g0.x;
    partials[o + 1u] = g0.y;
    partials[o + 2u] = g0.z;
    partials[o + 3u] = g1.x;
    partials[o + 4u] = g1.y;
    partials[o + 5u] = g1.z;
    partials[o + 6u] = g2.x;
    partials[o + 7u] = g2.y;
    partials[o + 8u] = g2.z;
}
