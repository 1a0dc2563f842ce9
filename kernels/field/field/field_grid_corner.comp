#version 460
#extension GL_GOOGLE_include_directive : require
// Grid backward, step 3 of 3, dispatched once per corner k = 0..7 in that order: one invocation
// per sorted position; the first position of each cell's run adds that cell's piece sums for
// corner k, in position order (a cell's pieces start at its first position and at every
// GRID_CHUNK boundary inside its run), to the node at corner k of the cell:
// d_params[node] += partial[8 s + k] piece by piece. Within one dispatch every node is corner k
// of at most one cell, so no two invocations touch the same node; across the dispatches a node
// receives its cells in corner order. Starting from zero, a node's sum is therefore the one a
// gather over its (up to) 8 cells in corner order would make, bit for bit, while only the
// occupied cells do work: a gather over every node of a 48³ grid cost llvmpipe milliseconds for a
// few thousand points. Accumulating batches add onto the earlier batches' sums. Twin:
// `crate::field::cpu::backward` (Grid).
#include "common.glsl"

#define GRID_CHUNK 256u

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) readonly buffer Partial { float partial[]; };
layout(std430, set = 0, binding = 2) buffer DParams { float d_params[]; };

layout(push_constant) uniform Push {
    uint n;      // sorted positions
    uint res;    // grid nodes per axis
    uint corner; // k: the node at offset ((k & 1), (k >> 1) & 1, (k >> 2) & 1) of the cell
    uint pad;
} pc;

void main() {
    uint s = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (s >= pc.n) {
        return;
    }
    uint c = keys[s].x;
    if (s > 0u && keys[s - 1u].x == c) {
        return; // not the first position of its cell's run
    }
    uint cells = pc.res - 1u;
    uvec3 q = uvec3(c % cells, (c / cells) % cells, c / (cells * cells))
        + uvec3(pc.corner & 1u, (pc.corner >> 1u) & 1u, (pc.corner >> 2u) & 1u);
    uint node = q.x + pc.res * (q.y + pc.res * q.z);
    float acc = d_params[node] + partial[8u * s + pc.corner];
    // Later pieces of the run start at chunk boundaries: at most n / GRID_CHUNK of them.
    for (uint p = (s / GRID_CHUNK + 1u) * GRID_CHUNK; p < pc.n && keys[p].x == c;
         p += GRID_CHUNK) {
        acc += partial[8u * p + pc.corner];
    }
    d_params[node] = acc;
}
