// Soft rasterization maths shared by the face setup and every fine kernel (brute force now, tiled
// later): the f32 twin of `src/raster/reference.rs`, function for function. A tiled kernel that
// calls these same functions in the same face order gets bit-identical pixels to the brute one.
//
// Where f32 needs a different arrangement of the same formula than the f64 twin, it is said here:
// - barycentrics are evaluated relative to a vertex of the opposite edge (`barycentric`);
// - the face determinant is taken in its translated form, and for a look-at view from the world
//   vertices (`face_setup.comp`), once: every later step reads it from the setup;
// - the softmax exponents are taken from depth differences, not from z̄ (`softmax_add_if`);
// - a division by a per-face constant (1 / z_k, 1 / |edge|², 1 / det) is a multiplication by its
//   reciprocal, taken once per face (`face_reciprocals`), and a division by σ or by the clip's
//   sum a multiplication by 1 / σ or 1 / sum: a pair's steps take 3 reciprocals (forward) or 4
//   (backward) instead of 12 or 29 divisions;
// - every exp, reciprocal and division is softvk's own (`fmath.glsl`), so the bits are the same
//   on every device: a reciprocal is about 20 correctly rounded operations where a division was
//   one instruction, so the fewer the better (the softmax takes one exp a pair, not two, and the
//   coverage's sigmoid and its derivative share theirs).
#ifndef SOFTVK_RASTER_GLSL
#define SOFTVK_RASTER_GLSL

#include "fmath.glsl"

#define DIST_EUCLIDEAN 0u
#define DIST_BARYCENTRIC 1u
#define DIST_HARD 2u

#define RGB_SOFTMAX 0u
#define RGB_HARD 1u

#define ALPHA_PROD 0u
#define ALPHA_SUM 1u
#define ALPHA_HARD 2u

#define FACE_FRONT 1u
#define FACE_FINITE 2u
#define FACE_DEGENERATE 4u

// `reference::MIN_DET`: SoftRas's determinant clamp.
const float MIN_DET = 1e-10;
// `reference::CLIP_SUM_FLOOR`.
const float CLIP_SUM_FLOOR = 1e-5;

// One face in one view after setup. Twin of `GpuFaceSetup` (src/raster/setup.rs) and of
// `reference::FaceSetup`. 128 bytes, std430. The fourth words hold the reciprocals the per-pixel
// steps multiply by (`face_reciprocals`), taken once per face by the setup rather than by every
// kernel that loads the face (each is about 25 operations: the tiled kernels load a face once
// per (face, tile) entry, brute force once per pair).
struct FaceSetup {
    vec4 v[3];    // screen-space vertices and 1 / depth (x_s, y_s, z, 1 / z)
    vec4 inv[3];  // rows (a, b, c) of M_j (clamped determinant), w_k = a x + b y + c; and
                  // 1 / |edge k|², edge k from vertex k to the next (0 for a zero-length edge)
    vec4 bbox;    // grown screen box (x_min, y_min, x_max, y_max)
    uint flags;   // FACE_FRONT | FACE_FINITE | FACE_DEGENERATE
    uint mesh;    // the batch's mesh the face belongs to (its view's)
    float det;    // the screen determinant, unclamped (`face_setup.comp`; its sign is FACE_FRONT's)
    float inv_det; // 1 / the clamped determinant
};

// What the per-pixel steps read of a `FaceSetup` (29 of its 32 words). The tiled kernels hold
// one face per lane and broadcast it across the subgroup one word per shuffle (a shuffle is one
// permute on llvmpipe; a word no step reads is never shuffled: the compiler drops it); brute
// force builds it from the setup per pair (`face_of`).
struct Face {
    vec3 v[3];      // screen-space vertices (x_s, y_s, z)
    vec2 inv[3];    // (a, b) of the rows of M_j
    vec4 bbox;      // grown screen box
    uint flags;     // FACE_*
    uint mesh;      // the batch's mesh
    float det;      // the setup's determinant, unclamped
    vec3 inv_z;     // 1 / z_k
    vec3 inv_len2;  // 1 / |v_{k+1} - v_k|² of edge k (0 for a zero-length edge)
    float inv_det;  // 1 / the clamped determinant
};

// Fills the reciprocals of a face whose vertices and determinant are set: the face setup's,
// stored in its record for every kernel that reads it.
void face_reciprocals(inout Face f) {
    for (uint k = 0u; k < 3u; ++k) {
        uint j = k == 2u ? 0u : k + 1u;
        vec2 e = f.v[j].xy - f.v[k].xy;
        float len2 = e.x * e.x + e.y * e.y;
        f.inv_z[k] = fm_rcp(f.v[k].z);
        f.inv_len2[k] = len2 > 0.0 ? fm_rcp(len2) : 0.0;
    }
    // The determinant the face setup took (for a look-at view not the screen vertices' own:
    // `face_setup.comp`), clamped as there.
    f.inv_det = fm_rcp(f.det > 0.0 ? max(f.det, MIN_DET) : min(f.det, -MIN_DET));
}

