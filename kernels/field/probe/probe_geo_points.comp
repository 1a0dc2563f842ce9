#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, geometric regularizer: the points whose φ the regularizer needs, 49 per
// surface candidate s_j, one invocation per point. Point (j, c, k) at index (7 j + c) 7 + k is
// q_c + δ_n e_k, where q_0 = s_j, q_c = s_j + δ e_c for the six neighbours, and e_0 = 0,
// e_1..e_6 = +x, −x, +y, −y, +z, −z: k = 0 is q_c itself (for W(φ)), k = 1..6 its central
// difference stencil (for the normal). Twin: `probe::geo::cpu::points`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Candidates { vec4 candidates[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Points { vec4 points[]; };

layout(push_constant) uniform Push {
    uint candidates;
    float delta;
    float delta_n;
    uint pad0;
} pc;

// ±step on the axis of offset k (0: none).
vec3 offset(uint k, float step) {
    vec3 r = vec3(0.0);
    if (k > 0u) {
        r[(k - 1u) / 2u] = (k & 1u) != 0u ? step : -step;
    }
    return r;
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.candidates * 49u) {
        return;
    }
    uint j = id / 49u;
    uint r = id - j * 49u;
    uint c = r / 7u;
    uint k = r - c * 7u;
    precise vec3 q = candidates[j].xyz + offset(c, pc.delta);
    precise vec3 p = q + offset(k, pc.delta_n);
    points[id] = vec4(p, 1.0);
}
