#version 460
#extension GL_GOOGLE_include_directive : require
// MLP backward, step 1 of 3, one invocation per point of a batch: the forward, saving every
// layer's input (acts) and softplus'(z) (deltas), then the backward of the point's
// dL/df = dL/dφ · φ (1 − φ) down the layers: δ_L = dL/df, and for hidden layer l
// δ_l[o] = softplus'(z_l[o]) · Σ_k W_{l+1}[k][o] δ_{l+1}[k], stored over softplus'.
// The host bounds the loop iterations (`mlp::backward_iterations`).
// Twin: `crate::field::cpu::backward` (Mlp).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Points { vec4 points[]; };
layout(std430, set = 0, binding = 2) readonly buffer DPhi { float d_phi[]; };
layout(std430, set = 0, binding = 3) buffer Acts { float acts[]; };
layout(std430, set = 0, binding = 4) buffer Deltas { float deltas[]; };

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
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    float phi = field_sigmoid(mlp_forward(points[i].xyz, i));
    uint w = MLP_WIDTH;
    uint layers = MLP_LAYERS;
    deltas[layers * w * pc.batch + i] = d_phi[i] * (phi * (1.0 - phi));
    for (uint l = layers; l-- > 0u;) {
        // δ_{l+1} into the private array, then W_{l+1}ᵀ δ_{l+1} per unit of layer l.
        uint out_next = l + 1u == layers ? 1u : w;
        for (uint k = 0u; k < out_next; ++k) {
            mlp_act[k] = deltas[((l + 1u) * w + k) * pc.batch + i];
        }
        uint off_next = mlp_layer_offset(l + 1u);
        for (uint o = 0u; o < w; ++o) {
            float s = 0.0;
            uint k = 0u;
            for (; k + 4u <= out_next; k += 4u) {
                s += params[off_next + k * w + o] * mlp_act[k]
                   + params[off_next + (k + 1u) * w + o] * mlp_act[k + 1u]
                   + params[off_next + (k + 2u) * w + o] * mlp_act[k + 2u]
                   + params[off_next + (k + 3u) * w + o] * mlp_act[k + 3u];
            }
            for (; k < out_next; ++k) {
                s += params[off_next + k * w + o] * mlp_act[k];
            }
            uint at = (l * w + o) * pc.batch + i;
            deltas[at] = deltas[at] * s;
        }
    }
}
