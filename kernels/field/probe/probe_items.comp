#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing: every anchor in every view as a binning item (`ProbeItem` of probe.glsl), one
// invocation per (view, anchor), view-major. The screen box holds the projection of the anchor's
// sphere, so binning by it loses no ray that can hit the sphere: the sphere's own extent on each
// screen axis (`sphere_extent`) within the box of the projected corners of its τ-cube (a
// projective map sends the cube to the hull of its corners when they are all in front of the
// camera; the corner box alone is up to √3 wider, and every tile it adds costs the binning, the
// list and the forward an entry). FLAG_VALID: all corners in front (depth and the projection's
// denominator positive); an anchor reaching behind the camera is not probed in that view.
// FLAG_INSIDE: the pixel holding the centre's projection is inside the silhouette (pixels
// outside the image are outside). Twin: `probe::prober::cpu::items`.
//
// It also bins the item (binning step 1, in place of the generic binning's count, scatter and
// sort): an item the binning would keep (FLAG_VALID, a tile rectangle: `tile_rect`, the generic
// binning's own) sets its anchor's bit in the anchor mask of every tile of its rectangle: tile
// t's anchors are the set bits of words `[t W, (t + 1) W)`, W = ⌈anchors / 32⌉, lowest first
// in anchor order (`bin_mask_counts.comp` and `probe_mask_list.comp` list them). The
// rectangle is also written (packed, all ones when the item is not binned) for the gradient sum
// (`probe_reduce.comp`). Integer `atomicOr`: the result does not depend on the order of the
// writes.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

