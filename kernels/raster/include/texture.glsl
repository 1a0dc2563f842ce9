// nvdiffrast's `texture` (`softvk::raster::hard::texture`), what its kernels share: the push
// constants, the mip stack's addressing, the level of detail and the bilinear taps, in f32 on
// softvk's maths, every intermediate `precise`; then a cube map's face projection and seamless
// taps. Twins: `src/raster/hard/texture/` and `cube/` (f64), whose module docs give the
// behaviour; each function here names the twin function it follows.
//
// The stack is one float array: level 0 (the texture, `tex_items` items of H × W texels of C
// floats), then each mip level the same way, level l being max(W >> l, 1) × max(H >> l, 1).
// A texel's global index counts texels over the whole stack, so it names one texel of one item
// of one level: the backward's sort key.
#ifndef SOFTVK_TEXTURE_GLSL
#define SOFTVK_TEXTURE_GLSL

// Twin of `TexPush` (src/raster/hard/gpu/texture/mod.rs); every texture kernel takes it.
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
const uint BOUNDARY_CUBE = 3u;  // a cube map: `items` are faces, six a cube; uv a direction

layout(constant_id = 0) const uint FILTER = FILTER_LINEAR;
layout(constant_id = 1) const uint BOUNDARY = BOUNDARY_WRAP;

const bool CUBE = BOUNDARY == BOUNDARY_CUBE;
// Floats of a lookup's uv (a 2D coordinate, or a cube map's direction) and uv_da.
const uint UV_DIM = CUBE ? 3u : 2u;
const uint DA_DIM = CUBE ? 6u : 4u;

// Texel entries a lookup gives the backward: one texel for nearest, four taps for the bilinear
// modes, four on each of two levels for linear-mipmap-linear.
const uint TAPS = FILTER == FILTER_NEAREST ? 1u : (FILTER == FILTER_MIPMAP_LINEAR ? 8u : 4u);

// Sorted entries a partial sum of the backward covers (`PARTIAL_BLOCK` in gpu/texture/mod.rs).
const uint PARTIAL_BLOCK = 256u;

const float LOG2_E = 1.44269504;  // 1 / ln 2
const float ONE_THIRD = 0.333333343;  // 1/3 rounded: a cube corner tap's share (no division)

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
    uint corner;  // a cube map's tap beyond a cube corner (its value the mean of the others); 4: none
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
    taps.corner = 4u;
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

// ---- Cube maps (twin: `texture::cube`) ----

// A direction's face by OpenGL's cube-map table (twin: `Projection`): the major axis (ties to
// x, then y; a zero is positive), the face +x, −x, +y, −y, +z, −z, the axes and signs of the
// numerators of s and t, and `ok`: whether (s, t) are finite.
struct Projection {
    uint face;
    uint major;
    uvec2 axes;
    vec2 signs;
    bool ok;
    vec2 st;  // (s, t) clamped to [0, 1]
};

Projection projection(vec3 d) {
    Projection p;
    vec3 a = abs(d);
    p.major = a.z > max(a.x, a.y) ? 2u : (a.y > a.x ? 1u : 0u);
    p.face = 2u * p.major + (d[p.major] < 0.0 ? 1u : 0u);
    // s: (axis, sign) +x (z, −), −x (z, +), ±y (x, +), +z (x, +), −z (x, −);
    // t: ±x (y, −), +y (z, +), −y (z, −), ±z (y, −).
    uint f = p.face;
    p.axes = uvec2(p.major == 0u ? 2u : 0u, p.major == 1u ? 2u : 1u);
    p.signs = vec2(f == 0u || f == 5u ? -1.0 : 1.0, f == 2u ? 1.0 : -1.0);
    precise float r = fm_rcp(2.0 * a[p.major]);
    precise float s = p.signs.x * d[p.axes.x] * r + 0.5;
    precise float t = p.signs.y * d[p.axes.y] * r + 0.5;
    p.ok = !isnan(s) && !isinf(s) && !isnan(t) && !isinf(t);
    p.st = p.ok ? clamp(vec2(s, t), 0.0, 1.0) : vec2(0.0);
    return p;
}

// The point (s, t) of `face`'s plane, (s, t) outside [0, 1] continuing it (twin:
// `cube_direction`).
vec3 cube_direction(uint face, float s, float t) {
    precise float a = 2.0 * s - 1.0;
    precise float b = 2.0 * t - 1.0;
    switch (face) {
        case 0u: return vec3(1.0, -b, -a);
        case 1u: return vec3(-1.0, -b, a);
        case 2u: return vec3(a, 1.0, b);
        case 3u: return vec3(a, -1.0, -b);
        case 4u: return vec3(a, -b, 1.0);
        default: return vec3(-a, -b, -1.0);
    }
}

