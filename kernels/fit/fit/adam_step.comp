#version 460
#extension GL_GOOGLE_include_directive : require
// Adam (`adam.glsl`) on parameters `first .. n`, one an invocation: the tail of a vector whose
// whole texels of four `adam_step4.comp` updates, or all of it. Twin: `crate::fit::adam::cpu::step`.
#include "common.glsl"
#include "adam.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Grads { float grads[]; };
layout(std430, set = 0, binding = 2) buffer FirstMoment { float m[]; };
layout(std430, set = 0, binding = 3) buffer SecondMoment { float v[]; };

void main() {
    uint i = pc.first + linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.n) {
        return;
    }
    vec4 p = vec4(params[i]);
    vec4 mi = vec4(m[i]);
    vec4 vi = vec4(v[i]);
    adam_update(p, vec4(grads[i]), mi, vi);
    m[i] = mi.x;
    v[i] = vi.x;
    params[i] = p.x;
}
