#version 460
#extension GL_GOOGLE_include_directive : require
// The posed positions of the rest mesh, p' = R(ω) (p − c) + c + t, one invocation per vertex,
// packed xyz. Twin: `Pose::apply` (f64).
#include "common.glsl"
#include "pose.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 1) readonly buffer Rest { float rest[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Posed { float posed[]; };

// Twin of `PosePush` (src/fit/pose/).
layout(push_constant) uniform Push {
    vec3 centre;
    uint vertex_count;
    uint translation_at;
    uint log_index; // pose_grad.comp only
    uint pad0;
    uint pad1;
} pc;

void main() {
    uint v = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (v >= pc.vertex_count) {
        return;
    }
    vec3 w = vec3(params[0], params[1], params[2]);
    uint ti = pc.translation_at;
    vec3 t = vec3(params[ti], params[ti + 1u], params[ti + 2u]);
    vec3 p = vec3(rest[3u * v], rest[3u * v + 1u], rest[3u * v + 2u]);
    vec3 q = fm_mul33(rotation_matrix(w), p - pc.centre) + pc.centre + t;
    posed[3u * v] = q.x;
    posed[3u * v + 1u] = q.y;
    posed[3u * v + 2u] = q.z;
}
