// nvdiffrast's `texture` (`softvk::raster::hard::texture`), what its kernels share: the push
// constants, the mip stack's addressing, the level of detail and the bilinear taps, in f32 on
// softvk's maths, every intermediate `precise`. Twin: `src/raster/hard/texture.rs` (f64), whose
// module docs give the behaviour; each function here names the twin function it follows.
//
// The stack is one float array: level 0 (the texture, `tex_items` items of H × W texels of C
// floats), then each mip level the same way, level l being max(W >> l, 1) × max(H >> l, 1).
// A texel's global index counts texels over the whole stack, so it names one texel of one item
// of one level: the backward's sort key.
#ifndef SOFTVK_TEXTURE_GLSL
#define SOFTVK_TEXTURE_GLSL

// Twin of `TexPush` (src/raster/hard/gpu/texture.rs); every texture kernel takes it.
layout(push_constant) uniform Push {
    uint width;        // W, H: the base level
    uint height;
    uint channels;     // C
    uint tex_items;    // textures in the stack: 1 (shared by every minibatch item) or B
    uint levels;       // levels in the stack, the base included
    uint points;       // lookups: B × h × w
    uint item_points;  // lookups a minibatch item (h × w)
    uint has_uv_da;    // 1: uv_da is bound and picks the level
    uint has_bias;     // 1: mip_level_bias is bound and is added to the level
    uint level;        // mip build: the level written; pyramid backward: the parent level
    uint entries;      // backward: texel entries (points × TAPS)
    uint texels;       // backward: texels over every level (the key of an absent tap)
} pc;

// The modes, as specialization constants (twin: `Filter`, `Boundary`).
const uint FILTER_NEAREST = 0u;
const uint FILTER_LINEAR = 1u;
const uint FILTER_MIPMAP_NEAREST = 2u;
const uint FILTER_MIPMAP_LINEAR = 3u;
const uint BOUNDARY_WRAP = 0u;
const uint BOUNDARY_CLAMP = 1u;
const uint BOUNDARY_ZERO = 2u;

layout(constant_id = 0) const uint FILTER = FILTER_LINEAR;
layout(constant_id = 1) const uint BOUNDARY = BOUNDARY_WRAP;

// Texel entries a lookup gives the backward: one texel for nearest, four taps for the bilinear
// modes, four on each of two levels for linear-mipmap-linear.
const uint TAPS = FILTER == FILTER_NEAREST ? 1u : (FILTER == FILTER_MIPMAP_LINEAR ? 8u : 4u);

// Sorted entries a partial sum of the backward covers (`PARTIAL_BLOCK` in gpu/texture.rs).
const uint PARTIAL_BLOCK = 256u;

const float LOG2_E = 1.44269504;  // 1 / ln 2

// Level l's texels across and down.
uvec2 level_size(uint l) {
    return uvec2(max(pc.width >> l, 1u), max(pc.height >> l, 1u));
}

// The global index of level l's first texel.
uint level_base(uint l) {
    uint base = 0u;
    for (uint k = 0u; k < l; ++k) {
        uvec2 s = level_size(k);
        base += pc.tex_items * s.x * s.y;
    }
    return base;
}

// The texture item lookup i reads.
uint tex_item(uint i) {
    return pc.tex_items == 1u ? 0u : i / pc.item_points;
}

// The footprint of uv_da in texels of the base level: (s_X, s_Y, t_X, t_Y), A = s_X² + t_X²,
// B = s_Y² + t_Y², C = s_X s_Y + t_X t_Y, the root √((A − B)²/4 + C²) and the major axis squared
// (A + B)/2 + root (twin: `level_of_detail`).
struct Footprint {
    vec4 st;
    float a;
    float b;
    float c;
    float root;
    float major;
};

Footprint footprint(vec4 da) {
    Footprint f;
    float w = float(pc.width);
    float h = float(pc.height);
    precise vec4 st = vec4(da.x * w, da.y * w, da.z * h, da.w * h);
    precise float a = st.x * st.x + st.z * st.z;
    precise float b = st.y * st.y + st.w * st.w;
    precise float c = st.x * st.y + st.z * st.w;
    precise float d = a - b;
    precise float root = fm_sqrt(0.25 * d * d + c * c);
    precise float major = 0.5 * (a + b) + root;
    f.st = st;
    f.a = a;
    f.b = b;
    f.c = c;
    f.root = root;
    f.major = major;
    return f;
}

// The level λ before the clamp (twin: `level_of_detail`): ½ log2 of the footprint's major axis
// squared, in texels of the base level, plus the bias.
float raw_level(vec4 da, float bias) {
    precise float level = 0.0;
    if (pc.has_uv_da != 0u) {
        Footprint f = footprint(da);
        level = 0.5 * LOG2_E * fm_log(f.major);
    }
    if (pc.has_bias != 0u) {
        level = level + bias;
    }
    return level;
}

// dλ/d(uv_da) (twin: `level_gradient`), zero where it is not finite (an isotropic or empty
// footprint).
vec4 level_gradient(vec4 da) {
    Footprint f = footprint(da);
    float w = float(pc.width);
    float h = float(pc.height);
    precise float k = fm_rcp(2.0 * f.major * 0.693147181);
    precise float q = fm_rcp(f.root);
    precise float half_d = 0.25 * (f.a - f.b) * q;
    precise float da_ = k * (0.5 + half_d);
    precise float db_ = k * (0.5 - half_d);
    precise float dc_ = k * f.c * q;
    vec4 st = f.st;  // (s_X, s_Y, t_X, t_Y)
    precise vec4 g = vec4(w * (2.0 * st.x * da_ + st.y * dc_), w * (2.0 * st.y * db_ + st.x * dc_),
                          h * (2.0 * st.z * da_ + st.w * dc_), h * (2.0 * st.w * db_ + st.z * dc_));
    bool finite = !any(isnan(g)) && !any(isinf(g));
    return f.root > 0.0 && f.major > 0.0 && finite ? g : vec4(0.0);
}

