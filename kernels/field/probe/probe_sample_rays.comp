#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, sampling: the probing rays of one iteration, one invocation per ray (view-major,
// `rays_per_view` per view). The first `uniform_per_view` rays of a view pick a pixel uniformly;
// the rest pick one from the view's contour density (the Laplacian of the silhouette, smoothed,
// |·|, quantized to integers on the host) by binary search in their exclusive prefix sum, and fall
// back to uniform where a view has no contour. Both jitter uniformly within the pixel. Random
// words: `rand_u32(key, ray, 0..2)`. Twin: `probe::sampler::cpu::sample_rays`.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Masks { float masks[]; };
// The exclusive prefix sum of the quantized densities over all views (view-major), and after the
// last pixel their total: views × pixels + 1 entries.
layout(std430, set = 0, binding = 1) readonly buffer Cdf { uint cdf[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Rays { Ray rays[]; };

layout(push_constant) uniform Push {
    uint views;
    uint rays_per_view;
    uint uniform_per_view;
    uint width;
    uint height;
    uint key;
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.views * pc.rays_per_view) {
        return;
    }
    uint view = id / pc.rays_per_view;
    uint i = id - view * pc.rays_per_view;
    uint pixels = pc.width * pc.height;
    uint first = view * pixels;
    uint last = first + pixels - 1u;
    uint base = cdf[first];
    uint total = cdf[last + 1u] - base;
    uint h = rand_u32(pc.key, id, 0u);
    uint pixel;
    if (i < pc.uniform_per_view || total == 0u) {
        pixel = scale_u32(h, pixels);
    } else {
        // The last pixel p of the view with cdf[p] <= target: the one whose weight interval holds
        // the target (pixels of weight 0 share their successor's prefix and are never chosen).
        uint target = base + scale_u32(h, total);
        uint lo = first;
        uint hi = last + 1u;
        while (hi - lo > 1u) {
            uint mid = lo + (hi - lo) / 2u;
            if (cdf[mid] <= target) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        pixel = lo - first;
    }
    uint row = pixel / pc.width;
    uint col = pixel - row * pc.width;
    precise float px = float(col) + unit_float(rand_u32(pc.key, id, 1u));
    precise float py = float(row) + unit_float(rand_u32(pc.key, id, 2u));
    float label = masks[first + pixel] >= 0.5 ? 1.0 : 0.0;
    rays[id] = Ray(px, py, view, label);
}
