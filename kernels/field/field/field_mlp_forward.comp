#version 460
#extension GL_GOOGLE_include_directive : require
// MLP backward, step 1 of 4, one invocation per point of a batch: the forward, saving every
// layer's input (acts) and softplus'(z) (deltas), and the output's δ_L = dL/df =
// dL/dφ · φ (1 − φ). Specialized like `field_mlp_eval` (unrolled for small networks: the
// activations then live in registers). The host bounds the loop iterations
// (`MlpLayout::forward_iterations`). Twin: `crate::field::cpu::backward` (Mlp).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Points { vec4 points[]; };
layout(std430, set = 0, binding = 2) readonly buffer DPhi { float d_phi[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Acts { float acts[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Deltas { float deltas[]; };

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

#define MLP_SAVE
#include "field.glsl"
#include "field_mlp.glsl"

void main() {
    // No early return (as in `field_mlp_eval`: uniform weight loads stay scalar outside control
    // flow): lanes past the end evaluate the last point and store nothing.
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint i = min(id, pc.n - 1u);
    float phi = field_sigmoid(mlp_forward(points[i].xyz, id < pc.n ? i : MLP_NO_POINT));
    if (id < pc.n) {
        deltas[MLP_LAYERS * MLP_WIDTH * pc.batch + i] = d_phi[i] * (phi * (1.0 - phi));
    }
}
