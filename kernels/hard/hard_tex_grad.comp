#version 460
#extension GL_GOOGLE_include_directive : require
// `texture`, backward, per lookup: the gradients to uv, uv_da and the bias, and the lookup's
// TAPS texel entries for the texels' gradients: entry i·TAPS + e holds the key of the texel it
// adds to (pc.texels where the tap reads nothing), its own index as the value (the sort keeps
// entries of one texel in this order) and the weight its lookup's output gradient is scaled by.
// `hard_tex_reduce.comp` sums them per texel after the sort. Twin: `texture::sample_backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Tex { float tex[]; };
layout(std430, set = 0, binding = 1) readonly buffer Uv { vec2 uv[]; };
layout(std430, set = 0, binding = 2) readonly buffer UvDa { vec4 uv_da[]; };
layout(std430, set = 0, binding = 3) readonly buffer Bias { float bias[]; };
layout(std430, set = 0, binding = 4) readonly buffer Dy { float dy[]; };
layout(std430, set = 0, binding = 5) writeonly buffer GradUv { vec2 grad_uv[]; };
layout(std430, set = 0, binding = 6) writeonly buffer GradUvDa { vec4 grad_uv_da[]; };
layout(std430, set = 0, binding = 7) writeonly buffer GradBias { float grad_bias[]; };
layout(std430, set = 0, binding = 8) writeonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 9) writeonly buffer Values { uint values[]; };
layout(std430, set = 0, binding = 10) writeonly buffer Weights { float weights[]; };

#define TEXTURE_READS
#include "texture.glsl"

// Writes entry e of lookup i.
void entry(uint i, uint e, bool read, uint texel, float weight) {
    uint at = i * TAPS + e;
    keys[at] = uvec2(read ? texel : pc.texels, 0u);
    values[at] = at;
    weights[at] = weight;
}

// The four taps' entries, scaled by `scale`, from entry `first` on (twin: the texels' half
// of `bilinear_backward`).
void tap_entries(uint i, uint first, Taps taps, float scale) {
    precise float fs = taps.frac.x;
    precise float ft = taps.frac.y;
    precise float w00 = (1.0 - fs) * (1.0 - ft);
    precise float w10 = fs * (1.0 - ft);
    precise float w01 = (1.0 - fs) * ft;
    precise float w11 = fs * ft;
    precise float s00 = scale * w00;
    precise float s10 = scale * w10;
    precise float s01 = scale * w01;
    precise float s11 = scale * w11;
    entry(i, first, taps.read[0], taps.texel[0], s00);
    entry(i, first + 1u, taps.read[1], taps.texel[1], s10);
    entry(i, first + 2u, taps.read[2], taps.texel[2], s01);
    entry(i, first + 3u, taps.read[3], taps.texel[3], s11);
}

// d(output · dy)/d(s, t) on one level, before ds/du (twin: the uv half of
// `bilinear_backward`).
vec2 tap_slopes(uint i, Taps taps) {
    uint c = pc.channels;
    precise float fs = taps.frac.x;
    precise float ft = taps.frac.y;
    precise float dfs = 0.0;
    precise float dft = 0.0;
    for (uint k = 0u; k < c; ++k) {
        float a00 = taps.read[0] ? tex[taps.texel[0] * c + k] : 0.0;
        float a10 = taps.read[1] ? tex[taps.texel[1] * c + k] : 0.0;
        float a01 = taps.read[2] ? tex[taps.texel[2] * c + k] : 0.0;
        float a11 = taps.read[3] ? tex[taps.texel[3] * c + k] : 0.0;
        float d = dy[i * c + k];
        precise float top = a00 + fs * (a10 - a00);
        precise float bottom = a01 + fs * (a11 - a01);
        dfs = dfs + d * ((a10 - a00) * (1.0 - ft) + (a11 - a01) * ft);
        dft = dft + d * (bottom - top);
    }
    return vec2(dfs, dft);
}

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.points) {
        return;
    }
    uint item = tex_item(i);
    vec2 p = uv[i];
    // Only linear-mipmap-linear's fraction depends on the level inputs.
    bool level_grads = FILTER == FILTER_MIPMAP_LINEAR;
    if (pc.has_uv_da != 0u && !level_grads) {
        grad_uv_da[i] = vec4(0.0);
    }
    if (pc.has_bias != 0u && !level_grads) {
        grad_bias[i] = 0.0;
    }
    if (FILTER == FILTER_NEAREST) {
        bool read;
        uint t = nearest_texel(item, p, read);
        entry(i, 0u, read, t, 1.0);
        grad_uv[i] = vec2(0.0);
        return;
    }
    uint l0 = 0u;
    uint l1 = 0u;
    float f = 0.0;
    float raw = 0.0;
    vec4 da = pc.has_uv_da != 0u ? uv_da[i] : vec4(0.0);
    if (FILTER != FILTER_LINEAR) {
        raw = raw_level(da, pc.has_bias != 0u ? bias[i] : 0.0);
        mip_levels(raw, l0, l1, f);
    }
    Taps a = bilinear_taps(l0, item, p);
    vec2 ga = tap_slopes(i, a);
    bool two = FILTER == FILTER_MIPMAP_LINEAR && !(f == 0.0 && l0 == l1);
    precise float wa = two ? 1.0 - f : 1.0;
    tap_entries(i, 0u, a, wa);
    if (FILTER != FILTER_MIPMAP_LINEAR) {
        grad_uv[i] = ga * a.scale;
        return;
    }
    if (!two) {
        for (uint e = 4u; e < 8u; ++e) {
            entry(i, e, false, 0u, 0.0);
        }
        grad_uv[i] = ga * a.scale;
        if (pc.has_uv_da != 0u) {
            grad_uv_da[i] = vec4(0.0);
        }
        if (pc.has_bias != 0u) {
            grad_bias[i] = 0.0;
        }
        return;
    }
    Taps b = bilinear_taps(l1, item, p);
    vec2 gb = tap_slopes(i, b);
    tap_entries(i, 4u, b, f);
    precise vec2 g0 = wa * ga * a.scale;
    precise vec2 g1 = f * gb * b.scale;
    grad_uv[i] = g0 + g1;
    // Through the fraction, where λ is not clamped: dλ = Σ dy (b − a).
    bool moving = raw > 0.0 && raw < float(pc.levels - 1u);
    precise float dl = 0.0;
    for (uint k = 0u; moving && k < pc.channels; ++k) {
        float va = bilerp(a, k);
        float vb = bilerp(b, k);
        dl = dl + dy[i * pc.channels + k] * (vb - va);
    }
    if (pc.has_bias != 0u) {
        grad_bias[i] = dl;
    }
    if (pc.has_uv_da != 0u) {
        precise vec4 g = dl * level_gradient(da);
        grad_uv_da[i] = g;
    }
}
