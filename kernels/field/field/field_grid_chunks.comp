#version 460
#extension GL_GOOGLE_include_directive : require
// Grid backward, step 2 of 3: one invocation per chunk of GRID_CHUNK sorted positions walks its
// positions in order and sums the 8 corner contributions w_k · dL/df of each run of one cell
// (a "piece": a cell's points within one chunk). The 8 sums land at the piece's first position:
// partial[8 s + k]. Sequential, fixed order. Twin: the plain sums of `cpu::backward`.
#include "common.glsl"

#define GRID_CHUNK 256u

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) readonly buffer Values { uint values[]; };
layout(std430, set = 0, binding = 2) readonly buffer Records { vec4 records[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Partial { vec4 partial[]; };

layout(push_constant) uniform Push {
    uint n;
} pc;

#define GRID_NO_PARAMS
#include "field.glsl"
#include "field_grid.glsl"

void main() {
    uint chunk = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint s0 = chunk * GRID_CHUNK;
    if (s0 >= pc.n) {
        return;
    }
    uint s1 = min(s0 + GRID_CHUNK, pc.n);
    vec4 acc_lo = vec4(0.0);
    vec4 acc_hi = vec4(0.0);
    uint start = s0;
    for (uint s = s0; s < s1; ++s) {
        uint c = keys[s].x;
        vec4 r = records[values[s]];
        vec4 lo, hi;
        grid_weights(r.xyz, lo, hi);
        acc_lo += r.w * lo;
        acc_hi += r.w * hi;
        if (s + 1u == s1 || keys[s + 1u].x != c) {
            partial[2u * start] = acc_lo;
            partial[2u * start + 1u] = acc_hi;
            acc_lo = vec4(0.0);
            acc_hi = vec4(0.0);
            start = s + 1u;
        }
    }
}
