#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, backward under G = max: dψ_i/dφ_j is 1 for the one anchor j that ψ_i came
// from and 0 for every other, so dL/dφ_j = coef · Σ over the rays whose ψ came from j, in ray
// order (view by view), of ψ_i − S_i: no per-(anchor, tile) entries at all. The rays are sorted
// by that anchor (`probe_aux_keys.comp` and the stable sort). One invocation per
// anchor, one writer per output: deterministic. Twin: `probe::prober::cpu::backward`.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 1) readonly buffer Outs { RayOut outs[]; };
// Ray indices sorted by anchor, and each anchor's [start, end) in them.
layout(std430, set = 0, binding = 2) readonly buffer Order { uint order[]; };
layout(std430, set = 0, binding = 3) readonly buffer AnchorRanges { uvec2 anchor_ranges[]; };
layout(std430, set = 0, binding = 4) buffer DPhi { float d_phi[]; };

// Twin of `MaxGradPush` (src/probe/prober/).
layout(push_constant) uniform Push {
    uint anchors;
    uint views;
    uint accumulate; // add to d_phi instead of overwriting it
    float coef;
} pc;

void main() {
    uint anchor = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (anchor >= pc.anchors) {
        return;
    }
    float s = 0.0;
    uvec2 range = anchor_ranges[anchor];
    for (uint q = range.x; q < range.y; ++q) {
        uint ray = order[q];
        RayOut out_ = outs[ray];
        // Rays without a hit share the last anchor's run (`probe_aux_keys.comp`); adding +0
        // for them leaves s as it is (s starts at +0, so it is never −0).
        s += out_.aux == anchor ? out_.psi - rays[ray].label : 0.0;
    }
    float g = pc.coef * s;
    d_phi[anchor] = pc.accumulate != 0u ? d_phi[anchor] + g : g;
}
