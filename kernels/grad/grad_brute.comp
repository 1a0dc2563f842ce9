#version 460
#extension GL_GOOGLE_include_directive : require
// Brute-force backward of the fine pass (the baseline): one invocation per (view, face), every
// rendered pixel of its view in row-major order, summed into the face's gradient. Twin:
// `reference_grad::backward_view`, whose summation order it has.
#define FINE_BACKWARD
#include "common.glsl"
#include "raster_grad.glsl"

layout(local_size_x = 64) in;

// Face gradients: `grad_stride` floats per (view, face), view-major (9 screen, then colour).
layout(std430, set = 0, binding = 6) buffer FaceGrads { float face_grads[]; };

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.face_count * pc.view_count) {
        return;
    }
    uint view = id / pc.face_count;
    uint face = id - view * pc.face_count;
    uint gview = pc.first_view + view;
    uint item = gview * pc.face_count + face;
    FaceSetup f = setups[item];
    bool vertex_colors = (pc.flags & FLAG_VERTEX_COLORS) != 0u;
    uint o = item * pc.grad_stride;
    for (uint i = 9u; i < pc.grad_stride; ++i) {
        face_grads[o + i] = 0.0;
    }
    vec3 acc[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
    vec3 cacc[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
    if ((f.flags & FACE_FINITE) != 0u) {
        for (uint row = 0u; row < pc.height; ++row) {
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
                    } else {
                        uint t = o + 9u + 3u * g.texel;
                        face_grads[t] += g.color[0].x;
                        face_grads[t + 1u] += g.color[0].y;
                        face_grads[t + 2u] += g.color[0].z;
                    }
                }
            }
        }
    }
    for (uint c = 0u; c < 3u; ++c) {
        face_grads[o + 3u * c] = acc[c].x;
        face_grads[o + 3u * c + 1u] = acc[c].y;
        face_grads[o + 3u * c + 2u] = acc[c].z;
        if (vertex_colors) {
            face_grads[o + 9u + 3u * c] = cacc[c].x;
            face_grads[o + 9u + 3u * c + 1u] = cacc[c].y;
            face_grads[o + 9u + 3u * c + 2u] = cacc[c].z;
        }
    }
}
