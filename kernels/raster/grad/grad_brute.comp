#version 460
#extension GL_GOOGLE_include_directive : require
// Brute-force backward of the fine pass (the baseline), one chunk of units at a time: a unit is
// (view, face, band of `split` rows), `parts` bands per view, numbered item-major
// (`item · parts + band`). One invocation per unit of [chunk_begin, chunk_end) sums the face
// over every pixel of its band in row-major order and writes the unit's partial at
// `unit - chunk_begin`. Bands bound each invocation's loop count (llvmpipe stops loops after
// 65 535 iterations); `grad_reduce.comp` and `grad_reduce_texels.comp` add each face's bands in
// order. Twin: `reference_grad::backward_view`, whose summation order it has within a band.
#define FINE_BACKWARD
#include "common.glsl"
#include "raster_grad.glsl"

layout(local_size_x = 64) in;

// This chunk's partials: `grad_stride` floats per unit, as vec4 records (`PARTIAL_COLORS` in
// raster_grad.glsl). The texel slots arrive zeroed (the host fills them) and are summed into
// here; with `TEXEL_MASKS` they arrive unwritten, and the mask says which were written.
layout(std430, set = 0, binding = 6) buffer Partials { vec4 partials[]; };

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.chunk_end - pc.chunk_begin) {
        return;
    }
    uint unit = pc.chunk_begin + id;
    uint item = unit / pc.parts;
    uint band = unit - item * pc.parts;
    uint view = item / pc.face_count;
    uint face = item - view * pc.face_count;
    uint gview = pc.first_view + view;
    Face f = face_of(setups[gview * pc.face_count + face]);
    bool vertex_colors = VERTEX_COLORS;
    uint o = id * (pc.grad_stride / 4u);
    uint row_begin = band * pc.split;
    uint row_end = min(pc.height, row_begin + pc.split);
    vec3 acc[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 cacc[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
    uint written = 0u; // TEXEL_MASKS: the texel slots written so far
    if ((f.flags & FACE_FINITE) != 0u) {
        for (uint row = row_begin; row < row_end; ++row) {
            for (uint col = 0u; col < pc.width; ++col) {
                Upstream u = load_upstream(gview, col, row);
                if (upstream_is_zero(u)) {
                    continue;
                }
                FaceGrad g;
                if (!pixel_face_grad(f, face, u, g)) {
                    continue;
                }
                acc[0] += g.screen[0];
                acc[1] += g.screen[1];
                acc[2] += g.screen[2];
                if (g.colored) {
                    if (vertex_colors) {
                        cacc[0] += g.color[0];
                        cacc[1] += g.color[1];
                        cacc[2] += g.color[2];
                    } else if (TEXEL_MASKS) {
                        uint bit = 1u << g.texel;
                        vec4 old = vec4(0.0);
                        if ((written & bit) != 0u) {
                            old = partials[o + PARTIAL_COLORS + g.texel];
                        }
                        partials[o + PARTIAL_COLORS + g.texel] = old + vec4(g.color[0], 0.0);
                        written |= bit;
                    } else {
                        partials[o + PARTIAL_COLORS + g.texel] += vec4(g.color[0], 0.0);
                    }
                }
            }
        }
    }
    for (uint c = 0u; c < 3u; ++c) {
        float w = TEXEL_MASKS && c == TEXEL_MASK_SLOT ? uintBitsToFloat(written) : 0.0;
        partials[o + c] = vec4(acc[c], w);
        if (vertex_colors) {
            partials[o + PARTIAL_COLORS + c] = vec4(cacc[c], 0.0);
        }
    }
}
