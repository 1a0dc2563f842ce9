#version 460
#extension GL_GOOGLE_include_directive : require
// Per vertex: the sum of its (edge, role) gradient slots from `flatten_edges.comp`, in the
// ascending slot order of the CSR, times `weight`; with `accumulate` added to what the buffer
// holds. One writer per vertex, no atomics. Twin: `crate::fit::flatten::cpu::loss_and_grad`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer VertexSlots { uint vertex_slots[]; };
layout(std430, set = 0, binding = 2) readonly buffer Slots { float slots[]; };
layout(std430, set = 0, binding = 3) buffer Grads { float grads[]; };

layout(push_constant) uniform Push {
    uint vertex_count;
    float weight;
    uint accumulate;
    uint pad;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.vertex_count) {
        return;
    }
    vec3 s = vec3(0.0);
    for (uint k = offsets[i]; k < offsets[i + 1u]; ++k) {
        uint o = 3u * vertex_slots[k];
        s += vec3(slots[o], slots[o + 1u], slots[o + 2u]);
    }
    for (uint c = 0u; c < 3u; ++c) {
        float old = pc.accumulate != 0u ? grads[3u * i + c] : 0.0;
        grads[3u * i + c] = old + pc.weight * s[c];
    }
}
