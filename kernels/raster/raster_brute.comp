#version 460
#extension GL_GOOGLE_include_directive : require
// Brute-force soft rasterization (SoftRas's own method): one invocation per pixel, every face of
// its view in index order. Twin: `reference::shade_pixel`, step for step. The baseline that the
// tiled kernel is compared against bit for bit, and benchmarked against.
#include "common.glsl"
#include "raster_fine.glsl"

layout(local_size_x = 64) in;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (id >= pixels * pc.view_count) {
        return;
    }
    uint view = pc.first_view + id / pixels;
    uint in_view = id - (id / pixels) * pixels;
    uint row = in_view / pc.width;
    uint col = in_view - row * pc.width;
    vec2 p = pixel_center(col, row, pc.width, pc.height);

    PixelState s = pixel_init();
    uint base = view * pc.face_count;
    for (uint j = 0u; j < pc.face_count; ++j) {
        shade_face(s, face_of(setups[base + j]), j, p);
    }
    pixel_finish(s, view * pixels + in_view);
}
