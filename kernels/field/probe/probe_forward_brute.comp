#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, forward, brute force: one invocation per ray over every anchor valid in its
// view, in index order (in passes over consecutive anchors where the driver's loop cap asks:
// `CARRY` in probe_forward.glsl). The baseline the tiled pass (`probe_forward.comp`) must equal bit for
// bit. Twin: `probe::prober::cpu::forward`.
#define CARRY_BINDING 6
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 1) readonly buffer Views { ProbeView views[]; };
layout(std430, set = 0, binding = 2) readonly buffer Anchors { vec4 anchors[]; };
layout(std430, set = 0, binding = 3) readonly buffer Phi { float phi[]; };
layout(std430, set = 0, binding = 4) readonly buffer Items { ProbeItem items[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Outs { RayOut outs[]; };

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
    float bound = hit_bound(d, ray_tau2(r.label, pc.tau2, pc.tau2_outside));
    uint item_base = r.view * pc.anchors;
    // This pass's anchors (all of them without CARRY).
    uint begin = CARRY != 0u ? pc.pass_begin : 0u;
    uint end = CARRY != 0u ? min(pc.pass_end, pc.anchors) : pc.anchors;
    Agg g = begin > 0u ? carry_load(id) : agg_init(MODE);
    for (uint anchor = begin; anchor < end; ++anchor) {
        uint flags = items[item_base + anchor].flags;
        if ((flags & FLAG_VALID) == 0u || !assigned(r.label, flags)) {
            continue;
        }
        if (ray_hits(o, d, bound, anchors[anchor].xyz)) {
            agg_add(g, MODE, pc.inv_t, phi[anchor], anchor);
        }
    }
    if (end < pc.anchors) {
        carry_store(g, id);
    } else {
        outs[id] = agg_finish(g, MODE, pc.temperature, r.label);
    }
}
