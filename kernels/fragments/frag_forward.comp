#version 460
#extension GL_GOOGLE_include_directive : require
// PyTorch3D's rasterizer, step 3 (after setup and binning): the K nearest faces of every pixel.
// One workgroup per 8×8 block of pixels, one invocation per pixel, visiting the faces binned to
// the block's tile in index order (binning keeps every face whose grown box can hold a pixel
// centre of the tile; the box test below is PyTorch3D's own, per pixel). The pixel's list lives
// in the output buffers, sorted by (z, face index), so a crowded tile's run is visited in
// passes over consecutive parts of it ([pass_begin, pass_end): the driver's loop cap), each
// pass resuming the list the last one left.
//
// Order: PyTorch3D's CPU rasterizer keeps a deque sorted by the tuple (z, f, ...) and drops its
// last element past K, so equal depths go to the lower face index; so does this, and the list
// does not depend on the order faces are visited in. A face cut in two by PyTorch3D's
// near-plane clipping (`neighbors[f]`, the other half, or -1) replaces its other half in the
// list when it is nearer to the pixel (squared edge distance) and is not added beside it, as
// PyTorch3D does; this one depends on the visiting order, index order in both.
//
// Loop iterations per invocation: K to start, per face of the pass at most 2K + 1 (finding the
// other half, moving an entry): what the host's pass size bounds (`forward_pass_faces`).
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
// [views, H, W, K]: the packed face index as an int64 (low word, high word), -1 where empty.
layout(std430, set = 0, binding = 6) buffer PixToFace { int pix_to_face[]; };
layout(std430, set = 0, binding = 7) buffer Zbuf { float zbuf[]; };
layout(std430, set = 0, binding = 8) buffer Dists { float dists[]; };
// [views, H, W, K, 3].
layout(std430, set = 0, binding = 9) buffer Bary { float bary[]; };

#include "fragments.glsl"

int face_at(uint slot) {
    return pix_to_face[2u * slot];
}

void write_slot(uint slot, int face, float z, float dist, vec3 b) {
    pix_to_face[2u * slot] = face;
    pix_to_face[2u * slot + 1u] = face < 0 ? -1 : 0;
    zbuf[slot] = z;
    dists[slot] = dist;
    bary[3u * slot] = b.x;
    bary[3u * slot + 1u] = b.y;
    bary[3u * slot + 2u] = b.z;
}

void copy_slot(uint to, uint from) {
    write_slot(to, face_at(from), zbuf[from], dists[from],
               vec3(bary[3u * from], bary[3u * from + 1u], bary[3u * from + 2u]));
}

// (z, f) before the entry in `slot`.
bool before(float z, int f, uint slot) {
    float zs = zbuf[slot];
    return z < zs || (z == zs && f < face_at(slot));
}

void main() {
    uint blocks_x = (pc.width + 7u) / 8u;
    uint blocks_y = (pc.height + 7u) / 8u;
    uint blocks_per_view = blocks_x * blocks_y;
    uint block = linear_group_id();
    uint view = block / blocks_per_view;
    if (view >= pc.views) {
        return; // surplus workgroup of a folded grid
    }
    uint in_view = block - view * blocks_per_view;
    uint by = in_view / blocks_x;
    uint bx = in_view - by * blocks_x;
    uint col = bx * 8u + (gl_LocalInvocationIndex & 7u);
    uint row = by * 8u + (gl_LocalInvocationIndex >> 3u);
    if (col >= pc.width || row >= pc.height) {
        return;
    }
    uint blocks_per_tile = pc.tile_size / 8u;
    uint tile = view * pc.tiles_x * pc.tiles_y + (by / blocks_per_tile) * pc.tiles_x
              + bx / blocks_per_tile;
    uvec2 range = ranges[tile];
    uint run = range.y - range.x;
    if (pc.pass_begin > 0u && pc.pass_begin >= run) {
        return; // the tile's run ended in an earlier pass
    }
    uint base = ((view * pc.height + row) * pc.width + col) * pc.k;
    uint filled = 0u;
    if (pc.pass_begin == 0u) {
        for (uint i = 0u; i < pc.k; ++i) {
            write_slot(base + i, -1, -1.0, -1.0, vec3(-1.0));
        }
    } else {
        while (filled < pc.k && face_at(base + filled) >= 0) {
            ++filled;
        }
    }
    uint first_face = meshes[view].x;
    vec2 p = frag_pixel(row, col);
    uint end = min(pc.pass_end, run);
    for (uint e = range.x + pc.pass_begin; e < range.x + end; ++e) {
        uint face = first_face + pair_items[pairs[e]];
        vec3 q0;
        vec3 q1;
        vec3 q2;
        load_face_verts(face, q0, q1, q2);
        // `CheckPointOutsideBoundingBox` (the face-wide tests were setup's).
        precise float x_min = min(q0.x, min(q1.x, q2.x)) - pc.grow;
        precise float y_min = min(q0.y, min(q1.y, q2.y)) - pc.grow;
        precise float x_max = max(q0.x, max(q1.x, q2.x)) + pc.grow;
        precise float y_max = max(q0.y, max(q1.y, q2.y)) + pc.grow;
        if (p.x > x_max || p.x < x_min || p.y > y_max || p.y < y_min) {
            continue;
        }
        vec3 w0;
        vec3 w;
        vec3 w_clip;
        frag_barycentrics(p, q0, q1, q2, w0, w, w_clip);
        precise float pz = w_clip.x * q0.z + w_clip.y * q1.z + w_clip.z * q2.z;
        if (pz < 0.0) {
            continue;
        }
        vec3 ed = edge_dists(p, q0.xy, q1.xy, q2.xy);
        float dist = min(min(ed.x, ed.y), ed.z);
        bool inside = w.x > 0.0 && w.y > 0.0 && w.z > 0.0;
        if (!inside && dist >= pc.blur_radius) {
            continue;
        }
        float signed_dist = inside ? -dist : dist;
        int f = int(face);

        // The other half of a clipped face, if it is in the list: replaced when this half is
        // nearer to the pixel, and either way this half is not added.
        int other = neighbors[face];
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
            if (!(dist < abs(dists[base + at]))) {
                continue;
            }
            // Move the entry to where (pz, f) sorts, then write it there.
            uint i = at;
            while (i > 0u && before(pz, f, base + i - 1u)) {
                copy_slot(base + i, base + i - 1u);
                --i;
            }
            while (i + 1u < filled && !before(pz, f, base + i + 1u)) {
                copy_slot(base + i, base + i + 1u);
                ++i;
            }
            write_slot(base + i, f, pz, signed_dist, w_clip);
            continue;
        }
        // A plain insertion; when the list is full, its last entry drops out (or this face,
        // if it sorts after it).
        uint i = filled;
        if (filled == pc.k) {
            if (!before(pz, f, base + pc.k - 1u)) {
                continue;
            }
            i = pc.k - 1u;
        } else {
            ++filled;
        }
        while (i > 0u && before(pz, f, base + i - 1u)) {
            copy_slot(base + i, base + i - 1u);
            --i;
        }
        write_slot(base + i, f, pz, signed_dist, w_clip);
    }
}
