#version 460
#extension GL_GOOGLE_include_directive : require
// Grid backward, step 1 of 3: per point of a batch, its cell as a sort key (the point index as
// the value), and (t, dL/df) with dL/df = dL/dφ · φ (1 − φ). Twin: `crate::field::cpu::backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Points { vec4 points[]; };
layout(std430, set = 0, binding = 2) readonly buffer DPhi { float d_phi[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Values { uint values[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Records { vec4 records[]; };

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
    float phi = field_sigmoid(grid_logit(cell, t, pc.res));
    uint cells = pc.res - 1u;
    keys[i] = uvec2(cell.x + cells * (cell.y + cells * cell.z), 0u);
    values[i] = i;
    records[i] = vec4(t, d_phi[i] * (phi * (1.0 - phi)));
}
