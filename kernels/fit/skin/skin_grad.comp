#version 460
#extension GL_GOOGLE_include_directive : require
// dL/dθ_j from dL/dp' per vertex, workgroup j for joint j. Turning joint j by dθ moves a point
// x of any bone below it (its own included) by ω_j × (x − c_j) dθ, ω_j and c_j the joint's
// posed axis and pivot, so
//   dL/dθ_j = ω_j · Σ_v Σ_i [k_i below j] w_i ((M_{k_i} p_v + b_{k_i}) − c_j) × g_v.
// `below[k]` holds, per bone k, the bits of the joints that move it (64 joints: two words).
// Invocation l sums the vertices l, l + 64, ... in order, then a fixed tree over the 64: the
// same bits on every run. Also logs the iteration: the loss (workgroup 0) and each angle.
// Twin: `Rig::angle_gradient` (f64).
#include "common.glsl"
#include "skin.glsl"

layout(local_size_x = 64) in;

// The joint angles (radians), one float per joint.
layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Bones { Bone bones[]; };
layout(std430, set = 0, binding = 2) readonly buffer Rest { float rest[]; };
layout(std430, set = 0, binding = 3) readonly buffer Skins { Skin skins[]; };
layout(std430, set = 0, binding = 4) readonly buffer Below { uvec2 below[]; };
layout(std430, set = 0, binding = 5) readonly buffer DPosed { float d_posed[]; };
layout(std430, set = 0, binding = 6) writeonly buffer DParams { float d_params[]; };
layout(std430, set = 0, binding = 7) readonly buffer Loss { float loss[]; };
// Per iteration: the loss, then the joint_count angles it evaluated.
layout(std430, set = 0, binding = 8) writeonly buffer Log { float log_rows[]; };

shared vec3 torques[64];

void main() {
    uint l = gl_LocalInvocationIndex;
    uint j = gl_WorkGroupID.x;
    Bone own = bones[j + 1u];
    vec3 c = own.world_pivot.xyz;
    uint word = j >> 5u;
    uint bit = 1u << (j & 31u);
    vec3 torque = vec3(0.0);
    for (uint v = l; v < pc.vertex_count; v += 64u) {
        vec3 p = vec3(rest[3u * v], rest[3u * v + 1u], rest[3u * v + 2u]);
        vec3 g = vec3(d_posed[3u * v], d_posed[3u * v + 1u], d_posed[3u * v + 2u]);
        Skin s = skins[v];
        vec3 moved = vec3(0.0);
        for (uint i = 0u; i < 4u; i++) {
            uint k = s.bones[i];
            bool moves = (below[k][word] & bit) != 0u;
            moved += moves ? s.weights[i] * (bone_apply(bones[k], p) - c) : vec3(0.0);
        }
        torque += fm_cross(moved, g);
    }
    torques[l] = torque;
    barrier();
    for (uint half_ = 32u; half_ > 0u; half_ >>= 1u) {
        if (l < half_) {
            torques[l] += torques[l + half_];
        }
        barrier();
    }
    if (l == 0u) {
        d_params[j] = fm_dot3(own.world_axis.xyz, torques[0]);
        uint row = pc.log_index * (pc.joint_count + 1u);
        log_rows[row + 1u + j] = params[j];
        if (j == 0u) {
            log_rows[row] = loss[0];
        }
    }
}
