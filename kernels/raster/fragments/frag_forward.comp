#version 460
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
#extension GL_KHR_shader_subgroup_arithmetic : require
// PyTorch3D's rasterizer, step 3 (after setup and binning): the K nearest faces of every pixel,
// as a list of (face, z) per pixel in `pix_to_face`'s two words; `frag_finish.comp` then writes
// the outputs from it.
// One workgroup per 8×8 block of pixels, one invocation per pixel, visiting the faces binned to
// the block's tile in index order (binning keeps every face whose grown box can hold a pixel
// centre of the tile; the box test below is PyTorch3D's own, per pixel). As the soft
// rasterizer's `raster_tiled.comp` does, each subgroup works alone: per batch of as many binned
// faces as it has lanes, each lane loads one face, a ballot keeps the faces whose grown box
// holds a pixel centre of the subgroup's pixels, and the loop over the ballot's bits, lowest
// first (index order), broadcasts each kept face with shuffles to every lane's pixel. (On
// llvmpipe a load in the loop is a scalar loop over the lanes, a shuffle one permute, and an
// empty ballot the only thing that skips work.) The pixel's list lives in `lists`, sorted by
// (z, face index), so a crowded tile's run is visited in passes over consecutive parts of it
// ([pass_begin, pass_end): the driver's loop cap), each pass resuming the list the last one
// left.
//
// Order: PyTorch3D's CPU rasterizer keeps a deque sorted by the tuple (z, f, ...) and drops its
// last element past K, so equal depths go to the lower face index; so does this, and the list
// does not depend on the order faces are visited in. A face cut in two by PyTorch3D's
// near-plane clipping (`neighbors[f]`, the other half, or -1) replaces its other half in the
// list when it is nearer to the pixel (squared edge distance) and is not added beside it, as
// PyTorch3D does; this one depends on the visiting order, index order in both.
//
// Loop iterations per invocation: K to find the list's end (after the first pass), per batch
// of a pass one and one per ballot word, per face at most 2K + 1 (finding the other half,
// moving an entry): what the host's pass size bounds (`FragmentPlan::new`).
// Twin: `reference::rasterize`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer FaceVerts { float face_verts[]; };
layout(std430, set = 0, binding = 1) readonly buffer Meshes { uvec2 meshes[]; };
layout(std430, set = 0, binding = 2) readonly buffer Neighbors { int neighbors[]; };
// Bin entries sorted by tile: each holds its item-major slot.
layout(std430, set = 0, binding = 3) readonly buffer Pairs { uint pairs[]; };
// The item (face slot within its view) of every item-major slot.
layout(std430, set = 0, binding = 4) readonly buffer PairItems { uint pair_items[]; };
// [start, end) of every tile's run of sorted entries, view-major.
layout(std430, set = 0, binding = 5) readonly buffer Ranges { uvec2 ranges[]; };
// [views, H, W, K] pairs of words: the face (-1 where empty) and its depth's bits. All ones
// before the first pass (the host fills them); `frag_finish.comp` turns each pair into the
// int64 face index.
layout(std430, set = 0, binding = 6) buffer Lists { uvec2 lists[]; };

#include "fragments.glsl"
#include "subgroup_face.glsl"

// One entry is one 8-byte load or store (on llvmpipe each is a scalar access per lane: one,
// not two).
int face_at(uint slot) {
    return int(lists[slot].x);
}

void write_slot(uint slot, int face, float z) {
    lists[slot] = uvec2(uint(face), floatBitsToUint(z));
}

// (z, f) before the entry `e`.
bool before(float z, int f, uvec2 e) {
    float zs = uintBitsToFloat(e.y);
    return z < zs || (z == zs && f < int(e.x));
}

// Moves entries one slot towards the list's end, from slot `i` down, while (z, f) sorts before
// the one in front of them; returns the slot (z, f) belongs in. One load and one store a step.
uint shift_up(uint base, uint i, float z, int f) {
    while (i > 0u) {
        uvec2 prev = lists[base + i - 1u];
        if (!before(z, f, prev)) {
            break;
        }
        lists[base + i] = prev;
        --i;
    }
    return i;
}

// One face as a lane holds it: its vertices and its box grown by √blur_radius.
struct LaneFace {
    vec3 q0;
    vec3 q1;
    vec3 q2;
    vec4 box;  // x_min, y_min, x_max, y_max (PyTorch3D's NDC)
    uint face;
    int other; // the other half of a face cut in two, or -1
};

LaneFace lane_face_shuffle(LaneFace f, uint i) {
    LaneFace g;
    g.q0 = subgroupShuffle(f.q0, i);
    g.q1 = subgroupShuffle(f.q1, i);
    g.q2 = subgroupShuffle(f.q2, i);
    g.box = subgroupShuffle(f.box, i);
    g.face = subgroupShuffle(f.face, i);
    g.other = subgroupShuffle(f.other, i);
    return g;
}

