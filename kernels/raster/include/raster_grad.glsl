// The backward of the fine pass, per (pixel, face): the f32 twin of
// `reference_grad::pixel_face_grad`, step for step. Shared by `grad_tiled.comp` (faces of a
// tile) and `grad_brute.comp` (every pixel for every face). Each face's contribution at a pixel
// needs only the pixel's upstream gradient and the forward's aggregates (`PixelAux`), never the
// other faces: one pass over the faces suffices, and the result does not depend on their order.
//
// Includers define FINE_BACKWARD before including this (the image and aux are read).
#ifndef SOFTVK_RASTER_GRAD_GLSL
#define SOFTVK_RASTER_GRAD_GLSL

#include "raster_fine.glsl"

// A partial gradient (one unit of the backward: a (face, tile) entry or a (face, band)) is a
// record of vec4s: the three screen corners' (x_s, y_s, z), then one per colour slot (texel or
// corner) RGB, each with an unused fourth float. Whole vec4s, because on llvmpipe every load or
// store of a lane's own address is a scalar loop over the lanes whatever its width: a texel's
// read-modify-write is then two such loops instead of six. Twin: `grad_stride`.
const uint PARTIAL_COLORS = 3u;

// With `TEXEL_MASKS`, the partial's first vec4's fourth float holds the bits of a 32-bit mask:
// bit t set where texel slot t was written. A slot is then written, not read, the first time
// (0 + s, as onto a zeroed slot: the same bits), so no fill of the chunk has to come first (on
// llvmpipe those 16 bytes a slot were a cache miss at the first read-modify-write), and the
// texel reduction adds only the slots the mask names.
const uint TEXEL_MASK_SLOT = 0u;

// dL/d(output RGBA), output resolution, view-major. A storage buffer even where the other inputs
// are texels: it is the host's range in an engine's backward (`GradIo::upstream`), which needs
// no usage beyond storage.
layout(std430, set = 0, binding = 5) readonly buffer DImage { vec4 d_image[]; };

vec4 d_image_at(uint id) {
    return d_image[id];
}

// `reference_grad::PixelUpstream`.
struct Upstream {
    vec2 p;            // pixel centre
    vec3 d_rgb;        // dL/d(rendered RGB)
    float d_alpha;     // dL/d(rendered alpha)
    float d_dot;       // d_rgb · I
    float inv_sum;     // 1 / S (softmax)
    float ref_depth;   // the softmax's reference depth
    float alpha_acc;
    uint alpha_zeros;
    uint hard_face;
};

Upstream zero_upstream() {
    Upstream u;
    u.p = vec2(0.0);
    u.d_rgb = vec3(0.0);
    u.d_alpha = 0.0;
    u.d_dot = 0.0;
    u.inv_sum = 0.0;
    u.ref_depth = 0.0;
    u.alpha_acc = 0.0;
    u.alpha_zeros = 0u;
    u.hard_face = 0xffffffffu;
    return u;
}

bool upstream_is_zero(Upstream u) {
    return u.d_alpha == 0.0 && (ALPHA_ONLY || u.d_rgb == vec3(0.0));
}

// The upstream of rendered pixel (col, row) of view `view` (absolute), centred at `p`
// (`pixel_center(col, row, ...)`): with anti-aliasing, the output pixel's gradient / 4
// (`reference_grad::upsample_grad_2x2`).
Upstream load_upstream_at(uint view, uint col, uint row, vec2 p) {
    uint id = view * pc.width * pc.height + row * pc.width + col;
    vec4 g;
    if (ANTIALIAS) {
        g = d_image_at(view * pc.out_width * pc.out_height + (row / 2u) * pc.out_width
                       + col / 2u) * 0.25;
    } else {
        g = d_image_at(id);
    }
    vec4 rgba = image_at(id);
    PixelAux a = aux_at(id);
    Upstream u;
    u.p = p;
    u.d_rgb = g.rgb;
    u.d_alpha = g.a;
    u.d_dot = fm_dot3(g.rgb, rgba.rgb);
    u.inv_sum = fm_rcp_pos(a.softmax_sum);
    u.ref_depth = a.softmax_ref_depth;
    u.alpha_acc = a.alpha_acc;
    u.alpha_zeros = a.alpha_zeros;
    u.hard_face = a.hard_face;
    return u;
}

Upstream load_upstream(uint view, uint col, uint row) {
    return load_upstream_at(view, col, row, pixel_center(col, row, pc.width, pc.height));
}

