#version 460
#extension GL_GOOGLE_include_directive : require
// Grid backward, step 2 of 4: after the stable sort by cell, each cell's range [start, end) of
// sorted positions. Cells without points keep the host's fill (start = end = 0). Each cell is
// written by exactly one invocation. Twin: none needed (an index structure; the result is
// checked through the gradient).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) writeonly buffer CellStart { uint cell_start[]; };
layout(std430, set = 0, binding = 2) writeonly buffer CellEnd { uint cell_end[]; };

layout(push_constant) uniform Push {
    uint n;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    uint c = keys[i].x;
    if (i == 0u || keys[i - 1u].x != c) {
        cell_start[c] = i;
    }
    if (i + 1u == pc.n || keys[i + 1u].x != c) {
        cell_end[c] = i + 1u;
    }
}
