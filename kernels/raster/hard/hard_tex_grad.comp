#version 460
#extension GL_GOOGLE_include_directive : require
// `texture`, backward, per lookup: the gradients to uv, uv_da and the bias, and the lookup's
// TAPS texel entries for the texels' gradients: entry i·TAPS + e holds the key of the texel it
// adds to (pc.texels where the tap reads nothing), its own index as the value (the sort keeps
// entries of one texel in this order) and the weight its lookup's output gradient is scaled by.
// `hard_tex_reduce.comp` sums them per texel after the sort. A cube map's lookup takes the
// gradient to (s, t) through the projection's Jacobian to its direction, and its level's through
// the Jacobian's own dependence on it. Twins: `texture::sample_backward`,
// `texture::sample_cube_backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Tex { float tex[]; };
layout(std430, set = 0, binding = 1) readonly buffer Uv { float uv[]; };
layout(std430, set = 0, binding = 2) readonly buffer UvDa { float uv_da[]; };
layout(std430, set = 0, binding = 3) readonly buffer Bias { float bias[]; };
layout(std430, set = 0, binding = 4) readonly buffer Dy { float dy[]; };
layout(std430, set = 0, binding = 5) writeonly buffer GradUv { float grad_uv[]; };
layout(std430, set = 0, binding = 6) writeonly buffer GradUvDa { float grad_uv_da[]; };
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
    if (CUBE && taps.corner < 4u) {
        // The corner's weight, a third each to the three texels its mean reads.
        uint j = taps.corner;
        precise float share = (j == 0u ? w00 : (j == 1u ? w10 : (j == 2u ? w01 : w11))) * ONE_THIRD;
        w00 = taps.corner == 0u ? 0.0 : w00 + share;
        w10 = taps.corner == 1u ? 0.0 : w10 + share;
        w01 = taps.corner == 2u ? 0.0 : w01 + share;
        w11 = taps.corner == 3u ? 0.0 : w11 + share;
    }
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
        vec4 a = tap_values(taps, k);
        float a00 = a.x;
        float a10 = a.y;
        float a01 = a.z;
        float a11 = a.w;
        float d = dy[i * c + k];
        precise float top = a00 + fs * (a10 - a00);
        precise float bottom = a01 + fs * (a11 - a01);
        dfs = dfs + d * ((a10 - a00) * (1.0 - ft) + (a11 - a01) * ft);
        dft = dft + d * (bottom - top);
    }
    return vec2(dfs, dft);
}

// The lookup's own gradients: to uv (dL/d(s, t), carried to the direction for a cube map, plus
// dL/dλ's share through the Jacobian), uv_da (dL/dλ times the level's gradient) and the bias
// (dL/dλ); `through_level`: linear-mipmap-linear between two levels (dl is 0 where λ clamps).
void own_grads(uint i, Lookup q, vec2 g_st, float dl, bool through_level) {
    bool has_da = pc.has_uv_da != 0u;
    if (pc.has_bias != 0u) {
        grad_bias[i] = through_level ? dl : 0.0;
    }
    if (!CUBE) {
        grad_uv[2u * i] = g_st.x;
        grad_uv[2u * i + 1u] = g_st.y;
        vec4 g = through_level && has_da ? dl * level_gradient(q.level_da) : vec4(0.0);
        for (uint k = 0u; has_da && k < 4u; ++k) {
            precise float gk = g[k];
            grad_uv_da[4u * i + k] = gk;
        }
        return;
    }
    vec3 gd = vec3(0.0);
    float gda[6] = float[6](0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    if (q.ok) {
        vec3 js = face_jacobian(q.p, 0u, q.dir);
        vec3 jt = face_jacobian(q.p, 1u, q.dir);
        if (through_level && has_da) {
            // Twin: `cube_level_gradient`, both parts zero where either is not finite.
            vec4 g = level_gradient(q.level_da);
            vec3 dx = vec3(q.da.x, q.da.z, q.dz.x);
            vec3 dy = vec3(q.da.y, q.da.w, q.dz.y);
            precise vec3 ld = g.x * face_hessian_times(q.p, 0u, q.dir, dx)
                            + g.y * face_hessian_times(q.p, 0u, q.dir, dy)
                            + g.z * face_hessian_times(q.p, 1u, q.dir, dx)
                            + g.w * face_hessian_times(q.p, 1u, q.dir, dy);
            precise vec3 lx = g.x * js + g.z * jt;
            precise vec3 ly = g.y * js + g.w * jt;
            bool finite = !any(isnan(ld)) && !any(isinf(ld)) && !any(isnan(lx))
                       && !any(isinf(lx)) && !any(isnan(ly)) && !any(isinf(ly));
            if (finite) {
                precise vec3 dld = dl * ld;
                gd = dld;
                for (uint k = 0u; k < 3u; ++k) {
                    precise float ax = dl * lx[k];
                    precise float ay = dl * ly[k];
                    gda[2u * k] = ax;
                    gda[2u * k + 1u] = ay;
                }
            }
        }
        precise vec3 through = g_st.x * js + g_st.y * jt;
        precise vec3 total = gd + through;
        gd = total;
    }
    for (uint k = 0u; k < 3u; ++k) {
        grad_uv[3u * i + k] = gd[k];
    }
    for (uint k = 0u; has_da && k < 6u; ++k) {
        grad_uv_da[6u * i + k] = gda[k];
    }
}

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.points) {
        return;
    }
    Lookup q = lookup(i);
    if (!q.ok) {
        for (uint e = 0u; e < TAPS; ++e) {
            entry(i, e, false, 0u, 0.0);
        }
        own_grads(i, q, vec2(0.0), 0.0, false);
        return;
    }
    if (FILTER == FILTER_NEAREST) {
        bool read;
        uint t = lookup_nearest(q, read);
        entry(i, 0u, read, t, 1.0);
        own_grads(i, q, vec2(0.0), 0.0, false);
        return;
    }
    uint l0 = 0u;
    uint l1 = 0u;
    float f = 0.0;
    float raw = 0.0;
    if (FILTER != FILTER_LINEAR) {
        raw = raw_level(q.level_da, q.bias);
        mip_levels(raw, l0, l1, f);
    }
    Taps a = lookup_taps(q, l0);
    vec2 ga = tap_slopes(i, a);
    // Only linear-mipmap-linear's fraction depends on the level inputs.
    bool two = FILTER == FILTER_MIPMAP_LINEAR && !(f == 0.0 && l0 == l1);
    precise float wa = two ? 1.0 - f : 1.0;
    tap_entries(i, 0u, a, wa);
    if (!two) {
        for (uint e = 4u; e < TAPS; ++e) {
            entry(i, e, false, 0u, 0.0);
        }
        own_grads(i, q, ga * a.scale, 0.0, false);
        return;
    }
    Taps b = lookup_taps(q, l1);
    vec2 gb = tap_slopes(i, b);
    tap_entries(i, 4u, b, f);
    precise vec2 g0 = wa * ga * a.scale;
    precise vec2 g1 = f * gb * b.scale;
    precise vec2 g_st = g0 + g1;
    // Through the fraction, where λ is not clamped: dλ = Σ dy (b − a).
    bool moving = raw > 0.0 && raw < float(pc.levels - 1u);
    precise float dl = 0.0;
    for (uint k = 0u; moving && k < pc.channels; ++k) {
        float va = bilerp(a, k);
        float vb = bilerp(b, k);
        dl = dl + dy[i * pc.channels + k] * (vb - va);
    }
    own_grads(i, q, g_st, dl, true);
}
