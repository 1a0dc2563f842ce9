#version 460
#extension GL_GOOGLE_include_directive : require
// `texture`, backward: after the entries' sort by texel, where each texel's run of entries
// begins and ends (runs[texel] = (first, end); texels with no entry keep the (0, 0) the host
// filled in).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) buffer Runs { uvec2 runs[]; };

#include "texture.glsl"

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.entries) {
        return;
    }
    uint key = keys[i].x;
    if (key >= pc.texels) {
        return;
    }
    if (i == 0u || keys[i - 1u].x != key) {
        runs[key].x = i;
    }
    if (i + 1u == pc.entries || keys[i + 1u].x != key) {
        runs[key].y = i + 1u;
    }
}
