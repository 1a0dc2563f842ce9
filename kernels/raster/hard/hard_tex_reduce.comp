#version 460
#extension GL_GOOGLE_include_directive : require
// `texture`, backward: each texel's gradient, channel by channel, the sum of its run's parts
// block by block (`hard_tex_partials.comp`): in the lookups' order, then the taps', the same
// on every device and run. Every texel of every level is written. Twin:
// `texture::sample_backward`'s `add_texel`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Runs { uvec2 runs[]; };
layout(std430, set = 0, binding = 1) readonly buffer Partials { float partials[]; };
layout(std430, set = 0, binding = 2) writeonly buffer GradTex { float grad_tex[]; };

#include "texture.glsl"

void main() {
    uint g = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint c = pc.channels;
    if (g >= pc.texels * c) {
        return;
    }
    uint t = g / c;
    uint k = g % c;
    uvec2 run = runs[t];
    precise float sum = 0.0;
    if (run.y > run.x) {
        sum = partials[run.x * c + k];
        uint last = (run.y - 1u) / PARTIAL_BLOCK;
        for (uint b = run.x / PARTIAL_BLOCK + 1u; b <= last; ++b) {
            sum = sum + partials[b * PARTIAL_BLOCK * c + k];
        }
    }
    grad_tex[g] = sum;
}
