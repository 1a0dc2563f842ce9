#version 460
#extension GL_GOOGLE_include_directive : require
// `texture`, backward through `texture_construct_mip`: each texel of level pc.level gains its
// share (¼, or ½ where the level is one texel high or wide) of the gradient of the texel of
// level pc.level + 1 it was averaged into. Run from the last level up. Twin:
// `MipStack::pyramid_backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) buffer GradTex { float grad_tex[]; };

#include "texture.glsl"

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint l = pc.level;
    uvec2 size = level_size(l);
    uvec2 below = level_size(l + 1u);
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
    float share = size.x == 1u || size.y == 1u ? 0.5 : 0.25;
    uint child = level_base(l + 1u) + item * below.x * below.y
        + min(y / 2u, below.y - 1u) * below.x + min(x / 2u, below.x - 1u);
    uint at = level_base(l) + texel;
    precise float g = grad_tex[at * c + k] + share * grad_tex[child * c + k];
    grad_tex[at * c + k] = g;
}
