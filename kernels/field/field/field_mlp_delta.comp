#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
// MLP backward, step 2 of 4, one dispatch per hidden layer l, from the last down: from
// `field_mlp_forward`'s softplus'(z_l) and the layer above's δ_{l+1},
// δ_l[o] = softplus'(z_l[o]) · Σ_k W_{l+1}[k][o] δ_{l+1}[k], stored over softplus'. One
// invocation per tile of DELTA_UNITS units × DELTA_POINTS points: per k it loads DELTA_UNITS
// weights and DELTA_POINTS δs for DELTA_UNITS · DELTA_POINTS products (on llvmpipe every load
// in a loop is a per-lane gather, uniform address or not, so a point-per-invocation loop paid
// a weight load per product). Sums over k in order. Twin: `crate::field::cpu::backward` (Mlp).
#include "common.glsl"

#define DELTA_UNITS 8u
#define DELTA_POINTS 4u

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) buffer Deltas { float deltas[]; };

layout(push_constant) uniform Push {
    uint n;
    uint batch;
    uint layer;
    uint pad;
} pc;

#include "field_mlp_shape.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint point_tiles = (pc.n + DELTA_POINTS - 1u) / DELTA_POINTS;
    uint unit_tiles = (MLP_WIDTH + DELTA_UNITS - 1u) / DELTA_UNITS;
    if (id >= point_tiles * unit_tiles) {
        return;
    }
    uint w = MLP_WIDTH;
    uint l = pc.layer;
    uint p0 = (id % point_tiles) * DELTA_POINTS;
    uint o0 = (id / point_tiles) * DELTA_UNITS;
    uint out_next = l + 1u == MLP_LAYERS ? 1u : w;
    uint off_next = mlp_layer_offset(l + 1u);
    // Units and points past the end read valid ones (the last) and store nothing.
    uint unit[DELTA_UNITS];
    [[unroll]] for (uint u = 0u; u < DELTA_UNITS; ++u) {
        unit[u] = min(o0 + u, w - 1u);
    }
    uint point[DELTA_POINTS];
    [[unroll]] for (uint q = 0u; q < DELTA_POINTS; ++q) {
        point[q] = min(p0 + q, pc.n - 1u);
    }
    float s[DELTA_UNITS][DELTA_POINTS];
    [[unroll]] for (uint u = 0u; u < DELTA_UNITS; ++u) {
        [[unroll]] for (uint q = 0u; q < DELTA_POINTS; ++q) {
            s[u][q] = 0.0;
        }
    }
    for (uint k = 0u; k < out_next; ++k) {
        float d[DELTA_POINTS];
        [[unroll]] for (uint q = 0u; q < DELTA_POINTS; ++q) {
            d[q] = deltas[((l + 1u) * w + k) * pc.batch + point[q]];
        }
        uint row = off_next + k * w;
        [[unroll]] for (uint u = 0u; u < DELTA_UNITS; ++u) {
            float wk = params[row + unit[u]];
            [[unroll]] for (uint q = 0u; q < DELTA_POINTS; ++q) {
                s[u][q] += wk * d[q];
            }
        }
    }
    [[unroll]] for (uint u = 0u; u < DELTA_UNITS; ++u) {
        [[unroll]] for (uint q = 0u; q < DELTA_POINTS; ++q) {
            if (o0 + u < w && p0 + q < pc.n) {
                uint at = (l * w + o0 + u) * pc.batch + p0 + q;
                deltas[at] = deltas[at] * s[u][q];
            }
        }
    }
}
