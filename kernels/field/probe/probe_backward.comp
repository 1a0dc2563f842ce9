#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
// Sphere probing, backward, step 2: one invocation per binned (anchor, tile) entry. It visits
// the rays of its tile in ray order and sums (ψ − S) dψ/dφ_j over those that used anchor j in
// the forward: max: the rays whose ψ came from j; LSE and union: the rays that hit j (the same
// `precise` hit test and assignment as the forward, so the same decisions). Every ray that
// reached j lies in one tile j was binned to, so each (ray, anchor) pair is counted once. The
// sum lands at the entry's index; `probe_reduce.comp` then adds each anchor's entries in a fixed
// order (view, then its tiles row by row). No atomics. Twin: `probe::prober::cpu::backward`.
//
// For llvmpipe's execution model (and without shared memory or barriers on any device): each
// subgroup works alone. Its entries, consecutive in tile order, mostly share one tile; it takes
// their tiles one at a time (the lowest lane's first). Per batch of as many of the tile's rays as
// it has lanes, each lane loads one ray and its forward result (one gathered load per batch
// instead of loads per (entry, ray) pair), and a loop over the batch broadcasts each ray with
// shuffles to every entry of the tile. Each entry still adds its rays in ray order with the same
// expressions, so the partials are what a loop per entry gives, bit for bit. The aggregation
// and the assignment are specialization constants, as in the forward.
#include "common.glsl"
#include "probe.glsl"

layout(local_size_x = 64) in;

// Lanes of this subgroup in the 64-invocation workgroup (never a fixed number: 8 on llvmpipe
// with AVX2, 32 on NVIDIA, 64 or 32 on AMD), and the words of its ballots.
uint subgroup_lanes() {
    return min(gl_SubgroupSize, 64u);
}
uint ballot_words() {
    return (gl_SubgroupSize + 31u) / 32u;
}

// The tile and the anchor of every entry (`probe_mask_list.comp`).
layout(std430, set = 0, binding = 0) readonly buffer ListTiles { uint list_tiles[]; };
layout(std430, set = 0, binding = 1) readonly buffer List { uint list[]; };
layout(std430, set = 0, binding = 2) readonly buffer Items { ProbeItem items[]; };
layout(std430, set = 0, binding = 3) readonly buffer Anchors { vec4 anchors[]; };
layout(std430, set = 0, binding = 4) readonly buffer Phi { float phi[]; };
layout(std430, set = 0, binding = 5) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 6) readonly buffer Views { ProbeView views[]; };
layout(std430, set = 0, binding = 7) readonly buffer Outs { RayOut outs[]; };
// Ray indices sorted by tile, and each tile's [start, end) in them.
layout(std430, set = 0, binding = 8) readonly buffer RayOrder { uint ray_order[]; };
layout(std430, set = 0, binding = 9) readonly buffer RayRanges { uvec2 ray_ranges[]; };
layout(std430, set = 0, binding = 10) writeonly buffer Partials { float partials[]; };
// Each tile's first entry, then the entry count at `total_index` (`probe_mask_list.comp`'s
// offsets): the entries that exist, which a guarded binning knows only here.
layout(std430, set = 0, binding = 11) readonly buffer Offsets { uint offsets[]; };

// Twin of `BackwardPush` (src/probe/prober/).
layout(push_constant) uniform Push {
    uint entries;        // entries the buffers hold (the count, or a guarded capacity)
    uint anchors;
    uint width;
    uint height;
    uint tiles_x;
    uint tiles_y;
    uint mode;           // AGG_* (unused: MODE)
    uint boundary_aware; // unused: BOUNDARY_AWARE
    float inv_s;
    float tau2;
    float inv_t;
    uint total_index;    // where `offsets` holds the entry count (the tile count)
    float tau2_outside;  // τ² of the rays outside the silhouettes
    uint pad0;
    uint pad1;
    uint pad2;
} pc;

layout(constant_id = 0) const uint MODE = AGG_MAX;
layout(constant_id = 1) const uint BOUNDARY_AWARE = 1u;

void main() {
    uint e = linear_group_id() * 64u + gl_LocalInvocationIndex;
    bool live = e < min(pc.entries, offsets[pc.total_index]);
    // A lane past the end stands in for tile 0 and anchor 0 and writes nothing (its load reads
    // slot 0, which the buffers always have, and is then discarded: with no entries at all
    // that slot holds whatever an earlier binning left).
    uint tile = list_tiles[live ? e : 0u];
    uint anchor = list[live ? e : 0u];
    tile = live ? tile : 0u;
    anchor = live ? anchor : 0u;
    uint view = tile / (pc.tiles_x * pc.tiles_y);
    bool anchor_inside = (items[view * pc.anchors + anchor].flags & FLAG_INSIDE) != 0u;
    vec3 p = anchors[anchor].xyz;
    float phi_j = phi[anchor];
    ProbeView v;
    if (MODE != AGG_MAX) {
        v = views[view];
    }

    uint lanes = subgroup_lanes();
    uint lane = gl_SubgroupInvocationID;
    float sum = 0.0;
    bool todo = live;
    uvec4 pending = subgroupBallot(todo);
    while (pending != uvec4(0u)) {
        uint t = subgroupShuffle(tile, subgroupBallotFindLSB(pending));
        bool mine = todo && tile == t;
        todo = todo && !mine;
        uvec2 range = ray_ranges[t];
        for (uint start = range.x; start < range.y; start += lanes) {
            uint k = start + lane;
            RayOut ro = RayOut(0.0, 0.0, NO_HIT, 0.0);
            Ray r = Ray(0.0, 0.0, 0u, 0.0);
            if (k < range.y && lane < lanes) {
                uint ray = ray_order[k];
                ro = outs[ray];
                r = rays[ray];
            }
            float err = ro.psi - r.label;
            uint count = min(lanes, range.y - start);
            for (uint i = 0u; i < count; ++i) {
                float err_i = subgroupShuffle(err, i);
                uint aux_i = subgroupShuffle(ro.aux, i);
                if (MODE == AGG_MAX) {
                    if (mine && aux_i == anchor) {
                        sum += err_i;
                    }
                } else {
                    RayOut ro_i = RayOut(subgroupShuffle(ro.psi, i), 0.0, aux_i,
                                         subgroupShuffle(ro.aux_f, i));
                    float px = subgroupShuffle(r.px, i);
                    float py = subgroupShuffle(r.py, i);
                    float label = subgroupShuffle(r.label, i);
                    bool use = mine
                        && (BOUNDARY_AWARE == 0u || (label >= 0.5) == anchor_inside);
                    vec3 o;
                    vec3 d;
                    view_ray(v, pixel_to_screen(px, py, float(pc.width), float(pc.height),
                                                pc.inv_s), o, d);
                    float bound = hit_bound(d, ray_tau2(label, pc.tau2, pc.tau2_outside));
                    if (use && ray_hits(o, d, bound, p)) {
                        sum += err_i * agg_grad(ro_i, MODE, pc.inv_t, phi_j);
                    }
                }
            }
        }
        pending = subgroupBallot(todo);
    }
    if (live) {
        partials[e] = sum;
    }
}
