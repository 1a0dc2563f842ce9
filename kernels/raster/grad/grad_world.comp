#version 460
#extension GL_GOOGLE_include_directive : require
// Chains each (view, face)'s dL/d(screen vertices) through the projection to dL/d(world
// position) per corner, and keeps dL/d(camera-space point) per corner for the camera gradient.
// One invocation per (view, face). Twin: `reference_grad::face_screen_to_world_grad`.
#include "common.glsl"
#include "view.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Positions { float positions[]; };
layout(std430, set = 0, binding = 1) readonly buffer Faces { uint faces[]; };
layout(std430, set = 0, binding = 2) readonly buffer Views { View views[]; };
layout(std430, set = 0, binding = 3) readonly buffer FaceGrads { float face_grads[]; };
// 9 floats per (view, face): dL/d(world position) of corners 0, 1, 2.
layout(std430, set = 0, binding = 4) writeonly buffer CornerWorld { float corner_world[]; };
// 9 floats per (view, face): dL/d(camera-space point) of corners 0, 1, 2 (zero for a matrix).
layout(std430, set = 0, binding = 5) writeonly buffer CornerCam { float corner_cam[]; };

layout(push_constant) uniform Push {
    uint face_count;
    uint view_count;
    uint vertex_count;
    uint stride;       // floats per face gradient
    uint position_offset;  // floats before vertex 0's x (`VertexLayout`)
    uint position_stride;  // floats from one vertex's x to the next's
} pc;

// `matrix_projection_grad`: dL/d(world point) through P, the divide and the distortion.
vec3 matrix_grad(View view, vec3 p, vec3 g) {
    float x = view.rows[0].x * p.x + view.rows[0].y * p.y + view.rows[0].z * p.z + view.rows[0].w;
    float y = view.rows[1].x * p.x + view.rows[1].y * p.y + view.rows[1].z * p.z + view.rows[1].w;
    float z = view.rows[2].x * p.x + view.rows[2].y * p.y + view.rows[2].z * p.z + view.rows[2].w;
    float zs = z + 1e-5;
    float x1 = fm_div(x, zs);
    float y1 = fm_div(y, zs);
    float k1 = view.dist.x;
    float k2 = view.dist.y;
    float p1 = view.dist.z;
    float p2 = view.dist.w;
    float k3 = view.k3;
    float r2 = x1 * x1 + y1 * y1;
    float radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
    float d_radial = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r2 * r2;
    float half_size = view.param * 0.5;
    float g_x2 = fm_div(g.x, half_size);
    float g_y2 = fm_div(g.y, half_size);
    float dx2_dx1 = radial + 2.0 * x1 * x1 * d_radial + 2.0 * p1 * y1 + 6.0 * p2 * x1;
    float dx2_dy1 = 2.0 * x1 * y1 * d_radial + 2.0 * p1 * x1 + 2.0 * p2 * y1;
    float dy2_dx1 = dx2_dy1;
    float dy2_dy1 = radial + 2.0 * y1 * y1 * d_radial + 6.0 * p1 * y1 + 2.0 * p2 * x1;
    float g_x1 = g_x2 * dx2_dx1 + g_y2 * dy2_dx1;
    float g_y1 = g_x2 * dx2_dy1 + g_y2 * dy2_dy1;
    vec3 g_row = vec3(fm_div(g_x1, zs), fm_div(g_y1, zs), g.z - fm_div(g_x1 * x1 + g_y1 * y1, zs));
    return g_row.x * view.rows[0].xyz + g_row.y * view.rows[1].xyz + g_row.z * view.rows[2].xyz;
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.face_count * pc.view_count) {
        return;
    }
    uint view_index = id / pc.face_count;
    uint face = id - view_index * pc.face_count;
    View view = views[view_index];
    for (uint c = 0u; c < 3u; ++c) {
        uint gi = id * pc.stride + 3u * c;
        vec3 g = vec3(face_grads[gi], face_grads[gi + 1u], face_grads[gi + 2u]);
        vec3 world = vec3(0.0);
        vec3 d_cam = vec3(0.0);
        // A zero gradient stays zero (and a vertex on the camera plane gives no 0 · ∞).
        if (g != vec3(0.0)) {
            uint v = view.mesh * pc.vertex_count + faces[3u * face + c];
            uint at = pc.position_offset + pc.position_stride * v;
            vec3 p = vec3(positions[at], positions[at + 1u], positions[at + 2u]);
            if (view.projection == PROJ_MATRIX) {
                world = matrix_grad(view, p, g);
            } else {
                vec3 rel = p - view.eye.xyz;
                vec3 pcam = vec3(fm_dot3(view.rows[0].xyz, rel), fm_dot3(view.rows[1].xyz, rel),
                                 fm_dot3(view.rows[2].xyz, rel));
                if (view.projection == PROJ_PERSPECTIVE) {
                    float k_xy = fm_rcp(pcam.z * view.param);
                    d_cam = vec3(g.x * k_xy, g.y * k_xy,
                                 g.z - fm_div((g.x * pcam.x + g.y * pcam.y) * k_xy, pcam.z));
                } else {
                    d_cam = vec3(g.x * view.param, g.y * view.param, g.z);
                }
                world = view.rows[0].xyz * d_cam.x + view.rows[1].xyz * d_cam.y
                      + view.rows[2].xyz * d_cam.z;
            }
        }
        uint o = id * 9u + 3u * c;
        corner_world[o] = world.x;
        corner_world[o + 1u] = world.y;
        corner_world[o + 2u] = world.z;
        corner_cam[o] = d_cam.x;
        corner_cam[o + 1u] = d_cam.y;
        corner_cam[o + 2u] = d_cam.z;
    }
}
