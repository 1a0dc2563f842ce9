#version 460
#extension GL_GOOGLE_include_directive : require
// SoftRas's FlattenLoss per edge (v0, v1) shared by two faces with opposite vertices v2, v3:
// the term (cos + 1)², cos the cosine between the two faces' perpendiculars from the edge line
// to v2 and v3, with SoftRas's epsilons; and its gradient wrt the 4 vertices by hand-written
// reverse mode, at the edge's own 4 slots (4 edge + role, 3 floats each). One writer per slot;
// `flatten_gather.comp` sums each vertex's slots in order. Twin, line for line:
// `crate::fit::flatten::cpu::edge_loss_grad`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Quads { uvec4 quads[]; };
layout(std430, set = 0, binding = 1) readonly buffer Positions { float positions[]; };
layout(std430, set = 0, binding = 2) writeonly buffer EdgeLoss { float edge_loss[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Slots { float slots[]; };

layout(push_constant) uniform Push {
    uint edge_count;
} pc;

const float EPS = 1e-6;

vec3 position(uint v) {
    return vec3(positions[3u * v], positions[3u * v + 1u], positions[3u * v + 2u]);
}

float dot3(vec3 a, vec3 b) {
    return (a.x * b.x + a.y * b.y) + a.z * b.z;
}

// One side's forward state: the perpendicular cb = b − a (a·b / (|a|² + eps)) and its
// length as SoftRas computes it, |b|_eps · sin.
struct Side {
    vec3 b;
    float bl1;
    float ab;
    float cosk;
    float sink;
    float s;   // ab / (a1l2 + eps)
    vec3 cb;
    float cbl1;
};

Side side_forward(vec3 a, float al1, float al2, vec3 b) {
    Side r;
    r.b = b;
    r.bl1 = fm_sqrt(dot3(b, b) + EPS);
    r.ab = dot3(a, b);
    r.cosk = fm_div(r.ab, al1 * r.bl1 + EPS);
    r.sink = fm_sqrt(1.0 - r.cosk * r.cosk + EPS);
    r.s = fm_div(r.ab, al2 + EPS);
    r.cb = b - a * r.s;
    r.cbl1 = r.bl1 * r.sink;
    return r;
}

// Reverse of `side_forward` given dL/d cb and dL/d cbl1: adds to dL/da and dL/d al2, returns
// dL/db.
vec3 side_backward(Side r, vec3 a, float al1, float al2, vec3 g_cb, float g_cbl1,
                   inout vec3 g_a, inout float g_al2) {
    float g_bl1 = g_cbl1 * r.sink;
    float g_sin = g_cbl1 * r.bl1;
    float g_cos = fm_div(-g_sin * r.cosk, r.sink);
    vec3 g_b = g_cb;
    vec3 g_c = -g_cb;              // c = a s
    g_a += g_c * r.s;
    float g_s = dot3(g_c, a);
    float d2 = al2 + EPS;          // s = ab / d2
    float g_ab = fm_div(g_s, d2);
    g_al2 -= fm_div(g_s * r.ab, d2 * d2);
    float d = al1 * r.bl1 + EPS;   // cos = ab / d
    g_ab += fm_div(g_cos, d);
    float g_d = fm_div(-g_cos * r.ab, d * d);
    float g_al1 = g_d * r.bl1;
    g_bl1 += g_d * al1;
    g_al2 += fm_div(g_al1, 2.0 * al1);  // al1 = sqrt(al2 + eps)
    g_b += r.b * fm_div(g_bl1, r.bl1);  // bl1 = sqrt(|b|² + eps): d/db = b / bl1
    g_a += r.b * g_ab;             // ab = a·b
    g_b += a * g_ab;
    return g_b;
}

void main() {
    uint e = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (e >= pc.edge_count) {
        return;
    }
    uvec4 q = quads[e];
    vec3 v0 = position(q.x);
    vec3 a = position(q.y) - v0;
    float al2 = dot3(a, a);
    float al1 = fm_sqrt(al2 + EPS);
    Side s1 = side_forward(a, al1, al2, position(q.z) - v0);
    Side s2 = side_forward(a, al1, al2, position(q.w) - v0);
    float num = dot3(s1.cb, s2.cb);
    float den = s1.cbl1 * s2.cbl1 + EPS;
    float c = fm_div(num, den);
    edge_loss[e] = (c + 1.0) * (c + 1.0);

    float g_c = 2.0 * (c + 1.0);
    float g_num = fm_div(g_c, den);
    float g_den = fm_div(-g_c * num, den * den);
    vec3 g_a = vec3(0.0);
    float g_al2 = 0.0;
    vec3 g_b1 = side_backward(s1, a, al1, al2, s2.cb * g_num, s2.cbl1 * g_den, g_a, g_al2);
    vec3 g_b2 = side_backward(s2, a, al1, al2, s1.cb * g_num, s1.cbl1 * g_den, g_a, g_al2);
    g_a += a * (2.0 * g_al2);
    vec3 g[4] = vec3[4](-(g_a + g_b1 + g_b2), g_a, g_b1, g_b2);
    for (uint role = 0u; role < 4u; ++role) {
        uint o = 3u * (4u * e + role);
        slots[o] = g[role].x;
        slots[o + 1u] = g[role].y;
        slots[o + 2u] = g[role].z;
    }
}
