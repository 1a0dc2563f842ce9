#version 460
#extension GL_GOOGLE_include_directive : require
// The segmented sum of the tiled backward: each (view, face) item sums the partials of its
// entries, which binning laid out contiguously at the item's scanned offset, in slot order.
// Fixed order, one writer per item: deterministic. Twin: the per-face sum of
// `reference_grad::backward_view`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Partials { float partials[]; };
layout(std430, set = 0, binding = 2) writeonly buffer FaceGrads { float face_grads[]; };

layout(push_constant) uniform Push {
    uint item_count;   // items of the view group
    uint first_item;   // the group's first item in face_grads
    uint stride;       // floats per gradient
    uint entry_total;  // entries of the group (a guarded binning: its capacity), a bound
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.item_count) {
        return;
    }
    // offsets[item_count] is the group's total (the binning writes it), so a guarded binning,
    // whose count the host never reads, needs no push constant for the last item's end. The
    // clamp to entry_total (the count, or a guarded binning's capacity) keeps every read inside
    // the partials.
    uint begin = min(offsets[id], pc.entry_total);
    uint end = min(offsets[id + 1u], pc.entry_total);
    uint o = (pc.first_item + id) * pc.stride;
    for (uint c = 0u; c < pc.stride; ++c) {
        float s = 0.0;
        for (uint e = begin; e < end; ++e) {
            s += partials[e * pc.stride + c];
        }
        face_grads[o + c] = s;
    }
}