// `PixelUpstream::alpha_grad`: dL/dA · ∂A/∂D_j, exact from the zero count.
float alpha_grad(Upstream u, float d) {
    if (MODE_ALPHA == ALPHA_PROD) {
        float factor = 1.0 - d;
        float others = factor == 0.0
                     ? (u.alpha_zeros == 1u ? u.alpha_acc : 0.0)
                     : (u.alpha_zeros == 0u ? fm_div_pos(u.alpha_acc, factor) : 0.0);
        return u.d_alpha * others;
    }
    if (MODE_ALPHA == ALPHA_SUM) {
        return fm_div(u.d_alpha, float(pc.face_count));
    }
    return 0.0;
}

// sigmoid'(x) without the cancellation of D (1 - D).
float sigmoid_grad(float x) {
    return fm_sigmoid_grad(x);
}

// One (pixel, face) contribution: dL/d(screen vertex (x_s, y_s, z)) of each corner, and the
// colour parameters' share: surface, `color[0]` for texel `texel`; vertex, `color[k]` for
// corner k. `colored` is false where the face adds no colour at the pixel.
struct FaceGrad {
    vec3 screen[3];
    vec3 color[3];
    uint texel;
    bool colored;
};

// `reference_grad::pixel_face_grad`. False where the face does not touch the pixel.
bool pixel_face_grad(Face f, uint j, Upstream u, out FaceGrad g) {
    g.screen[0] = vec3(0.0);
    g.screen[1] = vec3(0.0);
    g.screen[2] = vec3(0.0);
    g.color[0] = vec3(0.0);
    g.color[1] = vec3(0.0);
    g.color[2] = vec3(0.0);
    g.texel = 0u;
    g.colored = false;
    vec2 p = u.p;
    // Branch-free (on llvmpipe a branch skips nothing and costs masked stores): an untouched
    // face's numbers are computed and discarded (the caller keeps a pair's results only where
    // this returns true), and every conditional term is a select that leaves the bits of the
    // branching version. Gathers stay in bounds whatever the numbers (texel indices are clamped).
    bool live = (f.flags & FACE_FINITE) != 0u && !outside_bbox(f.bbox, p);
    vec3 w = barycentric(f, p);
    // Euclidean: the nearest edge, once for the coverage and its derivative.
    vec2 ea_pos = vec2(0.0);
    vec2 edge = vec2(0.0);
    uint ea = 0u;
    uint eb = 1u;
    float t = 0.0;
    float d2 = MODE_DIST == DIST_EUCLIDEAN ? nearest_edge(f, p, ea_pos, edge, ea, eb, t) : 0.0;
    float d;
    float inv_sigma = pc.inv_sigma;
    bool covered = coverage_from(d2, w, MODE_DIST, inv_sigma, pc.cutoff, d);
    bool hit = covered && live;
    float inv_clip_sum = clip_inverse_sum(w);
    vec3 wc = clamp(w, 0.0, 1.0) * inv_clip_sum; // clip_barycentric(w)
    float z = 0.0;
    bool in_range = !ALPHA_ONLY && depth_in_range(f, wc, pc.near, pc.far, z);
    g.colored = hit && in_range && (DOUBLE_SIDED || (f.flags & FACE_FRONT) != 0u);

    float d_cov = alpha_grad(u, d);
    vec3 d_color = vec3(0.0);
    float d_z = 0.0;
    if (!ALPHA_ONLY) {
        vec3 c = sample_color(f.mesh, j, wc);
        if (MODE_RGB == RGB_SOFTMAX) {
            // ref_depth ≤ z for every face the softmax took (it is the nearest depth seen).
            float e = fm_exp_le0((u.ref_depth - z) * pc.inv_gamma_range);
            float weight = d * e;
            float q = (fm_dot3(u.d_rgb, c) - u.d_dot) * u.inv_sum;
            d_color = g.colored ? u.d_rgb * (weight * u.inv_sum) : vec3(0.0);
            d_cov = g.colored ? d_cov + q * e : d_cov;
            d_z = g.colored ? -q * weight * pc.inv_gamma_range : 0.0;
        } else {
            d_color = g.colored && u.hard_face == j ? u.d_rgb : vec3(0.0);
        }
    }

    // Through w̃: depth and colour. None of it with an alpha-only upstream, where d_w would be
    // (0 - 0) / Σ = +0 exactly.
    vec3 d_w = vec3(0.0);
    if (!ALPHA_ONLY) {
        // Through w̃: depth and (vertex mode) colour.
        vec3 d_wc = vec3(0.0);
        bool depth = d_z != 0.0;
        float d_inv = -z * z * d_z;
        for (uint k = 0u; k < 3u; ++k) {
            float izk = f.inv_z[k];
            d_wc[k] = depth ? d_wc[k] + d_inv * izk : d_wc[k];
            g.screen[k].z = depth ? g.screen[k].z - d_inv * wc[k] * (izk * izk) : g.screen[k].z;
        }
        if (VERTEX_COLORS) {
            uvec3 vi = uvec3(faces[3u * j], faces[3u * j + 1u], faces[3u * j + 2u])
                     + f.mesh * pc.vertex_count;
            for (uint k = 0u; k < 3u; ++k) {
                vec3 ck = color_at(vi[k]);
                d_wc[k] = g.colored ? d_wc[k] + fm_dot3(d_color, ck) : d_wc[k];
                g.color[k] = g.colored ? d_color * wc[k] : vec3(0.0);
            }
        } else {
            g.texel = surface_texel_index(wc, pc.texture_res);
            g.color[0] = g.colored ? d_color : vec3(0.0);
        }

        // Clip: c = clamp(w, 0, 1), w̃ = c / max(Σc, floor).
        vec3 cl = clamp(w, 0.0, 1.0);
        float raw_sum = cl.x + cl.y + cl.z;
        float renorm = raw_sum >= CLIP_SUM_FLOOR ? fm_dot3(d_wc, wc) : 0.0;
        for (uint k = 0u; k < 3u; ++k) {
            d_w[k] = (w[k] > 0.0 && w[k] < 1.0) ? (d_wc[k] - renorm) * inv_clip_sum : 0.0;
        }
    }

    // Coverage.
    vec2 d_xy_cov[3] = vec2[3](vec2(0.0), vec2(0.0), vec2(0.0));
    bool cov = ALPHA_ONLY || d_cov != 0.0;
    {
        if (MODE_DIST == DIST_BARYCENTRIC) {
            uint k = 0u;
            if (w[1] < w[k]) k = 1u;
            if (w[2] < w[k]) k = 2u;
            float m = w[k];
            // The coverage's own argument (`coverage_from`: the same operations, so the
            // compiler shares the sigmoid's exponential and reciprocal; ±0 alike there).
            float least = min(min(w.x, w.y), w.z);
            float x = covered_arg(covered, least * abs(least) * inv_sigma);
            float add = d_cov * sigmoid_grad(x) * 2.0 * abs(m) * inv_sigma;
            for (uint c = 0u; c < 3u; ++c) {
                d_w[c] = cov && c == k ? d_w[c] + add : d_w[c];
            }
        } else if (MODE_DIST == DIST_EUCLIDEAN) {
            // Through the nearest edge (a, b) as `euclidean_dist2` picks it, to its two
            // vertices (selects, not a per-lane index; 0 + x = x).
            // The coverage's own argument (`coverage_from`: the same operations, so the
            // compiler shares the exponential and the reciprocal with the sigmoid's).
            bool inside = strictly_inside(w);
            float sgn = inside ? 1.0 : -1.0;
            float x = covered_arg(covered, (inside ? d2 : -d2) * inv_sigma);
            float d_d2 = d_cov * sigmoid_grad(x) * sgn * inv_sigma;
            vec2 r = vec2(ea_pos.x + t * edge.x - p.x, ea_pos.y + t * edge.y - p.y);
            vec2 to_a = d_d2 * 2.0 * (1.0 - t) * r;
            vec2 to_b = d_d2 * 2.0 * t * r;
            for (uint k = 0u; k < 3u; ++k) {
                d_xy_cov[k] = cov ? (ea == k ? to_a : (eb == k ? to_b : vec2(0.0))) : vec2(0.0);
            }
        }
    }

    // Barycentrics w_k = n_k / det, det the clamped determinant (constant where clamped). With
    // an alpha-only upstream, d_w is zero unless the coverage is barycentric: then d_xy would be
    // ±0, and adding ±0 to the edge term changes no bit (x + ±0 = x; +0 + -0 = +0).
    vec2 d_xy[3] = vec2[3](vec2(0.0), vec2(0.0), vec2(0.0));
    if (!ALPHA_ONLY || MODE_DIST == DIST_BARYCENTRIC) {
        bool clamped = f.det > 0.0 ? f.det < MIN_DET : f.det > -MIN_DET;
        float d_det = clamped ? 0.0 : -fm_dot3(d_w, w) * f.inv_det;
        for (uint k = 0u; k < 3u; ++k) {
            uint ia = k == 2u ? 0u : k + 1u;
            uint ib = k == 0u ? 2u : k - 1u;
            vec2 va = f.v[ia].xy;
            vec2 vb = f.v[ib].xy;
            float d_n = d_w[k] * f.inv_det;
            d_xy[ia] += d_n * vec2(vb.y - p.y, p.x - vb.x);
            d_xy[ib] += d_n * vec2(p.y - va.y, va.x - p.x);
            d_xy[k] += d_det * vec2(va.y - vb.y, vb.x - va.x);
        }
    }
    for (uint k = 0u; k < 3u; ++k) {
        g.screen[k].xy += d_xy[k] + d_xy_cov[k];
    }
    return hit;
}

#endif
