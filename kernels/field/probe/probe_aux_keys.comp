#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, backward under G = max, step 1: every ray's sort key is the anchor its ψ came
// from (`aux`), with the ray's index as the value. Rays without a hit join the last anchor's
// run, which `probe_max_grad.comp` skips them in: a bucket of their own past the last anchor
// would cost a key bit, and with 2^k anchors a whole sort pass. A stable sort then lists each
// anchor's rays in ray order (view by view: the rays are view-major), and the binning's ranges
// pass gives each anchor its run (`probe_max_grad.comp`).
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Rays { Ray rays[]; }; // (not read)
layout(std430, set = 0, binding = 1) readonly buffer Outs { RayOut outs[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Values { uint values[]; };

layout(push_constant) uniform Push {
    uint rays;
    uint anchors;
    uint views;
    uint pad0;
} pc;

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.rays) {
        return;
    }
    uint aux = outs[id].aux;
    uint key = aux == NO_HIT ? pc.anchors - 1u : aux;
    keys[id] = uvec2(key, 0u);
    values[id] = id;
}