// What the face gives the pixel p, added to the pixel's list of `filled` entries from `base`.
void visit(LaneFace lf, vec2 p, uint base, inout uint filled) {
    // `CheckPointOutsideBoundingBox` (the face-wide tests were setup's).
    if (p.x > lf.box.z || p.x < lf.box.x || p.y > lf.box.w || p.y < lf.box.y) {
        return;
    }
    vec3 q0 = lf.q0;
    vec3 q1 = lf.q1;
    vec3 q2 = lf.q2;
    vec3 w0;
    vec3 w;
    vec3 w_clip;
    frag_barycentrics(p, q0, q1, q2, w0, w, w_clip);
    precise float pz = w_clip.x * q0.z + w_clip.y * q1.z + w_clip.z * q2.z;
    if (pz < 0.0) {
        return;
    }
    vec3 ed = edge_dists(p, q0.xy, q1.xy, q2.xy);
    float dist = min(min(ed.x, ed.y), ed.z);
    bool inside = w.x > 0.0 && w.y > 0.0 && w.z > 0.0;
    if (!inside && dist >= pc.blur_radius) {
        return;
    }
    int f = int(lf.face);

    // The other half of a clipped face, if it is in the list: replaced when this half is nearer
    // to the pixel, and either way this half is not added.
    int other = lf.other;
    uint at = pc.k;
    if (other >= 0) {
        for (uint i = 0u; i < filled; ++i) {
            if (face_at(base + i) == other) {
                at = i;
                break;
            }
        }
    }
    if (at < pc.k) {
        // The other half's distance to the pixel, as the forward computed it.
        vec3 o0;
        vec3 o1;
        vec3 o2;
        load_face_verts(uint(other), o0, o1, o2);
        vec3 oe = edge_dists(p, o0.xy, o1.xy, o2.xy);
        if (!(dist < min(min(oe.x, oe.y), oe.z))) {
            return;
        }
        // Move the entry to where (pz, f) sorts, then write it there.
        uint i = shift_up(base, at, pz, f);
        while (i + 1u < filled) {
            uvec2 next = lists[base + i + 1u];
            if (before(pz, f, next)) {
                break;
            }
            lists[base + i] = next;
            ++i;
        }
        write_slot(base + i, f, pz);
        return;
    }
    // A plain insertion; when the list is full, its last entry drops out (or this face, if it
    // sorts after it).
    uint i = filled;
    if (filled == pc.k) {
        if (!before(pz, f, lists[base + pc.k - 1u])) {
            return;
        }
        i = pc.k - 1u;
    } else {
        ++filled;
    }
    write_slot(base + shift_up(base, i, pz, f), f, pz);
}

void main() {
    uint blocks_x = (pc.width + 7u) / 8u;
    uint blocks_y = (pc.height + 7u) / 8u;
    uint blocks_per_view = blocks_x * blocks_y;
    uint block = linear_group_id();
    uint view = block / blocks_per_view;
    if (view >= pc.views) {
        return; // surplus workgroup of a folded grid: uniform across the workgroup
    }
    uint in_view = block - view * blocks_per_view;
    uint by = in_view / blocks_x;
    uint bx = in_view - by * blocks_x;
    uint blocks_per_tile = pc.tile_size / 8u;
    uint tile = view * pc.tiles_x * pc.tiles_y + (by / blocks_per_tile) * pc.tiles_x
              + bx / blocks_per_tile;
    uvec2 range = ranges[tile];
    uint run = range.y - range.x;
    if (pc.pass_begin > 0u && pc.pass_begin >= run) {
        return; // the tile's run ended in an earlier pass: uniform across the workgroup
    }
    uint lanes = subgroup_lanes();
    uint lane = gl_SubgroupInvocationID;
    // This invocation's pixel: `segment_pixel` arranges each subgroup's pixels in a compact
    // block where the driver gives subgroups consecutive invocations.
    uvec2 at = segment_pixel(gl_LocalInvocationIndex, 8u, lanes);
    uint col = bx * 8u + at.x;
    uint row = by * 8u + at.y;
    bool valid = col < pc.width && row < pc.height;
    vec2 p = frag_pixel(min(row, pc.height - 1u), min(col, pc.width - 1u));
    // The box of the subgroup's pixel centres (lanes past the image's edge count as the edge).
    vec2 lo = lane_min(p);
    vec2 hi = lane_max(p);

    uint base = ((view * pc.height + row) * pc.width + col) * pc.k;
    // The host filled every slot with -1 before the first pass; a later pass finds where the
    // list ends.
    uint filled = 0u;
    if (pc.pass_begin > 0u && valid) {
        while (filled < pc.k && face_at(base + filled) >= 0) {
            ++filled;
        }
    }
    uint first_face = meshes[view].x;
    uint begin = range.x + pc.pass_begin;
    uint end = range.x + min(pc.pass_end, run);
    for (uint start = begin; start < end; start += lanes) {
        uint e = start + lane;
        LaneFace lf;
        lf.face = 0u;
        lf.other = -1;
        lf.q0 = vec3(0.0);
        lf.q1 = vec3(0.0);
        lf.q2 = vec3(0.0);
        lf.box = vec4(1.0, 1.0, -1.0, -1.0);
        bool touches = false;
        if (e < end && lane < lanes) {
            lf.face = first_face + pair_items[pairs[e]];
            lf.other = neighbors[lf.face];
            load_face_verts(lf.face, lf.q0, lf.q1, lf.q2);
            precise float x_min = min(lf.q0.x, min(lf.q1.x, lf.q2.x)) - pc.grow;
            precise float y_min = min(lf.q0.y, min(lf.q1.y, lf.q2.y)) - pc.grow;
            precise float x_max = max(lf.q0.x, max(lf.q1.x, lf.q2.x)) + pc.grow;
            precise float y_max = max(lf.q0.y, max(lf.q1.y, lf.q2.y)) + pc.grow;
            lf.box = vec4(x_min, y_min, x_max, y_max);
            touches = !(hi.x < x_min || hi.y < y_min || lo.x > x_max || lo.y > y_max);
        }
        uvec4 kept = subgroupBallot(touches);
        for (uint word = 0u; word < ballot_words(); ++word) {
            uint mask = kept[word];
            while (mask != 0u) {
                uint i = 32u * word + uint(findLSB(mask));
                mask &= mask - 1u;
                LaneFace g = lane_face_shuffle(lf, i);
                if (valid) {
                    visit(g, p, base, filled);
                }
            }
        }
    }
}
