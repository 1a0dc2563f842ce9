#version 460
#extension GL_GOOGLE_include_directive : require
// `texture`, forward: per lookup, the C values the filter and boundary modes (specialization
// constants FILTER, BOUNDARY) read from the mip stack at uv (a cube map's: at the direction),
// the mipmap modes on the levels that uv_da and the bias pick. Twins: `texture::sample`,
// `texture::sample_cube`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Tex { float tex[]; };
layout(std430, set = 0, binding = 1) readonly buffer Uv { float uv[]; };
layout(std430, set = 0, binding = 2) readonly buffer UvDa { float uv_da[]; };
layout(std430, set = 0, binding = 3) readonly buffer Bias { float bias[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Out { float out_tex[]; };

#define TEXTURE_READS
#include "texture.glsl"


void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.points) {
        return;
    }
    uint c = pc.channels;
    Lookup q = lookup(i);
    if (!q.ok) {
        for (uint k = 0u; k < c; ++k) {
            out_tex[i * c + k] = 0.0;
        }
        return;
    }
    if (FILTER == FILTER_NEAREST) {
        bool read;
        uint t = lookup_nearest(q, read);
        for (uint k = 0u; k < c; ++k) {
            out_tex[i * c + k] = read ? tex[t * c + k] : 0.0;
        }
        return;
    }
    uint l0 = 0u;
    uint l1 = 0u;
    float f = 0.0;
    if (FILTER != FILTER_LINEAR) {
        mip_levels(raw_level(q.level_da, q.bias), l0, l1, f);
    }
    Taps a = lookup_taps(q, l0);
    if (FILTER != FILTER_MIPMAP_LINEAR || (f == 0.0 && l0 == l1)) {
        for (uint k = 0u; k < c; ++k) {
            out_tex[i * c + k] = bilerp(a, k);
        }
        return;
    }
    Taps b = lookup_taps(q, l1);
    for (uint k = 0u; k < c; ++k) {
        float va = bilerp(a, k);
        float vb = bilerp(b, k);
        precise float value = va + f * (vb - va);
        out_tex[i * c + k] = value;
    }
}