// The views (`ProbeView`, ten texels each) and the anchors (one texel each) as texel buffers of
// the same bytes: on llvmpipe a storage-buffer load is a scalar loop over the lanes with a
// bounds-check branch per component (sixteen components of a view here), a texel fetch one
// branch-free gather of a whole texel.
layout(set = 0, binding = 0, rgba32ui) uniform readonly restrict uimageBuffer views;
layout(set = 0, binding = 1, rgba32ui) uniform readonly restrict uimageBuffer anchors;
layout(std430, set = 0, binding = 2) readonly buffer Masks { float masks[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Items { ProbeItem items[]; };
// Per tile, a bit per anchor; zero before this kernel.
layout(std430, set = 0, binding = 4) buffer TileMasks { uint tile_masks[]; };
// Per item: (x0 | x1 << 16, y0 | y1 << 16) of its tile rectangle, or all ones.
layout(std430, set = 0, binding = 5) writeonly buffer Rects { uvec2 rects[]; };

// Twin of `ItemsPush` (src/probe/prober/).
layout(push_constant) uniform Push {
    uint anchors;
    uint views;
    uint width;
    uint height;
    float tau;
    uint tile_size;
    uint tiles_x;
    uint tiles_y;
} pc;

#define BINNING_TILE_RECT_ONLY
#include "binning.glsl"

// The extent [lo, hi] of screen coordinate s = affine(a, p) / affine(a2, p) over the sphere
// |p − c| ≤ τ: the planes s = const tangent to the sphere, (A − s B)² = τ² |u − s w|² with
// A = affine(a, c), B = affine(a2, c), u = a.xyz, w = a2.xyz, a quadratic
// qa s² − 2 qb s + qc = 0 whose discriminant is τ² (|A w − B u|² − τ² |u × w|²), written that
// way against cancellation. False where the sphere reaches the plane B = 0 (qa ≤ 0) or
// rounding leaves no real roots: the caller keeps the corner box. `precise` throughout: the twin
// (`probe::prober::cpu::sphere_extent`) repeats every rounding. Rounding moves the ends by a few
// ulps; tile_rect widens every box by a pixel.
bool sphere_extent(vec4 a, vec4 a2, vec3 c, float tau, out vec2 ext) {
    precise float A = affine(a, c);
    precise float B = affine(a2, c);
    vec3 u = a.xyz;
    vec3 w = a2.xyz;
    precise float tau2 = tau * tau;
    precise float qa = B * B - tau2 * (w.x * w.x + w.y * w.y + w.z * w.z);
    precise float qb = A * B - tau2 * (u.x * w.x + u.y * w.y + u.z * w.z);
    precise vec3 v = A * w - B * u;
    precise vec3 x = vec3(u.y * w.z - u.z * w.y, u.z * w.x - u.x * w.z, u.x * w.y - u.y * w.x);
    precise float disc = tau2 * ((v.x * v.x + v.y * v.y + v.z * v.z)
                                 - tau2 * (x.x * x.x + x.y * x.y + x.z * x.z));
    ext = vec2(0.0);
    if (!(qa > 0.0 && disc >= 0.0)) {
        return false;
    }
    precise float r = fm_sqrt(disc);
    precise float lo = fm_div(qb - r, qa);
    precise float hi = fm_div(qb + r, qa);
    ext = vec2(lo, hi);
    return true;
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.anchors * pc.views) {
        return;
    }
    uint view = id / pc.anchors;
    uint anchor = id - view * pc.anchors;
    ProbeView v;
    int vt = int(view * PROBE_VIEW_TEXELS);
    v.a0 = uintBitsToFloat(imageLoad(views, vt));
    v.a1 = uintBitsToFloat(imageLoad(views, vt + 1));
    v.a2 = uintBitsToFloat(imageLoad(views, vt + 2));
    v.depth = uintBitsToFloat(imageLoad(views, vt + 3));
    vec3 p = uintBitsToFloat(imageLoad(anchors, int(anchor)).xyz);

    bool valid = true;
    vec4 box = vec4(1e30, 1e30, -1e30, -1e30);
    for (uint c = 0u; c < 8u; ++c) {
        vec3 sign = vec3((c & 1u) != 0u ? 1.0 : -1.0, (c & 2u) != 0u ? 1.0 : -1.0,
                         (c & 4u) != 0u ? 1.0 : -1.0);
        precise vec3 corner = p + pc.tau * sign;
        float den = affine(v.a2, corner);
        valid = valid && affine(v.depth, corner) > 0.0 && den > 0.0;
        vec2 s = fm_div2(vec2(affine(v.a0, corner), affine(v.a1, corner)), den);
        box = vec4(min(box.xy, s), max(box.zw, s));
    }

    vec2 ex;
    vec2 ey;
    if (sphere_extent(v.a0, v.a2, p, pc.tau, ex) && sphere_extent(v.a1, v.a2, p, pc.tau, ey)) {
        box = vec4(max(box.xy, vec2(ex.x, ey.x)), min(box.zw, vec2(ex.y, ey.y)));
    }
    float w = float(pc.width);
    float h = float(pc.height);
    float smin = min(w, h);
    float den = affine(v.a2, p);
    float sx = fm_div(affine(v.a0, p), den);
    float sy = fm_div(affine(v.a1, p), den);
    // The pixel whose centre is nearest: c = floor((x S + W) / 2), r = floor((H − y S) / 2).
    precise float fc = floor((sx * smin + w) * 0.5);
    precise float fr = floor((h - sy * smin) * 0.5);
    bool inside = false;
    if (den > 0.0 && fc >= 0.0 && fc < w && fr >= 0.0 && fr < h) {
        inside = masks[view * pc.width * pc.height + uint(fr) * pc.width + uint(fc)] >= 0.5;
    }
    uint flags = (valid ? FLAG_VALID : 0u) | (inside ? FLAG_INSIDE : 0u);
    items[id] = ProbeItem(box, flags, sx, sy, affine(v.depth, p));

    uvec4 rect;
    if (!(valid && tile_rect(box, rect))) {
        rects[id] = uvec2(0xFFFFFFFFu);
        return;
    }
    rects[id] = uvec2(rect.x | (rect.z << 16u), rect.y | (rect.w << 16u));
    uint words = (pc.anchors + 31u) / 32u;
    uint tile_base = view * pc.tiles_x * pc.tiles_y;
    uint bit = 1u << (anchor & 31u);
    for (uint ty = rect.y; ty <= rect.w; ++ty) {
        for (uint tx = rect.x; tx <= rect.z; ++tx) {
            atomicOr(tile_masks[(tile_base + ty * pc.tiles_x + tx) * words + anchor / 32u], bit);
        }
    }
}
