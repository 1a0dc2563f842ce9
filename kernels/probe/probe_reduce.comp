#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, backward, step 3: dL/dφ_j = coef · Σ over views, then over the entries of
// anchor j's item in that view (contiguous at the item's scanned offset), of the partials, in
// that fixed order. One invocation per anchor, one writer per output: deterministic. coef is
// 2 / (number of rays) times the gradient's weight. Twin: `probe::prober::cpu::backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Partials { float partials[]; };
layout(std430, set = 0, binding = 2) buffer DPhi { float d_phi[]; };

// Twin of `ReducePush` (src/probe/prober.rs).
layout(push_constant) uniform Push {
    uint anchors;
    uint views;
    uint entries;    // entries of the binning (the end of the last item's run)
    uint accumulate; // add to d_phi instead of overwriting it
    float coef;
    uint pad0;
    uint pad1;
    uint pad2;
} pc;

void main() {
    uint anchor = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (anchor >= pc.anchors) {
        return;
    }
    uint items = pc.anchors * pc.views;
    float s = 0.0;
    for (uint view = 0u; view < pc.views; ++view) {
        uint item = view * pc.anchors + anchor;
        uint end = item + 1u < items ? offsets[item + 1u] : pc.entries;
        for (uint slot = offsets[item]; slot < end; ++slot) {
            s += partials[slot];
        }
    }
    float g = pc.coef * s;
    d_phi[anchor] = pc.accumulate != 0u ? d_phi[anchor] + g : g;
}