Face face_of(FaceSetup s) {
    Face f;
    f.v[0] = s.v[0].xyz;
    f.v[1] = s.v[1].xyz;
    f.v[2] = s.v[2].xyz;
    f.inv[0] = s.inv[0].xy;
    f.inv[1] = s.inv[1].xy;
    f.inv[2] = s.inv[2].xy;
    f.bbox = s.bbox;
    f.flags = s.flags;
    f.mesh = s.mesh;
    f.det = s.det;
    f.inv_z = vec3(s.v[0].w, s.v[1].w, s.v[2].w);
    f.inv_len2 = vec3(s.inv[0].w, s.inv[1].w, s.inv[2].w);
    f.inv_det = s.inv_det;
    return f;
}

// A face that no pixel sees (no FACE_FINITE): for lanes past the end of a run.
Face face_none() {
    Face f;
    f.v[0] = vec3(0.0);
    f.v[1] = vec3(0.0);
    f.v[2] = vec3(0.0);
    f.inv[0] = vec2(0.0);
    f.inv[1] = vec2(0.0);
    f.inv[2] = vec2(0.0);
    f.bbox = vec4(0.0);
    f.flags = 0u;
    f.mesh = 0u;
    f.det = 0.0;
    f.inv_z = vec3(0.0);
    f.inv_len2 = vec3(0.0);
    f.inv_det = 0.0;
    return f;
}

// `camera::pixel_center`: x_p = (2c + 1 - W) / S, y_p = (2(H - 1 - r) + 1 - H) / S, S = min(W, H).
// Every operand is an integer below 2^24, so only the division rounds: correctly (`fm_div_rn`),
// once per pixel.
vec2 pixel_center(uint col, uint row, uint width, uint height) {
    float w = float(width);
    float h = float(height);
    float s = min(w, h);
    return vec2(fm_div_rn(2.0 * float(col) + 1.0 - w, s), fm_div_rn(2.0 * (h - 1.0 - float(row)) + 1.0 - h, s));
}

// `reference::outside_bbox` (strict, as SoftRas's check_border).
bool outside_bbox(vec4 bbox, vec2 p) {
    return p.x < bbox.x || p.y < bbox.y || p.x > bbox.z || p.y > bbox.w;
}

// `reference::barycentric`, w = M_j (x_p, y_p, 1). Row k of M_j vanishes on the edge opposite
// vertex k, so `a x + b y + c = a (x - x_r) + b (y - y_r)` for a vertex r of that edge, exactly,
// for the clamped determinant too. In f32 the translated form keeps its error at a few ulp of
// |p - v_r| instead of |c| (which grows like 1 / area and cancels), so the w of a small face stay
// accurate; SoftRas's σ = 1e-5 barycentric coverage is that sensitive.
vec3 barycentric(Face f, vec2 p) {
    return vec3(f.inv[0].x * (p.x - f.v[1].x) + f.inv[0].y * (p.y - f.v[1].y),
                f.inv[1].x * (p.x - f.v[2].x) + f.inv[1].y * (p.y - f.v[2].y),
                f.inv[2].x * (p.x - f.v[0].x) + f.inv[2].y * (p.y - f.v[0].y));
}

bool strictly_inside(vec3 w) {
    return w.x > 0.0 && w.x < 1.0 && w.y > 0.0 && w.y < 1.0 && w.z > 0.0 && w.z < 1.0;
}

// `reference::inside_closed`.
bool inside_closed(vec3 w) {
    return w.x >= 0.0 && w.x <= 1.0 && w.y >= 0.0 && w.y <= 1.0 && w.z >= 0.0 && w.z <= 1.0;
}

// `reference::dist2_point_segment`, given 1 / |b - a|² (0 for a zero-length segment, whose
// parameter is then 0: its dot product is 0 too).
float dist2_point_segment(vec2 p, vec2 a, vec2 b, float inv_len2) {
    float ex = b.x - a.x;
    float ey = b.y - a.y;
    float t = clamp(((p.x - a.x) * ex + (p.y - a.y) * ey) * inv_len2, 0.0, 1.0);
    float dx = a.x + t * ex - p.x;
    float dy = a.y + t * ey - p.y;
    return dx * dx + dy * dy;
}

// `reference::euclidean_dist2`: the nearest of the three edges, as segments.
float euclidean_dist2(Face f, vec2 p) {
    return min(min(dist2_point_segment(p, f.v[0].xy, f.v[1].xy, f.inv_len2[0]),
                   dist2_point_segment(p, f.v[1].xy, f.v[2].xy, f.inv_len2[1])),
               dist2_point_segment(p, f.v[2].xy, f.v[0].xy, f.inv_len2[2]));
}

