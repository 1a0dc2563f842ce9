#version 460
#extension GL_GOOGLE_include_directive : require
// nvdiffrast's `antialias` backward, the colour gradient: per (pixel, channel), dy plus, for
// every blended pair (α not +0.0) the pixel belongs to, −α·g as its pixel 0 or +α·g as its
// pixel 1, g = dy at the pair's target (pixel 0 when α > 0, else pixel 1), from the work list
// (`hard_antialias_pairs.comp`), in the twin's global pair order: the next-row pair from the
// pixel below, the right pair from the pixel to the left, the pixel's own right pair, its own
// next-row pair. One writer per output float. Twin: `antialias::antialias_backward` (colour).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Dy { float dy[]; };
layout(std430, set = 0, binding = 1) readonly buffer Pairs { uvec4 pairs[]; };
layout(std430, set = 0, binding = 2) writeonly buffer GradColor { float grad_color[]; };

#define HARD_NO_POSITIONS
#include "hard.glsl"
#include "hard_antialias.glsl"

// α·g of the pair (p0, p1) with record r in channel ch; `hit` whether it counts.
float share(uvec2 r, uint p0, uint p1, uint ch, out bool hit) {
    float alpha = uintBitsToFloat(r.x);
    hit = aa_blended(r.y) && r.x != 0u;
    uint target = aa_targets_first(alpha) ? p0 : p1;
    precise float s = alpha * dy[target * pc.channels + ch];
    return s;
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
    precise float g = dy[id];
    bool hit;
    if (y > 0u) {
        float s = share(pairs[i - pc.width].zw, i - pc.width, i, ch, hit);
        if (hit) {
            g += s;
        }
    }
    if (x > 0u) {
        float s = share(pairs[i - 1u].xy, i - 1u, i, ch, hit);
        if (hit) {
            g += s;
        }
    }
    uvec4 own = pairs[i];
    if (x + 1u < pc.width) {
        float s = share(own.xy, i, i + 1u, ch, hit);
        if (hit) {
            g -= s;
        }
    }
    if (y + 1u < pc.height) {
        float s = share(own.zw, i, i + pc.width, ch, hit);
        if (hit) {
            g -= s;
        }
    }
    grad_color[id] = g;
}