// ∂s/∂d (j = 0) or ∂t/∂d, the face held fixed (twin: `Projection::jacobian`).
vec3 face_jacobian(Projection p, uint j, vec3 d) {
    uint a = j == 0u ? p.axes.x : p.axes.y;
    float m = d[p.major];
    precise float k = 0.5 * (j == 0u ? p.signs.x : p.signs.y) * (m < 0.0 ? -1.0 : 1.0);
    precise float r = fm_rcp(m);
    precise float ga = k * r;
    precise float gm = -(k * d[a]) * (r * r);
    vec3 g = vec3(0.0);
    g[a] = ga;
    g[p.major] = gm;
    return g;
}

// s's (j = 0) or t's second derivatives in d times v, the face held fixed (twin:
// `Projection::hessians`).
vec3 face_hessian_times(Projection p, uint j, vec3 d, vec3 v) {
    uint a = j == 0u ? p.axes.x : p.axes.y;
    uint mj = p.major;
    float m = d[mj];
    precise float k = 0.5 * (j == 0u ? p.signs.x : p.signs.y) * (m < 0.0 ? -1.0 : 1.0);
    precise float r = fm_rcp(m);
    precise float h = -k * (r * r);
    precise float hmm = 2.0 * k * d[a] * (r * r * r);
    precise float oa = h * v[mj];
    precise float om = h * v[a] + hmm * v[mj];
    vec3 o = vec3(0.0);
    o[a] = oa;
    o[mj] = om;
    return o;
}

// a · b summed x, y, z in order (GLSL's dot leaves the order to the driver).
float dot3(vec3 a, vec3 b) {
    precise float r = a.x * b.x + a.y * b.y + a.z * b.z;
    return r;
}

// uv_da (dx/dX, dx/dY, dy/dX, dy/dY, dz/dX, dz/dY), held as `da` (its first four) and `dz`
// (its last two), carried onto the face: (ds/dX, ds/dY, dt/dX, dt/dY), zero where not finite
// (twin: `cube_face_derivatives`).
vec4 face_derivatives(Projection p, vec3 d, vec4 da, vec2 dz) {
    if (!p.ok) {
        return vec4(0.0);
    }
    vec3 js = face_jacobian(p, 0u, d);
    vec3 jt = face_jacobian(p, 1u, d);
    vec3 dx = vec3(da.x, da.z, dz.x);
    vec3 dy = vec3(da.y, da.w, dz.y);
    precise vec4 w = vec4(dot3(js, dx), dot3(js, dy), dot3(jt, dx), dot3(jt, dy));
    return any(isnan(w)) || any(isinf(w)) ? vec4(0.0) : w;
}

// The texel a face coordinate falls in, on a face n texels across (twin: `texel_of`).
uint texel_of(float x, float n) {
    precise float xn = x * n;
    return uint(clamp(floor(xn), 0.0, n - 1.0));
}

// The four taps of seamless bilinear filtering of cube `cube`'s `face` on level l (twin:
// `CubeTaps::new`): a tap past one edge reads the neighbouring face's texel its centre, on
// this face's plane, projects into; one past two (beyond a cube corner) is `corner`.
Taps cube_taps(uint l, uint cube, uint face, vec2 st) {
    Taps taps;
    uint n = level_size(l).x;
    float nf = float(n);
    precise float u = st.x * nf - 0.5;
    precise float v = st.y * nf - 0.5;
    float u0 = floor(u);
    float v0 = floor(v);
    precise float fu = u - u0;
    precise float fv = v - v0;
    taps.frac = vec2(fu, fv);
    taps.scale = vec2(nf);
    taps.corner = 4u;
    float inv = fm_rcp(nf);
    uint base = level_base(l) + cube * 6u * n * n;
    for (uint k = 0u; k < 4u; ++k) {
        float x = u0 + float(k & 1u);
        float y = v0 + float(k >> 1u);
        bool ix = x >= 0.0 && x < nf;
        bool iy = y >= 0.0 && y < nf;
        taps.read[k] = ix || iy;
        if (ix && iy) {
            taps.texel[k] = base + (face * n + uint(y)) * n + uint(x);
        } else if (ix || iy) {
            precise float cs = (x + 0.5) * inv;
            precise float ct = (y + 0.5) * inv;
            Projection q = projection(cube_direction(face, cs, ct));
            taps.texel[k] = base + (q.face * n + texel_of(q.st.y, nf)) * n + texel_of(q.st.x, nf);
        } else {
            taps.corner = k;
            taps.texel[k] = base;
        }
    }
    return taps;
}

