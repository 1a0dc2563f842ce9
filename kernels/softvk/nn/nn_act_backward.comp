#version 460
#extension GL_GOOGLE_include_directive : require
// Through a layer's fused activation, from its output: d_pre[i] = d_out[i] · act'(out[i])
// (relu: out > 0; leaky: out > 0 ? 1 : slope; sigmoid: out (1 − out); tanh: 1 − out²).
// Twin: `crate::nn::cpu::derivative_from_output`, as `crate::nn::cpu::conv2d_backward` and
// `crate::nn::cpu::linear_backward` apply it.
#include "common.glsl"
#include "nn.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Output { float outp[]; };
layout(std430, set = 0, binding = 1) readonly buffer DOut { float d_out[]; };
layout(std430, set = 0, binding = 2) writeonly buffer DPre { float d_pre[]; };

layout(push_constant) uniform Push {
    uint n;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    d_pre[i] = d_out[i] * derivative_from_output(outp[i]);
}
