#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
#extension GL_KHR_shader_subgroup_arithmetic : require
// Tiled backward of the fine pass, one chunk of (face, tile) entries at a time: workgroup
// (tile, part) takes the tile's entries whose item-major slot lies in [chunk_begin, chunk_end)
// (a contiguous sub-run: a tile's slots increase along its run, since binning's stable sort
// keeps the item-major order), and of those the part-th `split` faces. Each invocation holds one
// face and sums its contribution over every pixel of the tile in row-major order, then writes
// the entry's partial at `slot - chunk_begin`. Splitting a crowded tile over several workgroups
// bounds every invocation's loop count (llvmpipe stops loops after 65 535 iterations) without
// changing any sum: each entry is still summed by one invocation in pixel order. Each partial
// has one writer and a fixed summation order: no atomics, bit-identical runs.
// `grad_reduce.comp` and `grad_reduce_texels.comp` then add each face's partials, in slot order,
// to its gradients. Twin: `reference_grad::backward_view` (per tile instead of per image).
//
// Each subgroup works alone (no shared memory, no barrier; see `raster_tiled.comp`): it takes
// as many faces as it has lanes (one per lane, whose lane keeps its sums), then walks the tile's
// pixels as many at a time (a segment: a `segment_shape` block, 4 × 2 for 8 lanes, blocks
// row-major), each lane loading one pixel's upstream. A ballot keeps the faces whose box
// touches the segment's pixels with a non-zero upstream (any other face adds nothing there),
// and the loop over its bits broadcasts each kept face with shuffles: every lane takes its
// pixel's contribution, `lane_sum` adds them up, and the face's own lane adds the sum to its
// running total. So a face's partial is summed segment by segment in segment order, each
// segment by the subgroup's reduction (a fixed order on a given device: runs are
// bit-identical; against brute force it differs by float reassociation). A texel slot gets,
// segment by segment, the sum in lane order of the segment's pixels on that texel, added by the
// lowest of them (same order on every run).
// 64 invocations (a multiple of any subgroup size up to 64), or one subgroup on a CPU device:
// `tiled_backward_workgroup` (src/raster/fine.rs) says why. Nothing here depends on how many
// subgroups a workgroup has: its faces go to them round robin.
#define FINE_BACKWARD
// The per-lane inputs as texel buffers: branch-free gathers on llvmpipe (raster_fine.glsl).
#define TEXEL_INPUTS
#include "common.glsl"
#include "raster_grad.glsl"
#include "subgroup_face.glsl"

layout(local_size_x = 64, local_size_x_id = 5) in;

// This chunk's partials: `grad_stride` floats per entry, as vec4 records (`PARTIAL_COLORS` in
// raster_grad.glsl). The texel slots arrive zeroed (the host fills them) and are summed into
// here; with `TEXEL_MASKS` they arrive unwritten, and the mask says which were written.
layout(std430, set = 0, binding = 6) buffer Partials { vec4 partials[]; };
layout(std430, set = 0, binding = 7) readonly buffer Pairs { uint pairs[]; };
layout(std430, set = 0, binding = 8) readonly buffer PairItems { uint pair_items[]; };
layout(std430, set = 0, binding = 9) readonly buffer Ranges { uvec2 ranges[]; };

