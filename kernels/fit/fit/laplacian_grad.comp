#version 460
#extension GL_GOOGLE_include_directive : require
// dL/dx = 2 Lᵀ y with y = L x (from `laplacian_apply.comp`). The adjacency is symmetric, so
// (Lᵀ y)_i = y_i − Σ_{j ∈ N(i)} y_j / |N(j)| (y_i = 0 for a vertex without neighbours), summed
// over the CSR neighbours in ascending order. One writer per vertex: `weight` scales it, and
// with `accumulate` it is added to what the buffer holds.
// Twin: `crate::fit::laplacian::cpu::loss_and_grad`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Neighbours { uint neighbours[]; };
layout(std430, set = 0, binding = 2) readonly buffer Applied { vec4 applied[]; };
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
    uint begin = offsets[i];
    uint end = offsets[i + 1u];
    vec3 s = vec3(0.0);
    for (uint k = begin; k < end; ++k) {
        uint j = neighbours[k];
        s += fm_div3(applied[j].xyz, float(offsets[j + 1u] - offsets[j]));
    }
    vec3 g = (2.0 * pc.weight) * (applied[i].xyz - s);
    for (uint c = 0u; c < 3u; ++c) {
        float old = pc.accumulate != 0u ? grads[3u * i + c] : 0.0;
        grads[3u * i + c] = old + g[c];
    }
}
