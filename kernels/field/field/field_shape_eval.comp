#version 460
#extension GL_GOOGLE_include_directive : require
// φ = sigmoid(−sharpness · sd(p)) of an analytic shape per point (see field_shape.glsl).
// Twin: `crate::field::cpu::eval` (Analytic).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Points { vec4 points[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Phi { float phi[]; };

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
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    float g[SHAPE_MAX_PARAMS];
    phi[i] = field_sigmoid(-pc.sharpness * shape_sd(pc.kind, points[i].xyz, g));
}
