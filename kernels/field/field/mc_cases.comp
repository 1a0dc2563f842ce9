#version 460
#extension GL_GOOGLE_include_directive : require
// Marching cubes, step 1: per lattice cell (x, y, z) < res − 1, index x + (res − 1)(y + (res − 1) z),
// its case (bit k set when corner k = dx + 2 dy + 4 dz has φ > 0.5) and its triangle count from
// the case table (`table[case]`). Twin: `crate::field::mcubes::cpu`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Phi { float phi[]; };
layout(std430, set = 0, binding = 1) readonly buffer Table { uint table[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Counts { uint counts[]; };

layout(push_constant) uniform Push {
    uint res;
    uint cells;
} pc;

void main() {
    uint c = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (c >= pc.cells) {
        return;
    }
    uint m = pc.res - 1u;
    uvec3 q = uvec3(c % m, (c / m) % m, c / (m * m));
    uint mc_case = 0u;
    for (uint k = 0u; k < 8u; ++k) {
        uvec3 v = q + uvec3(k & 1u, (k >> 1u) & 1u, (k >> 2u) & 1u);
        if (phi[v.x + pc.res * (v.y + pc.res * v.z)] > 0.5) {
            mc_case |= 1u << k;
        }
    }
    counts[c] = table[mc_case];
}
