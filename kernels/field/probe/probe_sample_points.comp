#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, sampling: points in a box (anchors, or the regularizer's surface candidates),
// one invocation per point. The first `uniform_count` points are uniform in the box; the rest
// pick a visual-hull boundary point uniformly and add isotropic Gaussian noise of standard
// deviation `sigma` (Box–Muller), clamped to the box; without boundary points every point is
// uniform. Random words: `rand_u32(key, point, 0..4)`. Written as (x, y, z, 1).
// Twin: `probe::sampler::cpu::sample_points`.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Boundary { vec4 boundary[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Points { vec4 points[]; };

layout(push_constant) uniform Push {
    uint count;
    uint uniform_count;
    uint boundary_count;
    uint key;
    float lo_x;
    float lo_y;
    float lo_z;
    float sigma;
    float size_x; // box edge per axis
    float size_y;
    float size_z;
    float pad0;
    float hi_x;   // lo + size, as the host rounded it
    float hi_y;
    float hi_z;
    float pad1;
} pc;

const float TWO_PI = 6.283185307179586;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.count) {
        return;
    }
    vec3 lo = vec3(pc.lo_x, pc.lo_y, pc.lo_z);
    vec3 hi = vec3(pc.hi_x, pc.hi_y, pc.hi_z);
    vec3 p;
    if (id < pc.uniform_count || pc.boundary_count == 0u) {
        vec3 u = vec3(unit_float(rand_u32(pc.key, id, 0u)), unit_float(rand_u32(pc.key, id, 1u)),
                      unit_float(rand_u32(pc.key, id, 2u)));
        precise vec3 q = lo + vec3(pc.size_x, pc.size_y, pc.size_z) * u;
        p = q;
    } else {
        vec3 b = boundary[scale_u32(rand_u32(pc.key, id, 0u), pc.boundary_count)].xyz;
        float r1 = fm_sqrt(-2.0 * fm_log(unit_float_open0(rand_u32(pc.key, id, 1u))));
        float t1 = TWO_PI * unit_float(rand_u32(pc.key, id, 2u));
        float r2 = fm_sqrt(-2.0 * fm_log(unit_float_open0(rand_u32(pc.key, id, 3u))));
        float t2 = TWO_PI * unit_float(rand_u32(pc.key, id, 4u));
        vec2 sc1 = fm_sincos(t1);
        vec3 g = vec3(r1 * sc1.y, r1 * sc1.x, r2 * fm_cos(t2));
        p = b + pc.sigma * g;
    }
    points[id] = vec4(clamp(p, lo, hi), 1.0);
}
