#version 460
#extension GL_GOOGLE_include_directive : require
// `texture`, backward: the sorted entries in blocks of PARTIAL_BLOCK, one invocation per (block,
// channel): the sum, in entry order, of weight × output gradient over each texel's part of the
// block, written at that part's first entry (partials[i · C + k]). A texel's gradient is then
// the sum of its parts, block by block (`hard_tex_reduce.comp`): a fixed order, and no loop
// longer than a block or than the blocks of one run (llvmpipe stops loops at 65 535
// iterations; a coarse level's texel may gather every lookup of the image).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 1) readonly buffer Values { uint values[]; };
layout(std430, set = 0, binding = 2) readonly buffer Weights { float weights[]; };
layout(std430, set = 0, binding = 3) readonly buffer Dy { float dy[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Partials { float partials[]; };

#include "texture.glsl"

void main() {
    uint g = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint c = pc.channels;
    uint blocks = (pc.entries + PARTIAL_BLOCK - 1u) / PARTIAL_BLOCK;
    if (g >= blocks * c) {
        return;
    }
    uint k = g % c;
    uint first = (g / c) * PARTIAL_BLOCK;
    uint end = min(first + PARTIAL_BLOCK, pc.entries);
    uint head = first;
    uint key = keys[first].x;
    precise float sum = 0.0;
    for (uint j = first; j < end; ++j) {
        uint kj = keys[j].x;
        if (kj >= pc.texels) {
            break;  // the absent taps' entries, sorted last
        }
        if (kj != key) {
            partials[head * c + k] = sum;
            sum = 0.0;
            head = j;
            key = kj;
        }
        uint e = values[j];
        sum = sum + weights[e] * dy[(e / TAPS) * c + k];
    }
    if (key < pc.texels) {
        partials[head * c + k] = sum;
    }
}
