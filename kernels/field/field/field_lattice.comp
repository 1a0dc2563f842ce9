#version 460
#extension GL_GOOGLE_include_directive : require
// The points of lattice nodes [base, base + n) (see field_lattice.glsl), as vec4 (w = 1) for
// the fields' eval. Twin: `crate::field::mcubes::cpu::lattice_point`.
#include "common.glsl"
#include "field_lattice.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) writeonly buffer Points { vec4 points[]; };

layout(push_constant) uniform Push {
    vec4 cube;
    uint res;
    uint base;
    uint n;
    uint pad;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    points[i] = vec4(lattice_point(lattice_coords(pc.base + i, pc.res), pc.cube, pc.res), 1.0);
}
