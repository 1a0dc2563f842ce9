#version 460
#extension GL_GOOGLE_include_directive : require
// Marching cubes, step 2: per cell, its triangles at the scanned offsets. Each corner is a lattice
// edge crossing: its id 3 · (lower node) + axis (so the host welds shared vertices exactly) and
// its position p_a + t (p_b − p_a), t = (0.5 − φ_a) / (φ_b − φ_a), computed from the edge's lower
// node a to its upper node b whichever cell asks, so both cells of a shared edge get the same bits.
// Table: 256 triangle counts, then per case `stride` local edge indices (3 per triangle); local
// edge e has axis e / 4 and lower corner j = e % 4 spread over the other two axes (low axis first).
// Twin: `crate::field::mcubes::cpu`.
#include "common.glsl"
#include "field_lattice.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Phi { float phi[]; };
layout(std430, set = 0, binding = 1) readonly buffer Table { uint table[]; };
layout(std430, set = 0, binding = 2) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 3) writeonly buffer TriEdges { uint tri_edges[]; };
layout(std430, set = 0, binding = 4) writeonly buffer TriPoints { vec4 tri_points[]; };

layout(push_constant) uniform Push {
    vec4 cube;
    uint res;
    uint cells;
    uint stride;
    uint pad;
} pc;

uint node_index(uvec3 v) {
    return v.x + pc.res * (v.y + pc.res * v.z);
}

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
        if (phi[node_index(v)] > 0.5) {
            mc_case |= 1u << k;
        }
    }
    uint count = table[mc_case];
    uint out_tri = offsets[c];
    for (uint t = 0u; t < count; ++t) {
        for (uint corner = 0u; corner < 3u; ++corner) {
            uint e = table[256u + mc_case * pc.stride + 3u * t + corner];
            uint axis = e >> 2u;
            uint j = e & 3u;
            uvec3 lo = axis == 0u ? uvec3(0u, j & 1u, j >> 1u)
                     : (axis == 1u ? uvec3(j & 1u, 0u, j >> 1u) : uvec3(j & 1u, j >> 1u, 0u));
            uvec3 a = q + lo;
            uvec3 b = a;
            b[axis] += 1u;
            float fa = phi[node_index(a)];
            float fb = phi[node_index(b)];
            float s = fm_div(0.5 - fa, fb - fa);
            vec3 pa = lattice_point(a, pc.cube, pc.res);
            vec3 pb = lattice_point(b, pc.cube, pc.res);
            uint at = 3u * (out_tri + t) + corner;
            tri_edges[at] = 3u * node_index(a) + axis;
            tri_points[at] = vec4(pa + s * (pb - pa), 1.0);
        }
    }
}
