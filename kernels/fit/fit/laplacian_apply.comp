#version 460
#extension GL_GOOGLE_include_directive : require
// y = L x for SoftRas's uniform Laplacian: y_i = x_i − (Σ_{j ∈ N(i)} x_j) / |N(i)| (a vertex
// without neighbours has a zero row), neighbours from the CSR adjacency in ascending order.
// Writes (y_i, |y_i|²); `fit_sum.comp` sums the |y_i|² into the loss.
// Twin: `crate::fit::laplacian::cpu::loss_and_grad`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Neighbours { uint neighbours[]; };
layout(std430, set = 0, binding = 2) readonly buffer Positions { float positions[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Applied { vec4 applied[]; };

layout(push_constant) uniform Push {
    uint vertex_count;
} pc;

vec3 position(uint v) {
    return vec3(positions[3u * v], positions[3u * v + 1u], positions[3u * v + 2u]);
}

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.vertex_count) {
        return;
    }
    uint begin = offsets[i];
    uint end = offsets[i + 1u];
    vec3 y = vec3(0.0);
    if (end > begin) {
        vec3 s = vec3(0.0);
        for (uint k = begin; k < end; ++k) {
            s += position(neighbours[k]);
        }
        y = position(i) - fm_div3(s, float(end - begin));
    }
    applied[i] = vec4(y, (y.x * y.x + y.y * y.y) + y.z * y.z);
}