// The base level's texel `nearest` reads on a cube map (twin: `sample_cube`).
uint cube_nearest_texel(uint cube, Projection p) {
    float n = float(pc.width);
    return ((cube * 6u + p.face) * pc.width + texel_of(p.st.y, n)) * pc.width + texel_of(p.st.x, n);
}

#ifdef TEXTURE_READS
// One lookup as the filters take it, from the `uv`, `uv_da` and `bias` the kernel binds (float
// arrays, UV_DIM and DA_DIM a lookup): the texture item (a 2D texture's, or the cube's), the
// coordinate (uv, or the face's (s, t)), `ok` (false: a direction with no face, read as zero),
// and the level's inputs (uv_da, or the face's derivatives).
struct Lookup {
    uint item;
    vec2 uv;
    bool ok;
    Projection p;
    vec3 dir;
    vec4 da;  // uv_da's first four floats (a 2D texture's all)
    vec2 dz;  // a cube map's last two (dz/dX, dz/dY)
    vec4 level_da;
    float bias;
};

Lookup lookup(uint i) {
    Lookup q;
    q.item = pc.tex_items == (CUBE ? 6u : 1u) ? 0u : i / pc.item_points;
    q.ok = true;
    bool has_da = pc.has_uv_da != 0u;
    uint at = i * DA_DIM;
    q.da = has_da ? vec4(uv_da[at], uv_da[at + 1u], uv_da[at + 2u], uv_da[at + 3u]) : vec4(0.0);
    q.dz = CUBE && has_da ? vec2(uv_da[at + 4u], uv_da[at + 5u]) : vec2(0.0);
    q.bias = pc.has_bias != 0u ? bias[i] : 0.0;
    if (CUBE) {
        q.dir = vec3(uv[3u * i], uv[3u * i + 1u], uv[3u * i + 2u]);
        q.p = projection(q.dir);
        q.ok = q.p.ok;
        q.uv = q.p.st;
        q.level_da = has_da ? face_derivatives(q.p, q.dir, q.da, q.dz) : vec4(0.0);
    } else {
        q.dir = vec3(0.0);
        q.uv = vec2(uv[2u * i], uv[2u * i + 1u]);
        q.level_da = q.da;
    }
    return q;
}

// The bilinear taps of a lookup on level l.
Taps lookup_taps(Lookup q, uint l) {
    return CUBE ? cube_taps(l, q.item, q.p.face, q.uv) : bilinear_taps(l, q.item, q.uv);
}

// The base level's texel `nearest` reads; `read` false: zero.
uint lookup_nearest(Lookup q, out bool read) {
    if (CUBE) {
        read = q.ok;
        return cube_nearest_texel(q.item, q.p);
    }
    return nearest_texel(q.item, q.uv, read);
}

// Channel k of the four taps from the stack the kernel binds as `tex`, a corner's the mean of
// the other three (twin: `CubeTaps::values`).
vec4 tap_values(Taps taps, uint k) {
    uint c = pc.channels;
    vec4 a = vec4(taps.read[0] ? tex[taps.texel[0] * c + k] : 0.0,
                  taps.read[1] ? tex[taps.texel[1] * c + k] : 0.0,
                  taps.read[2] ? tex[taps.texel[2] * c + k] : 0.0,
                  taps.read[3] ? tex[taps.texel[3] * c + k] : 0.0);
    if (CUBE && taps.corner < 4u) {
        precise float sum = a.x + a.y + a.z + a.w;
        precise float mean = sum * ONE_THIRD;
        uint j = taps.corner;
        a = vec4(j == 0u ? mean : a.x, j == 1u ? mean : a.y, j == 2u ? mean : a.z,
                 j == 3u ? mean : a.w);
    }
    return a;
}

// Channel k of bilinear filtering over `taps` (twin: `bilinear`).
float bilerp(Taps taps, uint k) {
    vec4 a = tap_values(taps, k);
    precise float top = a.x + taps.frac.x * (a.y - a.x);
    precise float bottom = a.z + taps.frac.x * (a.w - a.z);
    precise float value = top + taps.frac.y * (bottom - top);
    return value;
}
#endif

#endif