float sigmoid(float x) {
    return fm_sigmoid(x);
}

// The squared distance to the nearest edge as `euclidean_dist2` computes it, and that edge:
// its first vertex `a`, its vector `e` = b - a, its vertex indices (ea, eb) (the first of
// equals) and the parameter `t` of the nearest point a + t e: what the backward needs of the
// same distance. Selects, not indexing by `ea` (a per-lane index into an array is a scalar
// loop over the lanes on llvmpipe).
float nearest_edge(Face f, vec2 p, out vec2 a, out vec2 e, out uint ea, out uint eb,
                   out float t) {
    float best = uintBitsToFloat(0x7f800000u);
    a = vec2(0.0);
    e = vec2(0.0);
    ea = 0u;
    eb = 1u;
    t = 0.0;
    for (uint i = 0u; i < 3u; ++i) {
        uint j = i == 2u ? 0u : i + 1u;
        vec2 va = f.v[i].xy;
        vec2 ve = f.v[j].xy - va;
        float ti = clamp(((p.x - va.x) * ve.x + (p.y - va.y) * ve.y) * f.inv_len2[i], 0.0, 1.0);
        float dx = va.x + ti * ve.x - p.x;
        float dy = va.y + ti * ve.y - p.y;
        float d2 = dx * dx + dy * dy;
        bool nearer = d2 < best;
        best = nearer ? d2 : best;
        a = nearer ? va : a;
        e = nearer ? ve : e;
        t = nearer ? ti : t;
        ea = nearer ? i : ea;
        eb = nearer ? j : eb;
    }
    return best;
}

// The sigmoid's argument: `x` where the face covers the pixel, 0 where it is ignored. An
// ignored pair's D is discarded (every caller selects it away), but it is computed (selects, not
// branches); from its own argument, far from the face, e^-|x| and the backward's products of it
// fall below 2^-126, and on x86 every vector operation with a subnormal operand or result takes
// a microcode assist of some hundred cycles (llvmpipe's compute threads keep subnormals).
float covered_arg(bool covered, float x) {
    return covered ? x : 0.0;
}

// `reference::coverage` given the squared edge distance `d2` (Euclidean mode only) and 1 / σ:
// false when the face is ignored at this pixel (outside and beyond the cut-off `t`); otherwise
// `d` is the coverage D.
bool coverage_from(float d2, vec3 w, uint dist, float inv_sigma, float t, out float d) {
    if (dist == DIST_HARD) {
        d = 1.0;
        return inside_closed(w);
    }
    if (dist == DIST_BARYCENTRIC) {
        float m = min(min(w.x, w.y), w.z);
        float s = m * abs(m);
        bool covered = -s < t;
        d = sigmoid(covered_arg(covered, s * inv_sigma));
        return covered;
    }
    // Selects rather than branches: on llvmpipe every branch costs masked stores.
    bool inside = strictly_inside(w);
    bool covered = inside || d2 < t;
    d = sigmoid(covered_arg(covered, (inside ? d2 : -d2) * inv_sigma));
    return covered;
}

// `reference::coverage`, given 1 / σ.
bool coverage(Face f, vec3 w, vec2 p, uint dist, float inv_sigma, float t, out float d) {
    float d2 = dist == DIST_EUCLIDEAN ? euclidean_dist2(f, p) : 0.0;
    return coverage_from(d2, w, dist, inv_sigma, t, d);
}

// 1 / the clip's sum: `clip_barycentric(w)` is `clamp(w, 0, 1)` times it.
float clip_inverse_sum(vec3 w) {
    vec3 c = clamp(w, 0.0, 1.0);
    return fm_rcp_pos(max(c.x + c.y + c.z, CLIP_SUM_FLOOR));
}

// `reference::clip_barycentric`.
vec3 clip_barycentric(vec3 w) {
    return clamp(w, 0.0, 1.0) * clip_inverse_sum(w);
}

// `reference::depth` and the near/far test together: false when the depth
// z = 1 / Σ_k (w̃_k / z_k) is outside [near, far] (a non-positive sum, whose z would be negative
// or infinite, is outside too; so is NaN).
bool depth_in_range(Face f, vec3 wc, float near, float far, out float z) {
    float inv_z = wc.x * f.inv_z.x + wc.y * f.inv_z.y + wc.z * f.inv_z.z;
    if (!(inv_z > 0.0)) {
        z = 0.0;
        return false;
    }
    z = fm_rcp_pos(inv_z);
    return z >= near && z <= far;
}

