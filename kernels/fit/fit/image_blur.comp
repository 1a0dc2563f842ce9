#version 460
#extension GL_GOOGLE_include_directive : require
// One pass of a separable Gaussian blur of RGBA images (view-major, row-major), along x
// (axis 0) or y (axis 1), one invocation per pixel: out(p) = Σ_{|i| ≤ r} w_i in(p + i e_axis),
// w_i = exp(−i²/(2 s²)) / Σ_{|k| ≤ r} exp(−k²/(2 s²)), r = pc.radius, s = pc.std, and pixels
// outside the image count as zero (so each pass is a symmetric matrix: the blur is its own
// adjoint, which the blurred image loss uses for its gradient). Twin: `fit::blur::cpu::blur`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Src { vec4 src[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { vec4 dst[]; };

// Twin of `BlurPush` (src/fit/blur.rs).
layout(push_constant) uniform Push {
    uint width;
    uint height;
    uint pixels; // all views
    uint radius;
    float std_px;
    uint axis;
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (i >= pc.pixels) {
        return;
    }
    uint x = i % pc.width;
    uint y = (i / pc.width) % pc.height;
    int here = int(pc.axis == 0u ? x : y);
    int size = int(pc.axis == 0u ? pc.width : pc.height);
    int stride = pc.axis == 0u ? 1 : int(pc.width);
    int r = int(pc.radius);
    float inv = fm_div(-0.5, pc.std_px * pc.std_px);
    float norm = 0.0;
    vec4 acc = vec4(0.0);
    for (int t = -r; t <= r; t++) {
        float w = fm_exp(float(t * t) * inv);
        norm += w;
        int at = here + t;
        if (at >= 0 && at < size) {
            acc += w * src[int(i) + t * stride];
        }
    }
    dst[i] = fm_div4(acc, norm);
}
