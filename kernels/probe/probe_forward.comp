#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, forward, tiled: one invocation per ray; ψ = G(φ of the anchors the ray passes
// within τ of), over the anchors binned to the ray's tile, in anchor order (the binning's stable
// sort keeps each tile's anchors in index order): the same hits in the same order as
// `probe_forward_brute.comp`, so the same ψ bit for bit. Anchors on the other side of the
// silhouette from the ray are skipped (boundary-aware assignment). Writes ψ, (ψ − S)² and the
// state the backward needs. Twin: `probe::prober::cpu::forward`.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 1) readonly buffer Views { ProbeView views[]; };
layout(std430, set = 0, binding = 2) readonly buffer Anchors { vec4 anchors[]; };
layout(std430, set = 0, binding = 3) readonly buffer Phi { float phi[]; };
layout(std430, set = 0, binding = 4) readonly buffer Items { ProbeItem items[]; };
layout(std430, set = 0, binding = 5) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, set = 0, binding = 6) readonly buffer Entries { uint entries[]; };
layout(std430, set = 0, binding = 7) readonly buffer EntryItems { uint entry_items[]; };
layout(std430, set = 0, binding = 8) writeonly buffer Outs { RayOut outs[]; };

#include "probe_forward.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.rays) {
        return;
    }
    Ray r = rays[id];
    vec3 o;
    vec3 d;
    view_ray(views[r.view],
             pixel_to_screen(r.px, r.py, float(pc.width), float(pc.height), pc.inv_s), o, d);
    float bound = hit_bound(d, pc.tau2);
    uint tile = ray_tile(r, pc.width, pc.height, pc.tile_size, pc.tiles_x, pc.tiles_y);
    uvec2 range = ranges[tile];
    uint item_base = r.view * pc.anchors;
    Agg g = agg_init(pc.mode);
    for (uint e = range.x; e < range.y; ++e) {
        uint anchor = entry_items[entries[e]];
        if (!assigned(r.label, items[item_base + anchor].flags)) {
            continue;
        }
        if (ray_hits(o, d, bound, anchors[anchor].xyz)) {
            agg_add(g, pc.mode, pc.inv_t, phi[anchor], anchor);
        }
    }
    outs[id] = agg_finish(g, pc.mode, pc.temperature, r.label);
}