// `reference::surface_texel_index`: SoftRas's texel within a face's R×R texture, with the same
// slack of TEXEL_TIE_ULPS R ulp on the tie test (exact on the edge w̃2 = 0; see the twin).
const float TEXEL_TIE_ULPS = 8.0;
const float FLT_EPSILON = 1.1920929e-7;

uint surface_texel_index(vec3 wc, uint res) {
    float r = float(res);
    uint a = min(uint(wc.x * r), res - 1u);
    uint b = min(uint(wc.y * r), res - 1u);
    float frac = (wc.x + wc.y) * r - float(a) - float(b);
    if (frac <= 1.0 + TEXEL_TIE_ULPS * r * FLT_EPSILON) {
        return b * res + a;
    }
    return (res - 1u - b) * res + (res - 1u - a);
}

// `reference::AlphaAccum`. Prod: Π(1 - D) over the factors that are not exactly 0, and the count
// of those that are (so the backward's ∂A/∂D_j = Π_{k≠j}(1 - D_k) is exact even where D_j
// rounds to 1; the alpha itself is unchanged: any zero factor makes it 1); sum: Σ D; hard: 1
// once any D > 0.5.
struct Alpha {
    float acc;
    uint zeros;
};

Alpha alpha_init(uint mode) {
    Alpha a;
    a.acc = mode == ALPHA_PROD ? 1.0 : 0.0;
    a.zeros = 0u;
    return a;
}

// `alpha_add` where `use`, else nothing; by selects (no branch).
void alpha_add_if(inout Alpha a, uint mode, float d, bool use) {
    if (mode == ALPHA_PROD) {
        float f = 1.0 - d;
        bool zero = f == 0.0;
        a.zeros += use && zero ? 1u : 0u;
        a.acc = use && !zero ? a.acc * f : a.acc;
    } else if (mode == ALPHA_SUM) {
        a.acc = use ? a.acc + d : a.acc;
    } else {
        a.acc = use && d > 0.5 ? 1.0 : a.acc;
    }
}

void alpha_add(inout Alpha a, uint mode, float d) {
    if (mode == ALPHA_PROD) {
        float f = 1.0 - d;
        if (f == 0.0) {
            a.zeros += 1u;
        } else {
            a.acc *= f;
        }
    } else if (mode == ALPHA_SUM) {
        a.acc += d;
    } else if (d > 0.5) {
        a.acc = 1.0;
    }
}

float alpha_resolve(Alpha a, uint mode, uint face_count) {
    if (mode == ALPHA_PROD) {
        return a.zeros > 0u ? 1.0 : 1.0 - a.acc;
    }
    if (mode == ALPHA_SUM) {
        return fm_div(a.acc, float(face_count));
    }
    return a.acc;
}

// `reference::SoftmaxAccum`: numerator and denominator scaled by e^{-max/γ}, max the largest
// z̄ = (far - z) / (far - near) seen, starting with the background's ε.
//
// The running maximum is kept as the depth `ref_depth` whose z̄ it is (the background's is
// far - ε (far - near)), and every exponent (z̄_a - z̄_b) / γ is taken as
// (z_b - z_a) * inv_gamma_range with inv_gamma_range = 1 / (γ (far - near)). Same maths; but
// in f32 z̄ ≈ 0.97 carries an absolute rounding of 6e-8, which at γ = 1e-4 is already a 1e-3
// error in the exponent, while the difference of two depths is as exact as the depths.
struct Softmax {
    float ref_depth;
    float sum;
    vec3 rgb;
};

Softmax softmax_init(vec3 background, float background_depth) {
    Softmax s;
    s.ref_depth = background_depth;
    s.sum = 1.0;
    s.rgb = background;
    return s;
}

// Adds a face's (z, D, colour) where `apply`, else nothing, by selects (the same bits as
// branching on it).
void softmax_add_if(inout Softmax s, float z, float d, vec3 color, float inv_gamma_range,
                    bool apply) {
    bool closer = apply && z < s.ref_depth;
    // One exp: a nearer face rescales the sums by e^{(z − ref) / ·} and weighs d e^0 = d; a
    // farther one weighs d e^{(ref − z) / ·}. Both exponents are −|z − ref| · inv_gamma_range
    // (exact negations), so this is the two-exp form's bits.
    float e = fm_exp_le0(-abs(z - s.ref_depth) * inv_gamma_range);
    float sum = closer ? s.sum * e : s.sum;
    vec3 rgb = closer ? s.rgb * e : s.rgb;
    float ref_depth = closer ? z : s.ref_depth;
    float weight = closer ? d : d * e;
    s.sum = apply ? sum + weight : s.sum;
    s.rgb = apply ? rgb + weight * color : s.rgb;
    s.ref_depth = ref_depth;
}

vec3 softmax_resolve(Softmax s) {
    return s.rgb * fm_rcp_pos(s.sum);  // the sum is positive: it starts at 1 and adds D e ≥ 0
}

#endif
