// The forward of sphere probing, shared by `probe_forward.comp` (tiled) and
// `probe_forward_brute.comp` (every anchor): the push constants and the per-ray setup.
#ifndef SOFTVK_PROBE_FORWARD_GLSL
#define SOFTVK_PROBE_FORWARD_GLSL

// Twin of `ForwardPush` (src/probe/prober.rs).
layout(push_constant) uniform Push {
    uint rays;           // rays of all views
    uint anchors;        // anchors (items per view)
    uint width;
    uint height;
    uint tile_size;
    uint tiles_x;
    uint tiles_y;
    uint mode;           // AGG_*
    float inv_s;         // 1 / min(W, H)
    float tau2;          // τ²
    float temperature;   // LSE: T
    float inv_t;         // LSE: 1 / T
    uint boundary_aware; // skip anchors whose centre is on the other side of the silhouette
    uint pad0;
    uint pad1;
    uint pad2;
} pc;

// Does the boundary-aware assignment let a ray with `label` use an anchor with `flags`?
bool assigned(float label, uint flags) {
    return pc.boundary_aware == 0u || (label >= 0.5) == ((flags & FLAG_INSIDE) != 0u);
}

#endif
