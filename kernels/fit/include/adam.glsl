// One Adam step with PyTorch's semantics (torch.optim.Adam, single-tensor path, no weight decay,
// no amsgrad), per parameter, in place:
//   m ← lerp(m, g, 1 − β1);  v ← β2 v + (1 − β2) g²;
//   p ← p − (lr / (1 − β1^t)) · m / (sqrt(v) / sqrt(1 − β2^t) + eps).
// The bias corrections are computed on the host in f64, as PyTorch does in Python floats.
// Shared by `adam_step.comp` (one parameter an invocation) and `adam_step4.comp` (four), which
// apply it to each parameter alike. Twin: `crate::fit::adam::cpu::step`.
#ifndef SOFTVK_ADAM_GLSL
#define SOFTVK_ADAM_GLSL

layout(push_constant) uniform Push {
    uint n;                // parameters (adam_step4: texels of four) this dispatch updates
    float lerp_weight;     // 1 − β1
    float beta2;
    float one_minus_beta2;
    float step_size;       // lr / (1 − β1^t)
    float bias2_sqrt;      // sqrt(1 − β2^t)
    float eps;
    uint first;            // adam_step: the first parameter (the ones before it are adam_step4's)
} pc;

// The step for four parameters (componentwise: each its own, as one at a time).
void adam_update(inout vec4 p, vec4 g, inout vec4 m, inout vec4 v) {
    // ATen's lerp: exact at both ends whichever side the weight is on.
    m = pc.lerp_weight < 0.5 ? m + pc.lerp_weight * (g - m)
                             : g - (g - m) * (1.0 - pc.lerp_weight);
    v = v * pc.beta2 + pc.one_minus_beta2 * (g * g);
    p -= pc.step_size * fm_div4v(m, fm_div4(fm_sqrt4(v), pc.bias2_sqrt) + pc.eps);
}

#endif