// The first position of the sorted run [lo, hi) whose slot is at least `s` (at most
// bit_length(hi - lo) iterations). A run that lies wholly at or past `s`, or wholly before it
// (a tile inside one chunk: the common case), takes one load and no search: on llvmpipe each
// load here is a scalar loop over the lanes with a bounds check per lane.
uint first_slot_from(uint lo, uint hi, uint s) {
    if (lo < hi && pairs[lo] >= s) {
        hi = lo;
    } else if (lo < hi && pairs[hi - 1u] < s) {
        lo = hi;
    }
    while (lo < hi) {
        uint mid = lo + (hi - lo) / 2u;
        if (pairs[mid] < s) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

void main() {
    uint tiles_per_view = pc.tiles_x * pc.tiles_y;
    uint group = linear_group_id();
    uint tile = group / pc.parts;
    uint part = group - tile * pc.parts;
    uint view = tile / tiles_per_view;
    if (view >= pc.view_count) {
        return; // uniform across the workgroup
    }
    uint in_view = tile - view * tiles_per_view;
    uint ty = in_view / pc.tiles_x;
    uint tx = in_view - ty * pc.tiles_x;
    uint gview = pc.first_view + view;
    uvec2 range = ranges[tile];
    uint lanes = subgroup_lanes();
    // A subgroup whose first face would lie past the tile's run, in any chunk, has nothing to
    // do: it leaves before the searches (uniform across the subgroup, and no barrier follows).
    // On llvmpipe a workgroup's subgroups run one after another, each paying its way to here;
    // most tiles have fewer faces than the workgroup has invocations.
    if (range.x + part * pc.split + gl_SubgroupID * lanes >= range.y) {
        return;
    }
    uint lo = first_slot_from(range.x, range.y, pc.chunk_begin);
    uint hi = first_slot_from(lo, range.y, pc.chunk_end);
    if (hi - lo <= part * pc.split) {
        return; // uniform: this part of the tile holds no entry of the chunk
    }
    uint first = lo + part * pc.split;
    uint last = first + min(pc.split, hi - first);
    uint pixels = pc.tile_size * pc.tile_size;

    uint lane = gl_SubgroupInvocationID;
    float inf = uintBitsToFloat(0x7f800000u);
    // The workgroup's faces go to its subgroups `lanes` at a time, round robin.
    for (uint start = first + gl_SubgroupID * lanes; start < last;
         start += gl_NumSubgroups * lanes) {
        uint k = start + lane;
        bool has = k < last && lane < lanes;
        uint slot = 0u;
        uint face = 0u;
        Face f = face_none();
        if (has) {
            slot = pairs[k];
            face = pair_items[slot];
            f = load_face(gview * pc.face_count + face);
        }
        uint o = (slot - pc.chunk_begin) * (pc.grad_stride / 4u);
        vec3 acc[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
        vec3 cacc[3] = vec3[3](vec3(0.0), vec3(0.0), vec3(0.0));
        uint written = 0u; // TEXEL_MASKS: the texel slots of this lane's partial written so far
        for (uint base = 0u; base < pixels; base += lanes) {
            uint i = base + lane;
            uvec2 at = segment_pixel(i, pc.tile_size, lanes);
            uint col = tx * pc.tile_size + at.x;
            uint row = (pc.first_row + ty) * pc.tile_size + at.y;
            bool live = i < pixels && lane < lanes && col < pc.width && row < pc.height;
            Upstream u = live ? load_upstream(gview, col, row) : zero_upstream();
            live = live && !upstream_is_zero(u);
            vec2 lo = lane_min(live ? u.p : vec2(inf));
            vec2 hi = lane_max(live ? u.p : vec2(-inf));
            bool touches = (f.flags & FACE_FINITE) != 0u
                        && !(hi.x < f.bbox.x || hi.y < f.bbox.y || lo.x > f.bbox.z
                             || lo.y > f.bbox.w);
            uvec4 kept = subgroupBallot(touches);
            for (uint word = 0u; word < ballot_words(); ++word) {
                uint mask = kept[word];
                while (mask != 0u) {
                    uint q = 32u * word + uint(findLSB(mask));
                    mask &= mask - 1u;
                    uint fq = subgroupShuffle(face, q);
                    FaceGrad g;
                    bool hit = live && pixel_face_grad(face_shuffle(f, q), fq, u, g);
                    bool mine = lane == q;
                    for (uint c = 0u; c < 3u; ++c) {
                        // With an alpha-only upstream no depth has a gradient: z stays +0.
                        if (ALPHA_ONLY) {
                            vec2 sum = lane_sum(hit ? g.screen[c].xy : vec2(0.0));
                            acc[c].xy += mine ? sum : vec2(0.0);
                        } else {
                            vec3 sum = lane_sum(hit ? g.screen[c] : vec3(0.0));
                            acc[c] += mine ? sum : vec3(0.0);
                        }
                    }
                    if (ALPHA_ONLY) {
                        continue;
                    }
                    bool colored = hit && g.colored;
                    if (VERTEX_COLORS) {
                        for (uint c = 0u; c < 3u; ++c) {
                            vec3 sum = lane_sum(colored ? g.color[c] : vec3(0.0));
                            cacc[c] += mine ? sum : vec3(0.0);
                        }
                    } else {
                        // Texel slots: the segment's pixels that share a texel of face q are
                        // summed in pixel order (one shuffle step per lane: texels are finer
                        // than pixels, so most pixels have a texel of their own), and the
                        // lowest of them adds the sum to the slot: one read-modify-write per
                        // face and segment, each lane on its own texel, rather than one per
                        // pixel (on llvmpipe each is a scalar loop over the lanes).
                        uint texel = colored ? g.texel : 0xFFFFFFFFu;
                        vec3 sum = vec3(0.0);
                        bool leader = colored;
                        for (uint k = 0u; k < lanes; ++k) {
                            bool same = subgroupShuffle(texel, k) == texel;
                            vec3 value = subgroupShuffle(g.color[0], k);
                            sum += same ? value : vec3(0.0);
                            leader = leader && !(same && k < lane);
                        }
                        uint oq = subgroupShuffle(o, q);
                        if (TEXEL_MASKS) {
                            // A slot face q's partial has not written yet is written, not
                            // read (the read was a cache miss); then face q's lane notes the
                            // slots its leaders wrote.
                            uint seen = subgroupShuffle(written, q);
                            uint bit = leader ? 1u << texel : 0u;
                            if (leader) {
                                vec4 old = vec4(0.0);
                                if ((seen & bit) != 0u) {
                                    old = partials[oq + PARTIAL_COLORS + texel];
                                }
                                partials[oq + PARTIAL_COLORS + texel] = old + vec4(sum, 0.0);
                            }
                            uint bits = lane_or(bit);
                            written |= mine ? bits : 0u;
                        } else if (leader) {
                            partials[oq + PARTIAL_COLORS + texel] += vec4(sum, 0.0);
                        }
                    }
                }
            }
        }
        if (has) {
            for (uint c = 0u; c < 3u; ++c) {
                float w = TEXEL_MASKS && c == TEXEL_MASK_SLOT ? uintBitsToFloat(written) : 0.0;
                partials[o + c] = vec4(acc[c], w);
                if (VERTEX_COLORS) {
                    partials[o + PARTIAL_COLORS + c] = vec4(cacc[c], 0.0);
                }
            }
        }
    }
}
