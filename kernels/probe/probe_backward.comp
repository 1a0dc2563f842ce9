#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, backward, step 2: one invocation per binned (anchor, tile) entry. It visits
// the rays of its tile in ray order and sums (ψ − S) dψ/dφ_j over those that used anchor j in
// the forward: max: the rays whose ψ came from j; LSE and union: the rays that hit j (the same
// `precise` hit test and assignment as the forward, so the same decisions). Every ray that
// reached j lies in one tile j was binned to, so each (ray, anchor) pair is counted once. The
// sum lands at the entry's item-major slot; `probe_reduce.comp` then adds each anchor's slots
// in a fixed order. No atomics. Twin: `probe::prober::cpu::backward`.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) readonly buffer Entries { uint entries[]; };
layout(std430, set = 0, binding = 2) readonly buffer EntryItems { uint entry_items[]; };
layout(std430, set = 0, binding = 3) readonly buffer Items { ProbeItem items[]; };
layout(std430, set = 0, binding = 4) readonly buffer Anchors { vec4 anchors[]; };
layout(std430, set = 0, binding = 5) readonly buffer Phi { float phi[]; };
layout(std430, set = 0, binding = 6) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 7) readonly buffer Views { ProbeView views[]; };
layout(std430, set = 0, binding = 8) readonly buffer Outs { RayOut outs[]; };
// Ray indices sorted by tile, and each tile's [start, end) in them.
layout(std430, set = 0, binding = 9) readonly buffer RayOrder { uint ray_order[]; };
layout(std430, set = 0, binding = 10) readonly buffer RayRanges { uvec2 ray_ranges[]; };
layout(std430, set = 0, binding = 11) writeonly buffer Partials { float partials[]; };

// Twin of `BackwardPush` (src/probe/prober.rs).
layout(push_constant) uniform Push {
    uint entries;        // binned (anchor, tile) entries
    uint anchors;
    uint width;
    uint height;
    uint tiles_x;
    uint tiles_y;
    uint mode;           // AGG_*
    uint boundary_aware;
    float inv_s;
    float tau2;
    float inv_t;
    float pad0;
} pc;

void main() {
    uint e = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (e >= pc.entries) {
        return;
    }
    uint tile = keys[e].x;
    uint slot = entries[e];
    uint anchor = entry_items[slot];
    uint view = tile / (pc.tiles_x * pc.tiles_y);
    uint flags = items[view * pc.anchors + anchor].flags;
    bool anchor_inside = (flags & FLAG_INSIDE) != 0u;
    vec3 p = anchors[anchor].xyz;
    float phi_j = phi[anchor];
    ProbeView v = views[view];
    uvec2 range = ray_ranges[tile];
    float sum = 0.0;
    for (uint q = range.x; q < range.y; ++q) {
        uint ray = ray_order[q];
        RayOut ro = outs[ray];
        Ray r = rays[ray];
        if (pc.mode == AGG_MAX) {
            if (ro.aux == anchor) {
                sum += ro.psi - r.label;
            }
            continue;
        }
        if (pc.boundary_aware != 0u && (r.label >= 0.5) != anchor_inside) {
            continue;
        }
        vec3 o;
        vec3 d;
        view_ray(v, pixel_to_screen(r.px, r.py, float(pc.width), float(pc.height), pc.inv_s), o, d);
        if (ray_hits(o, d, hit_bound(d, pc.tau2), p)) {
            sum += (ro.psi - r.label) * agg_grad(ro, pc.mode, pc.inv_t, phi_j);
        }
    }
    partials[slot] = sum;
}
