#version 460
#extension GL_GOOGLE_include_directive : require
// The dense-marching baseline, per ray: ψ = max φ over the ray's samples (0 without samples),
// and, with write_grad, dL_sil/dφ per sample of L_sil = mean (ψ − S)²: coef (ψ − S) at the first
// maximizing sample, 0 at the others (one writer per sample: deterministic). One invocation per
// ray. Twin: `probe::dense::cpu::max`.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 1) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 2) readonly buffer Phi { float phi[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Psi { float psi[]; };
layout(std430, set = 0, binding = 4) writeonly buffer DPhi { float d_phi[]; };

// Twin of `DenseMaxPush` (src/probe/dense.rs).
layout(push_constant) uniform Push {
    uint rays;
    uint write_grad;
    float coef; // 2 / (number of rays)
    uint pad;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.rays) {
        return;
    }
    uint first = offsets[id];
    uint end = offsets[id + 1u];
    float m = 0.0;
    uint arg = end;
    for (uint k = first; k < end; ++k) {
        float f = phi[k];
        if (arg == end || f > m) {
            m = f;
            arg = k;
        }
    }
    psi[id] = m;
    if (pc.write_grad != 0u) {
        float g = pc.coef * (m - rays[id].label);
        for (uint k = first; k < end; ++k) {
            d_phi[k] = k == arg ? g : 0.0;
        }
    }
}
