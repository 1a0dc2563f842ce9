#version 460
#extension GL_GOOGLE_include_directive : require
// Forward kinematics: every bone's transform from the joint angles, one invocation walking the
// joints in order (a parent comes before its children, so its bone is written when a child
// reads it). At most 64 joints. Twin: `Rig::kinematics` (f64).
#include "common.glsl"
#include "skin.glsl"

layout(local_size_x = 1) in;

// The joint angles (radians), one float per joint.
layout(std430, set = 0, binding = 0) readonly buffer Params { float params[]; };
layout(std430, set = 0, binding = 1) readonly buffer Joints { JointDef joints[]; };
layout(std430, set = 0, binding = 2) buffer Bones { Bone bones[]; };

void main() {
    Bone root;
    root.rows[0] = vec4(1.0, 0.0, 0.0, 0.0);
    root.rows[1] = vec4(0.0, 1.0, 0.0, 0.0);
    root.rows[2] = vec4(0.0, 0.0, 1.0, 0.0);
    root.world_axis = vec4(0.0);
    root.world_pivot = vec4(0.0);
    bones[0] = root;
    for (uint j = 0u; j < pc.joint_count; j++) {
        JointDef d = joints[j];
        Bone p = bones[d.parent_bone];
        // The parent's M as a matrix (GLSL's mat3 takes columns: transpose the rows).
        mat3 mp = transpose(mat3(p.rows[0].xyz, p.rows[1].xyz, p.rows[2].xyz));
        vec3 bp = vec3(p.rows[0].w, p.rows[1].w, p.rows[2].w);
        mat3 r = axis_rotation(d.axis, params[j]);
        mat3 m = fm_mul33m(mp, r);
        vec3 b = fm_mul33(mp, d.pivot - fm_mul33(r, d.pivot)) + bp;
        Bone o;
        o.rows[0] = vec4(m[0][0], m[1][0], m[2][0], b.x);
        o.rows[1] = vec4(m[0][1], m[1][1], m[2][1], b.y);
        o.rows[2] = vec4(m[0][2], m[1][2], m[2][2], b.z);
        o.world_axis = vec4(fm_mul33(mp, d.axis), 0.0);
        o.world_pivot = vec4(fm_mul33(mp, d.pivot) + bp, 0.0);
        bones[j + 1u] = o;
    }
}
