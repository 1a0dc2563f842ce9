#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
// Sphere probing, forward, tiled: one invocation per ray, the rays taken in tile order
// (`ray_order`, the stable sort of the rays by tile); ψ = G(φ of the anchors the ray passes
// within τ of), over the anchors binned to the ray's tile, in anchor order (the tile's entries,
// `probe_mask_list.comp`, list its anchors in index order): the same hits in the same order as
// `probe_forward_brute.comp`, so the same ψ bit for bit. Anchors on the other side of the
// silhouette from the ray are skipped (boundary-aware assignment). Writes ψ, (ψ − S)² and the
// state the backward needs. A tile whose run is too long for one invocation's loops is folded
// in passes (`CARRY` in probe_forward.glsl). Twin: `probe::prober::cpu::forward`.
//
// For llvmpipe's execution model (and without shared memory or barriers on any device): each
// subgroup works alone. Its rays, consecutive in tile order, lie in one tile or a few; it takes
// their tiles one at a time (the lowest lane's first). Per batch of as many of the tile's binned
// anchors as it has lanes, each lane loads one anchor (its flags, centre and φ: one gathered
// load per batch instead of a load per hit test); a ballot keeps those that some ray of the
// tile may use (boundary-aware: an anchor whose side of the silhouette no ray of the tile has is
// dropped); the loop over the ballot's bits, lowest first (anchor order), broadcasts each kept
// anchor with shuffles and every ray of the tile tests and aggregates it. Nothing assumes a
// subgroup size; the workgroup is 64 invocations (a few subgroups on every device).
#define CARRY_BINDING 9
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

// The rays (one texel each), the views (`ProbeView`, ten texels), the anchors (one texel), the
// items (`ProbeItem`, two texels) and the entries (below) as texel buffers of the same bytes:
// on llvmpipe a storage-buffer load is a scalar loop over the lanes with a bounds-check branch
// per component, a texel fetch one branch-free gather of a whole texel.
layout(set = 0, binding = 0, rgba32ui) uniform readonly restrict uimageBuffer rays;
layout(set = 0, binding = 1, rgba32ui) uniform readonly restrict uimageBuffer views;
layout(set = 0, binding = 2, rgba32ui) uniform readonly restrict uimageBuffer anchors;
layout(std430, set = 0, binding = 3) readonly buffer Phi { float phi[]; };
layout(set = 0, binding = 4, rgba32ui) uniform readonly restrict uimageBuffer items;
// Each tile's first entry, then the entry count: tile t's entries are [offsets[t], offsets[t + 1])
// (`bin_mask_counts.comp` and the scan).
layout(std430, set = 0, binding = 5) readonly buffer Offsets { uint offsets[]; };
// The anchor of every entry, sorted by tile, each tile's in index order: four entries a texel.
layout(set = 0, binding = 6, rgba32ui) uniform readonly restrict uimageBuffer list;
layout(std430, set = 0, binding = 7) writeonly buffer Outs { RayOut outs[]; };
// Ray indices sorted by tile (`probe_ray_keys.comp` and the stable sort).
layout(std430, set = 0, binding = 8) readonly buffer RayOrder { uint ray_order[]; };

#include "probe_forward.glsl"

vec4 texel_f(uvec4 t) {
    return uintBitsToFloat(t);
}

