// PyTorch3D's mesh rasterizer (`rasterize_meshes`), what its kernels share: the push constants,
// the pixel grid of its NDC and the per-(pixel, face) arithmetic of its CPU code
// (`csrc/rasterize_meshes/rasterize_meshes_cpu.cpp`, `csrc/utils/geometry_utils.h`), in f32,
// operation for operation, every intermediate `precise` (no fused multiply-add). Twin:
// `src/raster/fragments/reference.rs` (in f64).
#ifndef SOFTVK_FRAGMENTS_GLSL
#define SOFTVK_FRAGMENTS_GLSL

// Twin of `FragmentPush` (src/raster/fragments/gpu/mod.rs); every fragment kernel takes it.
layout(push_constant) uniform Push {
    uint width;           // image size in pixels
    uint height;
    uint k;               // faces kept per pixel
    uint flags;           // FRAG_*
    float blur_radius;    // squared NDC distance
    float grow;           // √blur_radius, rounded once on the host
    uint views;           // meshes of the batch (one view each)
    uint items_per_view;  // items per view: the largest mesh's face count
    uint tile_size;       // tile edge in pixels (a multiple of 8)
    uint tiles_x;
    uint tiles_y;
    uint pass_begin;      // forward: this pass's part [pass_begin, pass_end) of each tile's run
    uint pass_end;
    uint entries;         // backward: (face, tile) entries of the binning
    uint face_count;      // faces in `face_verts`
    uint pad0;
} pc;

const uint FRAG_PERSPECTIVE = 1u;  // perspective-correct barycentrics
const uint FRAG_CLIP = 2u;         // barycentrics clipped to [0, 1] and renormalized
const uint FRAG_CULL = 4u;         // faces of negative area skipped

// An item of the binning (one per (view, face slot)): its box in the binning's pixel-centre
// coordinates and whether it is binned at all. Twin: `ITEM_WORDS` in gpu.rs.
const uint ITEM_WORDS = 8u;
const uint ITEM_BINNED = 1u;

// A kernel that defines FRAGMENTS_PUSH_ONLY gets the push constants and constants alone (it
// binds no `face_verts`).
#ifndef FRAGMENTS_PUSH_ONLY

// PyTorch3D's kEpsilon.
const float P3D_EPS = 1e-8;

// `NonSquareNdcRange` and `PixToNonSquareNdc`: the NDC coordinate of pixel index i along a side
// of s1 pixels, the other side s2.
float pix_ndc(uint i, uint s1, uint s2) {
    precise float range = 2.0;
    if (s1 > s2) {
        range = fm_div_rn(float(s1) * 2.0, float(s2));
    }
    precise float offset = range * 0.5;
    precise float x = -offset + fm_div_rn(range * float(i) + offset, float(s1));
    return x;
}

// The NDC point that output pixel (row, col) samples: +X left, +Y up.
vec2 frag_pixel(uint row, uint col) {
    return vec2(pix_ndc(pc.width - 1u - col, pc.width, pc.height),
                pix_ndc(pc.height - 1u - row, pc.height, pc.width));
}

// `EdgeFunctionForward(p, v0, v1)`.
float edge_fn(vec2 p, vec2 v0, vec2 v1) {
    precise float e = (p.x - v0.x) * (v1.y - v0.y) - (p.y - v0.y) * (v1.x - v0.x);
    return e;
}

// The face's signed area as the rasterizer tests it: `EdgeFunctionForward(v0, v1, v2)`.
float face_area(vec2 v0, vec2 v1, vec2 v2) {
    return edge_fn(v0, v1, v2);
}

// `BarycentricCoordinatesForward`.
vec3 bary_forward(vec2 p, vec2 v0, vec2 v1, vec2 v2) {
    precise float area = edge_fn(v2, v0, v1) + P3D_EPS;
    precise float w0 = fm_div_rn(edge_fn(p, v1, v2), area);
    precise float w1 = fm_div_rn(edge_fn(p, v2, v0), area);
    precise float w2 = fm_div_rn(edge_fn(p, v0, v1), area);
    return vec3(w0, w1, w2);
}

// `BarycentricPerspectiveCorrectionForward`.
vec3 perspective_forward(vec3 b, vec3 z) {
    precise float t0 = b.x * z.y * z.z;
    precise float t1 = b.y * z.x * z.z;
    precise float t2 = b.z * z.x * z.y;
    precise float denom = max(t0 + t1 + t2, P3D_EPS);
    precise vec3 w = vec3(fm_div_rn(t0, denom), fm_div_rn(t1, denom), fm_div_rn(t2, denom));
    return w;
}

// `BarycentricClipForward`.
vec3 clip_forward(vec3 b) {
    precise vec3 w = max(b, vec3(0.0));
    precise float sum = max(w.x + w.y + w.z, 1e-5);
    precise vec3 c = vec3(fm_div_rn(w.x, sum), fm_div_rn(w.y, sum), fm_div_rn(w.z, sum));
    return c;
}

// `PointLineDistanceForward`: the squared distance from p to the segment v0 v1.
float segment_dist2(vec2 p, vec2 v0, vec2 v1) {
    precise vec2 d = v1 - v0;
    precise float l2 = d.x * d.x + d.y * d.y;
    if (l2 <= P3D_EPS) {
        precise vec2 r = p - v1;
        precise float rr = r.x * r.x + r.y * r.y;
        return rr;
    }
    precise vec2 pv = p - v0;
    precise float t = fm_div_rn(d.x * pv.x + d.y * pv.y, l2);
    float tt = min(max(t, 0.0), 1.0);
    precise vec2 proj = v0 + tt * d;
    precise vec2 r = p - proj;
    precise float rr = r.x * r.x + r.y * r.y;
    return rr;
}

// The squared distances to the edges in PyTorch3D's order: 01, 02, 12.
vec3 edge_dists(vec2 p, vec2 v0, vec2 v1, vec2 v2) {
    return vec3(segment_dist2(p, v0, v1), segment_dist2(p, v0, v2), segment_dist2(p, v1, v2));
}

// The face's three vertices (x, y in NDC, z the view depth).
void load_face_verts(uint face, out vec3 q0, out vec3 q1, out vec3 q2) {
    uint o = 9u * face;
    q0 = vec3(face_verts[o], face_verts[o + 1u], face_verts[o + 2u]);
    q1 = vec3(face_verts[o + 3u], face_verts[o + 4u], face_verts[o + 5u]);
    q2 = vec3(face_verts[o + 6u], face_verts[o + 7u], face_verts[o + 8u]);
}

// The barycentrics of a face at p as the edge functions give them (`w0`), after the
// perspective correction if asked (`w`, what "inside" tests), and after the clip if asked
// (`w_clip`, what the depth and the outputs use).
void frag_barycentrics(vec2 p, vec3 q0, vec3 q1, vec3 q2, out vec3 w0, out vec3 w,
                       out vec3 w_clip) {
    w0 = bary_forward(p, q0.xy, q1.xy, q2.xy);
    w = (pc.flags & FRAG_PERSPECTIVE) != 0u
        ? perspective_forward(w0, vec3(q0.z, q1.z, q2.z)) : w0;
    w_clip = (pc.flags & FRAG_CLIP) != 0u ? clip_forward(w) : w;
}

#endif
#endif
