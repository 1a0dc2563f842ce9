// The forward of sphere probing, shared by `probe_forward.comp` (tiled) and
// `probe_forward_brute.comp` (every anchor): the push constants and the per-ray setup.
#ifndef SOFTVK_PROBE_FORWARD_GLSL
#define SOFTVK_PROBE_FORWARD_GLSL

// Twin of `ForwardPush` (src/probe/prober/).
layout(push_constant) uniform Push {
    uint rays;           // rays of all views
    uint anchors;        // anchors (items per view)
    uint width;
    uint height;
    uint tile_size;
    uint tiles_x;
    uint tiles_y;
    uint mode;           // AGG_* (unused: MODE)
    float inv_s;         // 1 / min(W, H)
    float tau2;          // τ²
    float temperature;   // LSE: T
    float inv_t;         // LSE: 1 / T
    uint boundary_aware; // unused: BOUNDARY_AWARE
    float tau2_outside;  // τ² of the rays outside the silhouettes
    uint pass_begin;     // with CARRY: this pass's anchors, [pass_begin, pass_end) of a ray's
    uint pass_end;       //   list (brute: of all anchors; tiled: of its tile's run)
} pc;

// The aggregation (AGG_*) and boundary-aware assignment as specialization constants (the push
// constants' `mode` and `boundary_aware` are not read): a pipeline per combination, so that only
// the chosen mode's code runs (on llvmpipe an `if` on a push constant runs both sides). The
// tiled and brute-force kernels share these and every per-hit function, so they stay equal bit
// for bit.
layout(constant_id = 0) const uint MODE = AGG_MAX;
layout(constant_id = 1) const uint BOUNDARY_AWARE = 1u;
// An anchor list too long for one invocation (llvmpipe ends an invocation's loops after 65 535
// iterations) is folded in passes over consecutive parts of it: each pass but the last leaves
// every ray's running aggregate in `carry`, the next resumes from it; the same anchors in the
// same order, so the same bits as one pass. Without CARRY the binding is a placeholder and no
// code touches it. The includer defines CARRY_BINDING.
layout(constant_id = 2) const uint CARRY = 0u;

layout(std430, set = 0, binding = CARRY_BINDING) restrict buffer Carry { uvec4 carry[]; };

void carry_store(Agg g, uint ray) {
    carry[ray] = uvec4(floatBitsToUint(g.m), floatBitsToUint(g.s), g.aux, g.count);
}

Agg carry_load(uint ray) {
    uvec4 c = carry[ray];
    return Agg(uintBitsToFloat(c.x), uintBitsToFloat(c.y), c.z, c.w);
}

// Does the boundary-aware assignment let a ray with `label` use an anchor with `flags`?
bool assigned(float label, uint flags) {
    return BOUNDARY_AWARE == 0u || (label >= 0.5) == ((flags & FLAG_INSIDE) != 0u);
}

#endif