void main() {
    uint q = linear_group_id() * 64u + gl_LocalInvocationIndex;
    bool live = q < pc.rays;
    // A lane past the end stands in for ray 0 (pc.rays > 0: the host dispatches nothing
    // otherwise) and aggregates nothing.
    uint id = live ? ray_order[q] : 0u;
    uvec4 rt = imageLoad(rays, int(id));
    Ray r = Ray(uintBitsToFloat(rt.x), uintBitsToFloat(rt.y), rt.z, uintBitsToFloat(rt.w));
    // The fields of the ray's view that `view_ray` reads: o0, ox, oy, d0, dx, dy.
    ProbeView v;
    int vt = int(r.view * PROBE_VIEW_TEXELS);
    v.o0 = texel_f(imageLoad(views, vt + 4));
    v.ox = texel_f(imageLoad(views, vt + 5));
    v.oy = texel_f(imageLoad(views, vt + 6));
    v.d0 = texel_f(imageLoad(views, vt + 7));
    v.dx = texel_f(imageLoad(views, vt + 8));
    v.dy = texel_f(imageLoad(views, vt + 9));
    vec3 o;
    vec3 d;
    view_ray(v, pixel_to_screen(r.px, r.py, float(pc.width), float(pc.height), pc.inv_s), o, d);
    float bound = hit_bound(d, ray_tau2(r.label, pc.tau2, pc.tau2_outside));
    uint tile = ray_tile(r, pc.width, pc.height, pc.tile_size, pc.tiles_x, pc.tiles_y);
    bool inside = r.label >= 0.5;
    uint tiles_per_view = pc.tiles_x * pc.tiles_y;

    uint lanes = subgroup_lanes();
    uint lane = gl_SubgroupInvocationID;
    // This pass's part of each tile's run (all of it without CARRY). A ray whose tile's run
    // ended in an earlier pass is done: its ψ is written.
    uint begin = CARRY != 0u ? pc.pass_begin : 0u;
    uint my_run = offsets[tile + 1u] - offsets[tile];
    bool done = begin > 0u && begin >= my_run;
    Agg g = begin > 0u && live && !done ? carry_load(id) : agg_init(MODE);
    bool todo = live && !done;
    uvec4 pending = subgroupBallot(todo);
    while (pending != uvec4(0u)) {
        uint t = subgroupShuffle(tile, subgroupBallotFindLSB(pending));
        bool mine = todo && tile == t;
        todo = todo && !mine;
        bool any_in = subgroupBallot(mine && inside) != uvec4(0u);
        bool any_out = subgroupBallot(mine && !inside) != uvec4(0u);
        uvec2 range = uvec2(offsets[t], offsets[t + 1u]);
        uint run = range.y - range.x;
        range = uvec2(range.x + min(begin, run),
                      range.x + (CARRY != 0u ? min(pc.pass_end, run) : run));
        uint item_base = (t / tiles_per_view) * pc.anchors;
        for (uint start = range.x; start < range.y; start += lanes) {
            uint k = start + lane;
            uint anchor = 0u;
            uint flags = 0u;
            vec4 a = vec4(0.0);
            bool loaded = k < range.y && lane < lanes;
            if (loaded) {
                anchor = ENTRY_WORD(list, k);
                // ProbeItem's second texel starts with its flags.
                flags = imageLoad(items, int(2u * (item_base + anchor) + 1u)).x;
                a = vec4(texel_f(imageLoad(anchors, int(anchor))).xyz, phi[anchor]);
            }
            bool side_in = (flags & FLAG_INSIDE) != 0u;
            bool usable = BOUNDARY_AWARE == 0u || (side_in ? any_in : any_out);
            uvec4 kept = subgroupBallot(loaded && usable);
            for (uint word = 0u; word < ballot_words(); ++word) {
                uint mask = kept[word];
                while (mask != 0u) {
                    uint i = 32u * word + uint(findLSB(mask));
                    mask &= mask - 1u;
                    uint an = subgroupShuffle(anchor, i);
                    uint fl = subgroupShuffle(flags, i);
                    vec4 pa = subgroupShuffle(a, i);
                    if (mine && assigned(r.label, fl) && ray_hits(o, d, bound, pa.xyz)) {
                        agg_add(g, MODE, pc.inv_t, pa.w, an);
                    }
                }
            }
        }
        pending = subgroupBallot(todo);
    }
    if (live && !done && CARRY != 0u && pc.pass_end < my_run) {
        carry_store(g, id);
    } else if (live && !done) {
        outs[id] = agg_finish(g, MODE, pc.temperature, r.label);
    }
}
