#version 460
#extension GL_GOOGLE_include_directive : require
// MLP backward, step 2 of 3: one invocation per (chunk of FIELD_CHUNK points, parameter j):
// partial[chunk · P + j] = Σ over the chunk's points, in order, of δ_l[o] · a_l[i] (weight
// W_l[o][i]) or δ_l[o] (bias b_l[o]). Twin: the plain sums of `crate::field::cpu::backward`.
#include "common.glsl"

#define FIELD_CHUNK 256u

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Acts { float acts[]; };
layout(std430, set = 0, binding = 1) readonly buffer Deltas { float deltas[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Partial { float partial[]; };

layout(push_constant) uniform Push {
    vec4 cube;
    uint n;
    uint layers;
    uint width;
    uint freqs;
    float beta;
    uint batch;
    uint chunks;
    uint param_count;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint chunk = id / pc.param_count;
    uint j = id % pc.param_count;
    if (chunk >= pc.chunks) {
        return;
    }
    uint e = 3u + 6u * pc.freqs;
    uint w = pc.width;
    // Layer l of parameter j: in_dim, out_dim, its offset, the feature of its input a_l.
    uint off = 0u;
    uint in_dim = e;
    uint out_dim = w;
    uint feature = 0u;
    uint l = 0u;
    for (; l < pc.layers; ++l) {
        uint size = out_dim * in_dim + out_dim;
        if (j < off + size) {
            break;
        }
        off += size;
        feature = e + l * w;
        in_dim = w;
        out_dim = l + 1u == pc.layers ? 1u : w;
    }
    uint local = j - off;
    bool bias = local >= out_dim * in_dim;
    uint o = bias ? local - out_dim * in_dim : local / in_dim;
    uint delta_row = (l * w + o) * pc.batch;
    uint act_row = (feature + local % in_dim) * pc.batch;
    uint p0 = chunk * FIELD_CHUNK;
    uint p1 = min(p0 + FIELD_CHUNK, pc.n);
    float s = 0.0;
    if (bias) {
        for (uint p = p0; p < p1; ++p) {
            s += deltas[delta_row + p];
        }
    } else {
        for (uint p = p0; p < p1; ++p) {
            s += deltas[delta_row + p] * acts[act_row + p];
        }
    }
    partial[chunk * pc.param_count + j] = s;
}
