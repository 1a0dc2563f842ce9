#version 460
#extension GL_GOOGLE_include_directive : require
// Anti-aliasing: averages 2×2 blocks of a 2W × 2H RGBA image into W × H, per view (SoftRas
// `avg_pool2d(2, 2)`). Twin: `reference::downsample_2x2`, same summation order.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Big { vec4 big[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Small { vec4 small[]; };

layout(push_constant) uniform Push {
    uint width;  // output size
    uint height;
    uint view_count;
    uint pad0;
} pc;

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
    uint big_w = 2u * pc.width;
    uint top = view * 4u * pixels + (2u * row) * big_w + 2u * col;
    vec4 a = big[top];
    vec4 b = big[top + 1u];
    vec4 c = big[top + big_w];
    vec4 d = big[top + big_w + 1u];
    small[id] = (a + b + c + d) * 0.25;
}
