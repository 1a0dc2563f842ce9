#version 460
#extension GL_GOOGLE_include_directive : require
// The reconstruction decoder's mesh (SoftRas `models.py` Decoder), per object b and vertex i,
// from the network's outputs r = [displacement (3 V), centroid (3)] of object b and the sphere
// template's base = log(|t| / (1 − |t|)) and sign(t) (template already scaled by obj_scale):
//   c = tanh(0.1 r_c);  s = sigmoid(base + r_d);  v = s sign(t)
//   v = relu(v) (1 − c) − relu(−v) (c + 1) + c;   p = 0.5 v
// p goes to `canonical` (the object's mesh) and, turned about y by each of its copies'
// rotations (cos φ, sin φ): x' = cos φ x + sin φ z, z' = −sin φ x + cos φ z, to the renderer's
// positions (copy k of object b is mesh b·copies + k).
// Twin: `crate::recon::decode::cpu::forward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) readonly buffer Base { float base[]; };
layout(std430, set = 0, binding = 2) readonly buffer Signs { float signs[]; };
layout(std430, set = 0, binding = 3) readonly buffer Rotations { vec2 rotations[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Canonical { float canonical[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Positions { float positions[]; };

layout(push_constant) uniform Push {
    uint vertex_count;
    uint objects;
    uint copies;
    uint stride;  // floats per object in `outputs` (3 V + 3)
} pc;

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.vertex_count * pc.objects) {
        return;
    }
    uint b = gid / pc.vertex_count;
    uint i = gid - b * pc.vertex_count;
    uint r0 = b * pc.stride;
    vec3 p;
    for (uint k = 0u; k < 3u; ++k) {
        uint t = 3u * i + k;
        float c = fm_tanh(0.1 * outputs[r0 + 3u * pc.vertex_count + k]);
        float s = fm_sigmoid(base[t] + outputs[r0 + t]);
        float v = s * signs[t];
        p[k] = 0.5 * ((max(v, 0.0) * (1.0 - c) - max(-v, 0.0) * (c + 1.0)) + c);
    }
    uint o = 3u * gid;
    canonical[o] = p.x;
    canonical[o + 1u] = p.y;
    canonical[o + 2u] = p.z;
    for (uint k = 0u; k < pc.copies; ++k) {
        uint copy = b * pc.copies + k;
        vec2 cs = rotations[copy];
        uint q = 3u * (copy * pc.vertex_count + i);
        positions[q] = cs.x * p.x + cs.y * p.z;
        positions[q + 1u] = p.y;
        positions[q + 2u] = cs.x * p.z - cs.y * p.x;
    }
}
