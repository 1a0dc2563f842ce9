#version 460
#extension GL_GOOGLE_include_directive : require
// dL/d(ω, t) from dL/dp' per vertex, one workgroup: dL/dt = Σ_i g_i,
// dL/dω = J_l(ω)ᵀ Σ_i (q_i × g_i), q_i = R(ω)(p_i − c). Invocation l sums the vertices
// l, l + 64, ... in order, then a fixed tree over the 64: the same bits on every run. Also logs
// the iteration: its loss and the pose it was evaluated at. Twin: `pose_gradient` (f64).
#include "common.glsl"
#include "pose.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 1) readonly buffer Rest { float rest[]; };
layout(std430, set = 0, binding = 2) readonly buffer DPosed { float d_posed[]; };
// dL/d(params), the layout of `params`.
layout(std430, set = 0, binding = 3) writeonly buffer DParams { float d_params[]; };
layout(std430, set = 0, binding = 4) readonly buffer Loss { float loss[]; };
// Per iteration: the loss, ω, t, and an unused float.
layout(std430, set = 0, binding = 5) writeonly buffer Log { vec4 log_rows[]; };

layout(push_constant) uniform Push {
    vec3 centre;
    uint vertex_count;
    uint translation_at;
    uint log_index;
    uint pad0;
    uint pad1;
} pc;

shared vec3 torques[64];
shared vec3 forces[64];

void main() {
    uint l = gl_LocalInvocationIndex;
    vec3 w = vec3(params[0], params[1], params[2]);
    uint ti = pc.translation_at;
    vec3 t = vec3(params[ti], params[ti + 1u], params[ti + 2u]);
    mat3 r = rotation_matrix(w);
    vec3 torque = vec3(0.0);
    vec3 force = vec3(0.0);
    for (uint v = l; v < pc.vertex_count; v += 64u) {
        vec3 p = vec3(rest[3u * v], rest[3u * v + 1u], rest[3u * v + 2u]);
        vec3 g = vec3(d_posed[3u * v], d_posed[3u * v + 1u], d_posed[3u * v + 2u]);
        torque += fm_cross(fm_mul33(r, p - pc.centre), g);
        force += g;
    }
    torques[l] = torque;
    forces[l] = force;
    barrier();
    for (uint half_ = 32u; half_ > 0u; half_ >>= 1u) {
        if (l < half_) {
            torques[l] += torques[l + half_];
            forces[l] += forces[l + half_];
        }
        barrier();
    }
    if (l == 0u) {
        vec3 d_w = fm_mul33(transpose(left_jacobian(w)), torques[0]);
        vec3 d_t = forces[0];
        d_params[0] = d_w.x;
        d_params[1] = d_w.y;
        d_params[2] = d_w.z;
        d_params[ti] = d_t.x;
        d_params[ti + 1u] = d_t.y;
        d_params[ti + 2u] = d_t.z;
        log_rows[2u * pc.log_index] = vec4(loss[0], w);
        log_rows[2u * pc.log_index + 1u] = vec4(t, 0.0);
    }
}
