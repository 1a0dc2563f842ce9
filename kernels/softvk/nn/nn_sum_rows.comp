#version 460
#extension GL_GOOGLE_include_directive : require
// Deterministic sum over rows: sums[dst_offset + j] = Σ_{r < rows}, in order, rows_in[r · cols + j].
// Reduces Conv2d's per-sample parameter gradients (`nn_conv_wgrad`) over the batch.
// Twin: the batch sum of `crate::nn::cpu::conv2d_backward` (d_params accumulated sample by
// sample in order).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rows { float rows_in[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Sums { float sums[]; };

layout(push_constant) uniform Push {
    uint rows;
    uint cols;
    uint dst_offset;
    uint pad;
} pc;

void main() {
    uint j = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (j >= pc.cols) {
        return;
    }
    float s = 0.0;
    for (uint r = 0u; r < pc.rows; ++r) {
        s += rows_in[r * pc.cols + j];
    }
    sums[pc.dst_offset + j] = s;
}
