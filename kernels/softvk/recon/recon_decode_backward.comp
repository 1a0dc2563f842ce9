#version 460
#extension GL_GOOGLE_include_directive : require
// The backward of `recon_decode.comp`, per object b and vertex i. The position's gradient is
//   g = d_canonical[b, i] + Σ_k Rᵀ_k d_positions[b·copies + k, i]   (k ascending),
// Rᵀ: x = cos φ x' − sin φ z', z = sin φ x' + cos φ z'; then, per coordinate, with p = 0.5 v:
//   dL/d r_d = 0.5 g (v > 0 ? 1 − c : c + 1) s (1 − s) sign(t)
// and the vertex's share of dL/dc, 0.5 g (1 − |v|), at its slot of `partials`;
// `recon_centroid_grad.comp` sums the shares over the vertices in order and chains through
// c = tanh(0.1 r_c). Twin: `crate::recon::decode::cpu::backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Outputs { float outputs[]; };
layout(std430, set = 0, binding = 1) readonly buffer Base { float base[]; };
layout(std430, set = 0, binding = 2) readonly buffer Signs { float signs[]; };
layout(std430, set = 0, binding = 3) readonly buffer Rotations { vec2 rotations[]; };
layout(std430, set = 0, binding = 4) readonly buffer DCanonical { float d_canonical[]; };
layout(std430, set = 0, binding = 5) readonly buffer DPositions { float d_positions[]; };
layout(std430, set = 0, binding = 6) writeonly buffer DOutputs { float d_outputs[]; };
layout(std430, set = 0, binding = 7) writeonly buffer Partials { float partials[]; };

layout(push_constant) uniform Push {
    uint vertex_count;
    uint objects;
    uint copies;
    uint stride;
} pc;

void main() {
    uint gid = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (gid >= pc.vertex_count * pc.objects) {
        return;
    }
    uint b = gid / pc.vertex_count;
    uint i = gid - b * pc.vertex_count;
    uint o = 3u * gid;
    vec3 g = vec3(d_canonical[o], d_canonical[o + 1u], d_canonical[o + 2u]);
    for (uint k = 0u; k < pc.copies; ++k) {
        uint copy = b * pc.copies + k;
        vec2 cs = rotations[copy];
        uint q = 3u * (copy * pc.vertex_count + i);
        vec3 d = vec3(d_positions[q], d_positions[q + 1u], d_positions[q + 2u]);
        g += vec3(cs.x * d.x - cs.y * d.z, d.y, cs.y * d.x + cs.x * d.z);
    }
    uint r0 = b * pc.stride;
    for (uint k = 0u; k < 3u; ++k) {
        uint t = 3u * i + k;
        float c = fm_tanh(0.1 * outputs[r0 + 3u * pc.vertex_count + k]);
        float s = fm_sigmoid(base[t] + outputs[r0 + t]);
        float sign_t = signs[t];
        float v = s * sign_t;
        float gk = 0.5 * g[k];
        float dv = v > 0.0 ? 1.0 - c : c + 1.0;
        d_outputs[r0 + t] = gk * dv * (s * (1.0 - s)) * sign_t;
        partials[o + k] = gk * (1.0 - abs(v));
    }
}
