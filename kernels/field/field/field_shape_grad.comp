#version 460
#extension GL_GOOGLE_include_directive : require
// Analytic backward, step 1 of 2: one invocation per (chunk of FIELD_CHUNK points, parameter j):
// partial[chunk · P + j] = Σ over the chunk's points, in order, of
// dL/dφ · φ (1 − φ) · (−sharpness) · ∂sd/∂θ_j. Twin: `crate::field::cpu::backward` (Analytic).
#include "common.glsl"

#define FIELD_CHUNK 256u

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Points { vec4 points[]; };
layout(std430, set = 0, binding = 2) readonly buffer DPhi { float d_phi[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Partial { float partial[]; };

layout(push_constant) uniform Push {
    uint kind;
    uint n;
    float sharpness;
    uint param_count;
    uint chunks;
    uint pad0;
    uint pad1;
    uint pad2;
} pc;

#include "field.glsl"
#include "field_shape.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint chunk = id / pc.param_count;
    uint j = id % pc.param_count;
    if (chunk >= pc.chunks) {
        return;
    }
    uint p0 = chunk * FIELD_CHUNK;
    uint p1 = min(p0 + FIELD_CHUNK, pc.n);
    float s = 0.0;
    for (uint p = p0; p < p1; ++p) {
        float g[SHAPE_MAX_PARAMS];
        float f = -pc.sharpness * shape_sd(pc.kind, points[p].xyz, g);
        float phi = field_sigmoid(f);
        s += d_phi[p] * (phi * (1.0 - phi)) * (-pc.sharpness * g[j]);
    }
    partial[chunk * pc.param_count + j] = s;
}
