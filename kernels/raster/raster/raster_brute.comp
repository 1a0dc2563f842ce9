#version 460
#extension GL_GOOGLE_include_directive : require
// Brute-force soft rasterization (SoftRas's own method): one invocation per pixel, every face of
// its view in index order (in passes over consecutive faces where the driver's loop cap asks:
// `CARRY` in raster_fine.glsl). Twin: `reference::shade_pixel`, step for step. The baseline
// that the tiled kernel is compared against bit for bit, and benchmarked against.
#define CARRY_BINDING 5
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

    uint pixel = view * pixels + in_view;
    // This pass's faces (all of them without CARRY).
    uint begin = CARRY != 0u ? pc.pass_begin : 0u;
    uint end = CARRY != 0u ? min(pc.pass_end, pc.face_count) : pc.face_count;
    PixelState s = begin > 0u ? carry_load(pixel) : pixel_init();
    uint base = view * pc.face_count;
    for (uint j = begin; j < end; ++j) {
        shade_face(s, face_of(setups[base + j]), j, p);
    }
    if (end < pc.face_count) {
        carry_store(s, pixel);
    } else {
        pixel_finish(s, pixel);
    }
}