// The mipmap modes' levels (twin: `mip_levels`): ⌊λ⌋, the level above it within the stack and
// λ's fraction (0 for linear-mipmap-nearest and where λ clamps to 0); `raw` is λ unclamped.
void mip_levels(float raw, out uint l0, out uint l1, out float frac) {
    float top = float(pc.levels - 1u);
    float lambda = isnan(raw) ? 0.0 : clamp(raw, 0.0, top);
    float f0 = floor(lambda);
    l0 = uint(f0);
    if (FILTER == FILTER_MIPMAP_NEAREST || lambda <= 0.0) {
        l1 = l0;
        frac = 0.0;
        return;
    }
    l1 = uint(min(f0 + 1.0, top));
    precise float f = lambda - f0;
    frac = f;
}

// The four taps of bilinear filtering on one level (twin: `Taps::new`): the texels `00, 10,
// 01, 11` around (u w − ½, v h − ½) by the boundary mode, whether each is read (`zero` leaves
// taps outside), the weights' fractions and ds/du, dt/dv (zero where the clamp holds).
struct Taps {
    uint texel[4];  // global texel indices
    bool read[4];
    vec2 frac;
    vec2 scale;
};

Taps bilinear_taps(uint l, uint item, vec2 uv) {
    Taps taps;
    uvec2 size = level_size(l);
    float w = float(size.x);
    float h = float(size.y);
    precise float u = uv.x;
    precise float v = uv.y;
    if (BOUNDARY == BOUNDARY_WRAP) {
        u = u - floor(u);
        v = v - floor(v);
    }
    precise float s = u * w - 0.5;
    precise float t = v * h - 0.5;
    taps.scale = vec2(w, h);
    bool hold_s = false;
    bool hold_t = false;
    if (BOUNDARY == BOUNDARY_CLAMP) {
        taps.scale.x = s >= 0.0 && s <= w - 1.0 ? w : 0.0;
        taps.scale.y = t >= 0.0 && t <= h - 1.0 ? h : 0.0;
        s = clamp(s, 0.0, w - 1.0);
        t = clamp(t, 0.0, h - 1.0);
        hold_s = s == 0.0 || s == w - 1.0;
        hold_t = t == 0.0 || t == h - 1.0;
    }
    bool finite = !isnan(s) && !isinf(s) && !isnan(t) && !isinf(t);
    float s0 = finite ? floor(s) : 0.0;
    float t0 = finite ? floor(t) : 0.0;
    precise float fs = s - s0;
    precise float ft = t - t0;
    taps.frac = vec2(fs, ft);
    // Both taps of each axis, held within [−1, extent] so that the integers stay small.
    float xs[2] = float[2](s0, s0 + (hold_s ? 0.0 : 1.0));
    float ys[2] = float[2](t0, t0 + (hold_t ? 0.0 : 1.0));
    uint base = level_base(l) + item * size.x * size.y;
    for (uint k = 0u; k < 4u; ++k) {
        float x = clamp(xs[k & 1u], -1.0, w);
        float y = clamp(ys[k >> 1u], -1.0, h);
        if (BOUNDARY == BOUNDARY_WRAP) {
            x = x < 0.0 ? w - 1.0 : (x >= w ? 0.0 : x);
            y = y < 0.0 ? h - 1.0 : (y >= h ? 0.0 : y);
        }
        bool inside = x >= 0.0 && x <= w - 1.0 && y >= 0.0 && y <= h - 1.0;
        taps.read[k] = finite && inside;
        taps.texel[k] = base + uint(clamp(y, 0.0, h - 1.0)) * size.x + uint(clamp(x, 0.0, w - 1.0));
    }
    return taps;
}

// The base level's texel `nearest` reads (twin: `nearest_texel`); `read` false: zero.
uint nearest_texel(uint item, vec2 uv, out bool read) {
    float w = float(pc.width);
    float h = float(pc.height);
    precise float u = uv.x;
    precise float v = uv.y;
    if (BOUNDARY == BOUNDARY_WRAP) {
        u = u - floor(u);
        v = v - floor(v);
    }
    precise float su = u * w;
    precise float tv = v * h;
    float x = floor(su);
    float y = floor(tv);
    bool finite = !isnan(x) && !isinf(x) && !isnan(y) && !isinf(y);
    bool outside = x < 0.0 || x >= w || y < 0.0 || y >= h;
    read = finite && !(BOUNDARY == BOUNDARY_ZERO && outside);
    x = finite ? clamp(x, 0.0, w - 1.0) : 0.0;
    y = finite ? clamp(y, 0.0, h - 1.0) : 0.0;
    return (item * pc.height + uint(y)) * pc.width + uint(x);
}

#ifdef TEXTURE_READS
// Channel k of bilinear filtering over `taps`, from the stack the kernel binds as `tex` (twin:
// `bilinear`).
float bilerp(Taps taps, uint k) {
    uint c = pc.channels;
    float a00 = taps.read[0] ? tex[taps.texel[0] * c + k] : 0.0;
    float a10 = taps.read[1] ? tex[taps.texel[1] * c + k] : 0.0;
    float a01 = taps.read[2] ? tex[taps.texel[2] * c + k] : 0.0;
    float a11 = taps.read[3] ? tex[taps.texel[3] * c + k] : 0.0;
    precise float top = a00 + taps.frac.x * (a10 - a00);
    precise float bottom = a01 + taps.frac.x * (a11 - a01);
    precise float value = top + taps.frac.y * (bottom - top);
    return value;
}
#endif

#endif
