#version 460
#extension GL_GOOGLE_include_directive : require
// A strided sum to a scalar, one workgroup per component: workgroup k writes
// `outputs[out_index + k] = bias + scale * Σ_{i < n} values[i * stride + offset + k]`.
// Invocation t sums i = t, t + 256, ... in order, then the fixed tree of `fit_reduce.glsl`.
// Finishes every fit loss (per view, per vertex or per edge terms → one value) and the
// deformation's centre gradient. Twin: the plain f64 sums of each loss's twin.
#include "common.glsl"
#include "fit_reduce.glsl"

layout(local_size_x = 256) in;

layout(std430, set = 0, binding = 0) readonly buffer Values { float values[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Outputs { float outputs[]; };

layout(push_constant) uniform Push {
    uint n;
    uint stride;
    uint offset;
    uint out_index;
    float scale;
    float bias;
} pc;

void main() {
    uint component = linear_group_id(); // the host dispatches exactly one group per component
    float s = 0.0;
    for (uint i = gl_LocalInvocationIndex; i < pc.n; i += FIT_REDUCE_SIZE) {
        s += values[i * pc.stride + pc.offset + component];
    }
    float total = workgroup_sum(vec4(s, 0.0, 0.0, 0.0)).x;
    if (gl_LocalInvocationIndex == 0u) {
        outputs[pc.out_index + component] = pc.bias + pc.scale * total;
    }
}
