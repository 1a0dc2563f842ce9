#version 460
#extension GL_GOOGLE_include_directive : require
// One Adam step with PyTorch's semantics (torch.optim.Adam, single-tensor path, no weight decay,
// no amsgrad), per parameter, in place:
//   m ← lerp(m, g, 1 − β1);  v ← β2 v + (1 − β2) g²;
//   p ← p − (lr / (1 − β1^t)) · m / (sqrt(v) / sqrt(1 − β2^t) + eps).
// The bias corrections are computed on the host in f64, as PyTorch does in Python floats.
// Twin: `crate::fit::adam::cpu::step`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Grads { float grads[]; };
layout(std430, set = 0, binding = 2) buffer FirstMoment { float m[]; };
layout(std430, set = 0, binding = 3) buffer SecondMoment { float v[]; };

layout(push_constant) uniform Push {
    uint n;
    float lerp_weight;     // 1 − β1
    float beta2;
    float one_minus_beta2;
    float step_size;       // lr / (1 − β1^t)
    float bias2_sqrt;      // sqrt(1 − β2^t)
    float eps;
    uint pad;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    float g = grads[i];
    float mi = m[i];
    // ATen's lerp: exact at both ends whichever side the weight is on.
    mi = pc.lerp_weight < 0.5 ? mi + pc.lerp_weight * (g - mi)
                              : g - (g - mi) * (1.0 - pc.lerp_weight);
    float vi = v[i] * pc.beta2 + pc.one_minus_beta2 * (g * g);
    m[i] = mi;
    v[i] = vi;
    params[i] -= pc.step_size * (mi / (sqrt(vi) / pc.bias2_sqrt + pc.eps));
}
