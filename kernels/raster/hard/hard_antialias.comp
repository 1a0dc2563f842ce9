#version 460
#extension GL_GOOGLE_include_directive : require
// nvdiffrast's `antialias` forward, step 2: per (pixel, channel), out = color plus the blends of
// the pairs whose target it is, each α·(color[pixel 1] − color[pixel 0]) from the work list
// (`hard_antialias_pairs.comp`; pixel 0 is the target when α > 0, else pixel 1), added in the
// twin's global pair order (minibatch, rows from row 0, columns, right pair before next-row
// pair): the next-row pair from the pixel below, the right pair from the pixel to the left, then
// the pixel's own right pair, then its own next-row pair. One writer per output float.
// Twin: `antialias::antialias`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Color { float color[]; };
layout(std430, set = 0, binding = 1) readonly buffer Pairs { uvec4 pairs[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Out { float outs[]; };

#define HARD_NO_POSITIONS
#include "hard.glsl"
#include "hard_antialias.glsl"

// The blend of the pair (p0, p1) with record r in channel ch, when `first` says which of its
// pixels this one is and that pixel is the target; else nothing.
float blend(uvec2 r, uint p0, uint p1, uint ch, bool first, inout bool hit) {
    float alpha = uintBitsToFloat(r.x);
    hit = aa_blended(r.y) && aa_targets_first(alpha) == first;
    precise float d = color[p1 * pc.channels + ch] - color[p0 * pc.channels + ch];
    precise float term = alpha * d;
    return term;
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (id >= pc.batch * pixels * pc.channels) {
        return;
    }
    uint i = id / pc.channels;
    uint ch = id - i * pc.channels;
    uint p = i % pixels;
    uint y = p / pc.width;
    uint x = p - y * pc.width;
    precise float o = color[id];
    bool hit = false;
    if (y > 0u) {
        float term = blend(pairs[i - pc.width].zw, i - pc.width, i, ch, false, hit);
        if (hit) {
            o += term;
        }
    }
    if (x > 0u) {
        float term = blend(pairs[i - 1u].xy, i - 1u, i, ch, false, hit);
        if (hit) {
            o += term;
        }
    }
    uvec4 own = pairs[i];
    if (x + 1u < pc.width) {
        float term = blend(own.xy, i, i + 1u, ch, true, hit);
        if (hit) {
            o += term;
        }
    }
    if (y + 1u < pc.height) {
        float term = blend(own.zw, i, i + pc.width, ch, true, hit);
        if (hit) {
            o += term;
        }
    }
    outs[id] = o;
}
