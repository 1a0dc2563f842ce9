// A skinned articulated mesh on the GPU (`src/fit/rig.rs`, `src/fit/articulated.rs`): hinge
// joints in a tree, forward kinematics to one rigid transform per bone, linear blend skinning,
// in f32 (the angles, binding 0, are declared by the kernels that read them). Twins:
// `Rig::kinematics`, `Rig::skin`, `Rig::angle_gradient` (f64).
//
// Bone 0 is the unmoved root; bone j + 1 is moved by joint j. A joint turns its bone (and, by
// the tree, every bone below it) by its angle θ_j about its axis a_j through its pivot o_j, both
// given in the rest pose and carried along by the joint's parent:
//   G_{j+1}(x) = G_parent(R(a_j, θ_j) (x − o_j) + o_j).
#ifndef SOFTVK_SKIN_GLSL
#define SOFTVK_SKIN_GLSL

// A joint as `JointDef` (src/fit/articulated.rs) writes it: the rest pivot, the parent's bone
// (0: the root), the unit rest axis.
struct JointDef {
    vec3 pivot;
    uint parent_bone;
    vec3 axis;
    uint pad;
};

// A bone's transform x ↦ M x + b as three rows (M's row, b's component), then, for the bone of
// a joint, the joint's axis and pivot in the posed world (a zero w).
struct Bone {
    vec4 rows[3];
    vec4 world_axis;
    vec4 world_pivot;
};

// Up to four bones per vertex and their weights (summing to 1).
struct Skin {
    uvec4 bones;
    vec4 weights;
};

vec3 bone_apply(Bone b, vec3 x) {
    return vec3(fm_dot3(b.rows[0].xyz, x) + b.rows[0].w,
                fm_dot3(b.rows[1].xyz, x) + b.rows[1].w,
                fm_dot3(b.rows[2].xyz, x) + b.rows[2].w);
}

// R(a, θ) = I + sin θ [a]× + (1 − cos θ) [a]×² for a unit axis a; (1 − cos θ) as 2 sin²(θ/2).
mat3 axis_rotation(vec3 a, float theta) {
    mat3 k = mat3(vec3(0.0, a.z, -a.y), vec3(-a.z, 0.0, a.x), vec3(a.y, -a.x, 0.0));
    float h = fm_sin(0.5 * theta);
    return mat3(1.0) + fm_sin(theta) * k + (2.0 * h * h) * fm_mul33m(k, k);
}

// Twin of `SkinPush` (src/fit/articulated.rs).
layout(push_constant) uniform Push {
    uint vertex_count;
    uint joint_count;
    uint log_index; // skin_grad.comp only
    uint pad;
} pc;

#endif
