#version 460
#extension GL_GOOGLE_include_directive : require
// `texture_construct_mip`: mip level pc.level of the stack from the level above it, each texel
// the mean of the 2 × 2 texels it covers (2 × 1 where the level above is one texel high or
// wide). Twin: `MipStack::build` (the same order of additions).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) buffer Tex { float tex[]; };

#include "texture.glsl"

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint l = pc.level;
    uvec2 size = level_size(l);
    uvec2 above = level_size(l - 1u);
    uint c = pc.channels;
    uint per_item = size.x * size.y;
    if (i >= pc.tex_items * per_item * c) {
        return;
    }
    uint k = i % c;
    uint texel = i / c;
    uint item = texel / per_item;
    uint x = texel % size.x;
    uint y = (texel % per_item) / size.x;
    uint src = level_base(l - 1u) + item * above.x * above.y;
    uint dst = level_base(l) + texel;
    float value;
    if (above.x == 1u || above.y == 1u) {
        uint a = above.y == 1u ? src + 2u * x : src + 2u * y;
        uint b = a + 1u;
        precise float sum = tex[a * c + k] + tex[b * c + k];
        value = 0.5 * sum;
    } else {
        uint r0 = src + 2u * y * above.x + 2u * x;
        uint r1 = r0 + above.x;
        precise float sum = tex[r0 * c + k] + tex[(r0 + 1u) * c + k] + tex[r1 * c + k]
            + tex[(r1 + 1u) * c + k];
        value = 0.25 * sum;
    }
    tex[dst * c + k] = value;
}
