#version 460
#extension GL_GOOGLE_include_directive : require
// φ = sigmoid(MLP logit) per point (see field_mlp.glsl). The host bounds the loop iterations of
// one invocation (`mlp::eval_iterations`). Twin: `crate::field::cpu::eval` (Mlp).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Points { vec4 points[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Phi { float phi[]; };

layout(push_constant) uniform Push {
    vec4 cube;
    uint n;
    uint layers;
    uint width;
    uint freqs;
    float beta;
    uint batch;
    uint chunks;
    uint param_count;
} pc;

#include "field.glsl"
#include "field_mlp.glsl"

void main() {
    // No early return: on llvmpipe, code after a divergent return runs masked, and a masked
    // load of a uniform address (every weight) is a per-lane gather instead of one load. Lanes
    // past the end evaluate the last point and store nothing.
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint i = min(id, pc.n - 1u);
    float value = field_sigmoid(mlp_forward(points[i].xyz, i));
    if (id < pc.n) {
        phi[id] = value;
    }
}
