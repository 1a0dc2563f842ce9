#version 460
#extension GL_GOOGLE_include_directive : require
// nvdiffrast's `antialias` backward, last step where `pos_gradient_boost` ≠ 1: per float of the
// position gradient (rows × dims / 3 of them, after `hard_grad_gather.comp`), its product with
// the boost (f32, rounded once on the host), in place. One writer per float.
// Twin: the boost loop of `antialias::antialias_backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Boost { float boost; };
layout(std430, set = 0, binding = 1) buffer Grads { float grads[]; };

#define HARD_NO_POSITIONS
#include "hard.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.rows * (pc.dims / 3u)) {
        return;
    }
    precise float g = grads[id] * boost;
    grads[id] = g;
}
