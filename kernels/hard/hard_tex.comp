#version 460
#extension GL_GOOGLE_include_directive : require
// `texture`, forward: per lookup, the C values the filter and boundary modes (specialization
// constants FILTER, BOUNDARY) read from the mip stack at uv, the mipmap modes on the levels
// that uv_da and the bias pick. Twin: `texture::sample`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Tex { float tex[]; };
layout(std430, set = 0, binding = 1) readonly buffer Uv { vec2 uv[]; };
layout(std430, set = 0, binding = 2) readonly buffer UvDa { vec4 uv_da[]; };
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
    uint item = tex_item(i);
    vec2 p = uv[i];
    if (FILTER == FILTER_NEAREST) {
        bool read;
        uint t = nearest_texel(item, p, read);
        for (uint k = 0u; k < c; ++k) {
            out_tex[i * c + k] = read ? tex[t * c + k] : 0.0;
        }
        return;
    }
    uint l0 = 0u;
    uint l1 = 0u;
    float f = 0.0;
    if (FILTER != FILTER_LINEAR) {
        float raw = raw_level(pc.has_uv_da != 0u ? uv_da[i] : vec4(0.0),
                              pc.has_bias != 0u ? bias[i] : 0.0);
        mip_levels(raw, l0, l1, f);
    }
    Taps a = bilinear_taps(l0, item, p);
    if (FILTER != FILTER_MIPMAP_LINEAR || (f == 0.0 && l0 == l1)) {
        for (uint k = 0u; k < c; ++k) {
            out_tex[i * c + k] = bilerp(a, k);
        }
        return;
    }
    Taps b = bilinear_taps(l1, item, p);
    for (uint k = 0u; k < c; ++k) {
        float va = bilerp(a, k);
        float vb = bilerp(b, k);
        precise float value = va + f * (vb - va);
        out_tex[i * c + k] = value;
    }
}
