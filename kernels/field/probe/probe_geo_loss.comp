#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, geometric regularizer (SPEC §5), one invocation per surface candidate j:
//   term_j = W(φ(s_j)) Σ_l W(φ(q_l)) ‖n(s_j) − n(q_l)‖_p^p / Σ_l W(φ(q_l))   (0 when Σ W = 0)
// over the six neighbours q_l, W(x) = 1[|x − 0.5| < ε], n = g / max(|g|, NORMAL_EPS) with g the
// central differences of φ on the point's stencil (the 1 / 2δ_n factor cancels). Writes term_j
// and dL/dφ of the candidate's 49 points (`probe_geo_points.comp`'s layout): coef · dterm_j/dφ,
// through the normals only (W is piecewise constant). One writer per output: deterministic.
// Twin: `probe::geo::cpu::loss`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Phi { float phi[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Terms { float terms[]; };
layout(std430, set = 0, binding = 2) buffer DPhi { float d_phi[]; };

// Twin of `GeoLossPush` (src/probe/geo.rs).
layout(push_constant) uniform Push {
    uint candidates;
    uint write_grad; // 0: the loss only
    uint accumulate; // add to d_phi instead of overwriting it
    float epsilon;   // W's half-width ε
    float p;         // the norm's exponent, >= 1
    float coef;      // weight / N
    float normal_eps;
    uint pad0;
} pc;

// d|x|^p / dx.
float dpow(float x) {
    if (x == 0.0) {
        return 0.0; // p = 1: the subgradient 0 at the kink
    }
    float a = pc.p == 1.0 ? 1.0 : pc.p * fm_pow(abs(x), pc.p - 1.0);
    return x > 0.0 ? a : -a;
}

float powp(float x) {
    float a = abs(x);
    return a == 0.0 ? 0.0 : (pc.p == 2.0 ? a * a : fm_pow(a, pc.p));
}

void main() {
    uint j = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (j >= pc.candidates) {
        return;
    }
    uint base = j * 49u;
    vec3 n[7];
    vec3 g[7];
    float len[7];
    bool w[7];
    for (uint c = 0u; c < 7u; ++c) {
        uint b = base + 7u * c;
        g[c] = vec3(phi[b + 1u] - phi[b + 2u], phi[b + 3u] - phi[b + 4u], phi[b + 5u] - phi[b + 6u]);
        len[c] = fm_length3(g[c]);
        n[c] = fm_div3(g[c], max(len[c], pc.normal_eps));
        w[c] = abs(phi[b] - 0.5) < pc.epsilon;
    }
    float denom = 0.0;
    for (uint l = 1u; l < 7u; ++l) {
        denom += w[l] ? 1.0 : 0.0;
    }
    float term = 0.0;
    vec3 dn[7];
    for (uint c = 0u; c < 7u; ++c) {
        dn[c] = vec3(0.0);
    }
    if (w[0] && denom > 0.0) {
        for (uint l = 1u; l < 7u; ++l) {
            if (!w[l]) {
                continue;
            }
            vec3 diff = n[0] - n[l];
            term += powp(diff.x) + powp(diff.y) + powp(diff.z);
            vec3 gd = fm_div3(vec3(dpow(diff.x), dpow(diff.y), dpow(diff.z)), denom);
            dn[0] += gd;
            dn[l] -= gd;
        }
        term = fm_div(term, denom);
    }
    terms[j] = term;
    if (pc.write_grad == 0u) {
        return;
    }
    for (uint c = 0u; c < 7u; ++c) {
        // d(g / max(|g|, eps))/dg: (I − n nᵀ) / |g| above eps, I / eps below.
        vec3 dg = len[c] > pc.normal_eps ? fm_div3(dn[c] - n[c] * fm_dot3(n[c], dn[c]), len[c])
                                         : fm_div3(dn[c], pc.normal_eps);
        dg *= pc.coef;
        uint b = base + 7u * c;
        float vals[7] = float[7](0.0, dg.x, -dg.x, dg.y, -dg.y, dg.z, -dg.z);
        for (uint k = 0u; k < 7u; ++k) {
            d_phi[b + k] = pc.accumulate != 0u ? d_phi[b + k] + vals[k] : vals[k];
        }
    }
}
