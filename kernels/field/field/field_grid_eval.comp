#version 460
#extension GL_GOOGLE_include_directive : require
// φ = sigmoid(trilinear grid logit) per point. Twin: `crate::field::cpu::eval` (Grid).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Points { vec4 points[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Phi { float phi[]; };

layout(push_constant) uniform Push {
    vec4 cube;
    uint res;
    uint n;
    uint pad0;
    uint pad1;
} pc;

#include "field.glsl"
#include "field_grid.glsl"

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    uvec3 cell;
    vec3 t;
    grid_locate(points[i].xyz, pc.cube, pc.res, cell, t);
    phi[i] = field_sigmoid(grid_logit(cell, t, pc.res));
}
