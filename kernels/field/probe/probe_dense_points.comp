#version 460
#extension GL_GOOGLE_include_directive : require
// The dense-marching baseline of sphere probing (the conventional way to render a ray's
// occupancy): the sample points of every ray, at a fixed step through the field's cube. One
// invocation per ray: the ray's line (as the prober builds it) is clipped to the cube, [t0, t1],
// and its count = ceil((t1 − t0) |d| / step) samples (counts and offsets come from the host) are
// written from the ray's offset at the centres of count equal parts of the chord, t0 + (k + 1/2)
// (t1 − t0) / count: at most `step` apart, all inside the cube. Twin:
// `probe::dense::cpu::points`.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 1) readonly buffer Views { ProbeView views[]; };
layout(std430, set = 0, binding = 2) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Points { vec4 points[]; };

// Twin of `DensePointsPush` (src/probe/dense.rs).
layout(push_constant) uniform Push {
    uint rays;
    uint width;
    uint height;
    uint pad0;
    float inv_s;
    float step; // unused by the kernel (the counts carry it)
    float pad1;
    float pad2;
    vec4 cube; // centre, half-edge
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.rays) {
        return;
    }
    Ray r = rays[id];
    vec3 o;
    vec3 d;
    view_ray(views[r.view], pixel_to_screen(r.px, r.py, float(pc.width), float(pc.height), pc.inv_s),
             o, d);
    float t0 = -3.0e38;
    float t1 = 3.0e38;
    for (int a = 0; a < 3; ++a) {
        float lo = pc.cube[a] - pc.cube.w;
        float hi = pc.cube[a] + pc.cube.w;
        if (d[a] != 0.0) {
            float ta = fm_div(lo - o[a], d[a]);
            float tb = fm_div(hi - o[a], d[a]);
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    uint first = offsets[id];
    uint count = offsets[id + 1u] - first;
    float dt = fm_div(t1 - t0, float(max(count, 1u)));
    for (uint k = 0u; k < count; ++k) {
        float t = t0 + (float(k) + 0.5) * dt;
        points[first + k] = vec4(o + t * d, 1.0);
    }
}
