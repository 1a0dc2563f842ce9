#version 460
#extension GL_GOOGLE_include_directive : require
// Brute-force soft rasterization (SoftRas's own method): one invocation per pixel, every face of
// its view in index order. Twin: `reference::shade_pixel`, step for step. The baseline that the
// tiled kernels are compared against bit for bit, and benchmarked against.
#include "common.glsl"
#include "raster.glsl"

layout(local_size_x = 64) in;

// Twin of `PixelAux` (src/raster/brute.rs): what the backward pass needs of the forward's
// running aggregates, so that it needs no second forward. 16 bytes per pixel.
struct PixelAux {
    float softmax_ref_depth; // depth whose z̄ is the softmax's running max (background: far - ε (far - near))
    float softmax_sum;       // softmax denominator, scaled by e^{-max/γ} (includes the background's term)
    float alpha_acc;         // prod: Π(1 - D); sum: Σ D; hard: 0 or 1
    uint hard_face;          // hard colour: the winning face, or 0xffffffff for the background
};

layout(std430, set = 0, binding = 0) readonly buffer Setups { FaceSetup setups[]; };
layout(std430, set = 0, binding = 1) readonly buffer Colors { float colors[]; };
layout(std430, set = 0, binding = 2) readonly buffer Faces { uint faces[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Image { vec4 image[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Aux { PixelAux aux[]; };

#define FLAG_DOUBLE_SIDED 1u
#define FLAG_VERTEX_COLORS 2u
#define FLAG_CULL 4u

// Twin of `RasterPush` (src/raster/brute.rs).
layout(push_constant) uniform Push {
    uint width;            // rendered size (2× the output with anti-aliasing)
    uint height;
    uint face_count;
    uint view_count;
    float sigma;
    float cutoff;          // T = σ ln(1/ε_d − 1)
    float near;
    float far;
    float inv_gamma_range; // 1 / (γ (far − near))
    float background_depth; // far − ε (far − near): the background's softmax depth
    uint dist;             // DIST_*
    uint rgb;              // RGB_*
    uint alpha;            // ALPHA_*
    uint texture_res;      // R (surface colours)
    uint flags;            // FLAG_*
    uint pad0;
    vec4 background;       // C_b (w unused)
} pc;

// `FaceColors::sample`: C_j at clipped barycentrics w̃.
vec3 sample_color(uint face, vec3 wc) {
    if ((pc.flags & FLAG_VERTEX_COLORS) != 0u) {
        uvec3 f = uvec3(faces[3u * face], faces[3u * face + 1u], faces[3u * face + 2u]);
        vec3 c0 = vec3(colors[3u * f.x], colors[3u * f.x + 1u], colors[3u * f.x + 2u]);
        vec3 c1 = vec3(colors[3u * f.y], colors[3u * f.y + 1u], colors[3u * f.y + 2u]);
        vec3 c2 = vec3(colors[3u * f.z], colors[3u * f.z + 1u], colors[3u * f.z + 2u]);
        return wc.x * c0 + wc.y * c1 + wc.z * c2;
    }
    uint r2 = pc.texture_res * pc.texture_res;
    uint t = face * r2 + surface_texel_index(wc, pc.texture_res);
    return vec3(colors[3u * t], colors[3u * t + 1u], colors[3u * t + 2u]);
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (id >= pixels * pc.view_count) {
        return;
    }
    uint view = id / pixels;
    uint in_view = id - view * pixels;
    uint row = in_view / pc.width;
    uint col = in_view - row * pc.width;
    vec2 p = pixel_center(col, row, pc.width, pc.height);

    bool cull = (pc.flags & FLAG_CULL) != 0u;
    bool double_sided = (pc.flags & FLAG_DOUBLE_SIDED) != 0u;
    float alpha = alpha_init(pc.alpha);
    Softmax soft = softmax_init(pc.background.rgb, pc.background_depth);
    bool hard_found = false;
    float hard_depth = 0.0;
    vec3 hard_rgb = pc.background.rgb;
    uint hard_face = 0xffffffffu;

    uint base = view * pc.face_count;
    for (uint j = 0u; j < pc.face_count; ++j) {
        FaceSetup f = setups[base + j];
        if ((f.flags & FACE_FINITE) == 0u || (cull && outside_bbox(f.bbox, p))) {
            continue;
        }
        vec3 w = barycentric(f, p);
        float d;
        if (!coverage(f, w, p, pc.dist, pc.sigma, pc.cutoff, d)) {
            continue;
        }
        // Alpha counts every non-ignored face, whatever its depth or facing.
        alpha = alpha_add(alpha, pc.alpha, d);

        vec3 wc = clip_barycentric(w);
        float z;
        if (!depth_in_range(f, wc, pc.near, pc.far, z)) {
            continue;
        }
        if (!(double_sided || (f.flags & FACE_FRONT) != 0u)) {
            continue;
        }
        if (pc.rgb == RGB_SOFTMAX) {
            softmax_add(soft, z, d, sample_color(j, wc), pc.inv_gamma_range);
        } else if (inside_closed(w) && (!hard_found || z < hard_depth)) {
            hard_found = true;
            hard_depth = z;
            hard_rgb = sample_color(j, wc);
            hard_face = j;
        }
    }
    vec3 rgb = pc.rgb == RGB_SOFTMAX ? softmax_resolve(soft) : hard_rgb;
    image[id] = vec4(rgb, alpha_resolve(alpha, pc.alpha, pc.face_count));
    PixelAux a;
    a.softmax_ref_depth = soft.ref_depth;
    a.softmax_sum = soft.sum;
    a.alpha_acc = alpha;
    a.hard_face = hard_face;
    aux[id] = a;
}
