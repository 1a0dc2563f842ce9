#version 460
#extension GL_GOOGLE_include_directive : require
// Adam (`adam.glsl`) on whole texels of four parameters, one texel an invocation: texel j holds
// parameters 4j .. 4j + 3. On a CPU device a storage-buffer load is a scalar loop over the lanes
// with a branch per component, per load: a vec4 load runs that loop once for four parameters,
// where four float loads run it four times. The parameters past the last whole texel are
// `adam_step.comp`'s. Twin: `crate::fit::adam::cpu::step`.
#include "common.glsl"
#include "adam.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) buffer Params { vec4 params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Grads { vec4 grads[]; };
layout(std430, set = 0, binding = 2) buffer FirstMoment { vec4 m[]; };
layout(std430, set = 0, binding = 3) buffer SecondMoment { vec4 v[]; };

void main() {
    uint j = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (j >= pc.n) {
        return;
    }
    vec4 p = params[j];
    vec4 mj = m[j];
    vec4 vj = v[j];
    adam_update(p, grads[j], mj, vj);
    m[j] = mj;
    v[j] = vj;
    params[j] = p;
}
