#version 460
#extension GL_GOOGLE_include_directive : require
// One of softvk's maths functions (`fmath.glsl`) on every element: out[i] = f(a[i], b[i]) for
// i < n, with f chosen by `pc.function` (the order of `crate::fmath::Function`). The check that
// a device computes them as their CPU twin does (`crate::fmath`), bit for bit.
#include "common.glsl"
#include "fmath.glsl"

layout(local_size_x = 256) in;

layout(std430, set = 0, binding = 0) readonly buffer A { float a[]; };
layout(std430, set = 0, binding = 1) readonly buffer B { float b[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Out { float outputs[]; };

layout(push_constant) uniform Push {
    uint n;
    uint function;
} pc;

void main() {
    uint i = linear_group_id() * 256u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    float x = a[i];
    float y = b[i];
    float r;
    switch (pc.function) {
        case 0u: r = fm_rcp(x); break;
        case 1u: r = fm_rcp_1_2(x); break;
        case 2u: r = fm_div(x, y); break;
        case 3u: r = fm_div_rn(x, y); break;
        case 4u: r = fm_sqrt(x); break;
        case 5u: r = fm_exp(x); break;
        case 6u: r = fm_exp_le0(x); break;
        case 7u: r = fm_expm1(x); break;
        case 8u: r = fm_log(x); break;
        case 9u: r = fm_sigmoid(x); break;
        case 10u: r = fm_sigmoid_grad(x); break;
        case 11u: r = fm_tanh(x); break;
        case 12u: r = fm_pow(x, y); break;
        case 13u: r = fm_sin(x); break;
        case 14u: r = fm_cos(x); break;
        default: r = fm_rcp_pos(x); break;
    }
    outputs[i] = r;
}
