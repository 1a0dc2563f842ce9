// Shared by the `kernels/softvk/nn/` layer kernels (`crate::nn`): the fused activation, chosen by
// specialization constants (llvmpipe runs every branch of a push-constant mode, so the mode must
// be a constant for the dead ones to vanish), and the layers' push constants.
// Twins: `crate::nn::cpu::activate` and `crate::nn::cpu::derivative_from_output`.
#ifndef SOFTVK_NN_GLSL
#define SOFTVK_NN_GLSL

#define ACT_IDENTITY 0u
#define ACT_RELU 1u
#define ACT_LEAKY_RELU 2u
#define ACT_SIGMOID 3u
#define ACT_TANH 4u

layout(constant_id = 0) const uint ACT = ACT_IDENTITY;
// LeakyRelu's negative slope (> 0, so the derivative can be read from the output's sign).
layout(constant_id = 1) const float SLOPE = 0.2;

float activate(float x) {
    if (ACT == ACT_RELU) {
        return max(x, 0.0);
    } else if (ACT == ACT_LEAKY_RELU) {
        return x > 0.0 ? x : SLOPE * x;
    } else if (ACT == ACT_SIGMOID) {
        return fm_sigmoid(x);
    } else if (ACT == ACT_TANH) {
        // |x| ≥ 10 is ±1 in f32; the clamp keeps exp finite.
        float e = fm_exp(2.0 * clamp(x, -10.0, 10.0));
        return fm_div(e - 1.0, e + 1.0);
    }
    return x;
}

// d activate / dx, from the activation's output y.
float derivative_from_output(float y) {
    if (ACT == ACT_RELU) {
        return y > 0.0 ? 1.0 : 0.0;
    } else if (ACT == ACT_LEAKY_RELU) {
        return y > 0.0 ? 1.0 : SLOPE;
    } else if (ACT == ACT_SIGMOID) {
        return y * (1.0 - y);
    } else if (ACT == ACT_TANH) {
        return 1.0 - y * y;
    }
    return 1.0;
}

// Conv2d's shape and where its parameters start; `total` is the invocations that do work.
// Rust twin: `crate::nn::gpu::ConvPush`.
#define NN_CONV_PUSH                                                                             \
    layout(push_constant) uniform Push {                                                         \
        uint batch;                                                                              \
        uint in_c;                                                                               \
        uint in_h;                                                                               \
        uint in_w;                                                                               \
        uint out_c;                                                                              \
        uint out_h;                                                                              \
        uint out_w;                                                                              \
        uint kernel;                                                                             \
        uint stride;                                                                             \
        uint padding;                                                                            \
        uint param_offset;                                                                       \
        uint total;                                                                              \
    } pc;

// Linear's shape and where its parameters start. Rust twin: `crate::nn::gpu::LinearPush`.
#define NN_LINEAR_PUSH                                                                           \
    layout(push_constant) uniform Push {                                                         \
        uint batch;                                                                              \
        uint in_f;                                                                               \
        uint out_f;                                                                              \
        uint param_offset;                                                                       \
        uint total;                                                                              \
        uint pad0;                                                                               \
        uint pad1;                                                                               \
        uint pad2;                                                                               \
    } pc;

#endif
