// The per-pixel fine pass shared by `raster_brute.comp` and `raster_tiled.comp` (and, for its
// bindings and push constants, by the backward kernels, which define FINE_BACKWARD: they read
// the image and aux): bindings 0–4, the push constants, and the step that folds one face into a
// pixel's running state. Both kernels
// call `shade_face` for the same faces in the same (index) order, so their pixels are bit for bit
// the same; they differ only in which faces they visit (all, or their tile's). Twin:
// `reference::shade_pixel`, step for step.
#ifndef SOFTVK_RASTER_FINE_GLSL
#define SOFTVK_RASTER_FINE_GLSL

#include "raster.glsl"

// Twin of `PixelAux` (src/raster/fine.rs): what the backward pass needs of the forward's
// running aggregates, so that it needs no second forward. 32 bytes per pixel.
struct PixelAux {
    float softmax_ref_depth; // depth whose z̄ is the softmax's running max (background: far - ε (far - near))
    float softmax_sum;       // softmax denominator, scaled by e^{-max/γ} (includes the background's term)
    float alpha_acc;         // prod: Π(1 - D) over non-zero factors; sum: Σ D; hard: 0 or 1
    uint alpha_zeros;        // prod: how many factors 1 - D were exactly 0
    uint hard_face;          // hard colour: the winning face, or 0xffffffff for the background
    uint pad0;
    uint pad1;
    uint pad2;
};

#ifdef TEXEL_INPUTS
// The face setups and colours as uniform texel buffers of uvec4 texels (the same bytes; the host
// binds the same ranges either way): eight texels per `FaceSetup`, one per colour. The tiled
// kernels read both per lane inside their loops, where on llvmpipe a storage-buffer load is a
// scalar loop over the lanes with a bounds-check branch per component (nine such loops per face
// record), while a texel fetch is one branch-free gather of whole texels whose cache misses
// overlap. Bits are reinterpreted, never converted.
layout(set = 0, binding = 0, rgba32ui) uniform readonly restrict uimageBuffer setups;
layout(set = 0, binding = 1, rgba32ui) uniform readonly restrict uimageBuffer colors;

// `face_of(setups[index])`, fetched as texels.
Face load_face(uint index) {
    int t = int(index * 8u);
    Face f;
    for (int k = 0; k < 3; ++k) {
        vec4 v = uintBitsToFloat(imageLoad(setups, t + k));
        vec4 inv = uintBitsToFloat(imageLoad(setups, t + 3 + k));
        f.v[k] = v.xyz;
        f.inv_z[k] = v.w;
        f.inv[k] = inv.xy;
        f.inv_len2[k] = inv.w;
    }
    f.bbox = uintBitsToFloat(imageLoad(setups, t + 6));
    uvec4 last = imageLoad(setups, t + 7);
    f.flags = last.x;
    f.mesh = last.y;
    f.det = uintBitsToFloat(last.z);
    f.inv_det = uintBitsToFloat(last.w);
    return f;
}

// Colour `i` (RGB).
vec3 color_at(uint i) {
    return uintBitsToFloat(imageLoad(colors, int(i)).rgb);
}
#else
layout(std430, set = 0, binding = 0) readonly buffer Setups { FaceSetup setups[]; };
// RGB and an unused fourth float per colour: one vec4 load is one scalar loop over the lanes on
// llvmpipe, where three float loads are three.
layout(std430, set = 0, binding = 1) readonly buffer Colors { vec4 colors[]; };

// The face record of setup `index`.
Face load_face(uint index) {
    return face_of(setups[index]);
}

// Colour `i` (RGB).
vec3 color_at(uint i) {
    return colors[i].rgb;
}
#endif
layout(std430, set = 0, binding = 2) readonly buffer Faces { uint faces[]; };
#if defined(FINE_BACKWARD) && defined(TEXEL_INPUTS)
// The forward's image and aux as texels (one per pixel, two per `PixelAux`): the backward reads
// them per lane inside its loops (see `setups`).
layout(set = 0, binding = 3, rgba32ui) uniform readonly restrict uimageBuffer image;
layout(set = 0, binding = 4, rgba32ui) uniform readonly restrict uimageBuffer aux;

vec4 image_at(uint id) {
    return uintBitsToFloat(imageLoad(image, int(id)));
}

PixelAux aux_at(uint id) {
    uvec4 a = imageLoad(aux, int(2u * id));
    uvec4 b = imageLoad(aux, int(2u * id + 1u));
    PixelAux p;
    p.softmax_ref_depth = uintBitsToFloat(a.x);
    p.softmax_sum = uintBitsToFloat(a.y);
    p.alpha_acc = uintBitsToFloat(a.z);
    p.alpha_zeros = a.w;
    p.hard_face = b.x;
    p.pad0 = b.y;
    p.pad1 = b.z;
    p.pad2 = b.w;
    return p;
}
#elif defined(FINE_BACKWARD)
layout(std430, set = 0, binding = 3) readonly buffer Image { vec4 image[]; };
layout(std430, set = 0, binding = 4) readonly buffer Aux { PixelAux aux[]; };

vec4 image_at(uint id) {
    return image[id];
}

PixelAux aux_at(uint id) {
    return aux[id];
}
#else
layout(std430, set = 0, binding = 3) writeonly buffer Image { vec4 image[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Aux { PixelAux aux[]; };
#endif

#define FLAG_DOUBLE_SIDED 1u
#define FLAG_VERTEX_COLORS 2u
#define FLAG_CULL 4u
#define FLAG_ANTIALIAS 8u
#define FLAG_ALPHA_ONLY 16u
#define FLAG_TEXEL_MASKS 32u

// The modes, as specialization constants (twin: `FineModes`, src/raster/fine.rs): the host builds
// one pipeline per combination it renders with. On llvmpipe a branch never skips work (it only
// narrows the lane mask), so a mode read from push constants would run every mode's code.
layout(constant_id = 0) const uint MODE_DIST = DIST_EUCLIDEAN;
layout(constant_id = 1) const uint MODE_RGB = RGB_SOFTMAX;
layout(constant_id = 2) const uint MODE_ALPHA = ALPHA_PROD;
layout(constant_id = 3) const uint MODE_FLAGS = 0u; // FLAG_*
const bool DOUBLE_SIDED = (MODE_FLAGS & FLAG_DOUBLE_SIDED) != 0u;
const bool VERTEX_COLORS = (MODE_FLAGS & FLAG_VERTEX_COLORS) != 0u;
const bool CULL = (MODE_FLAGS & FLAG_CULL) != 0u;
const bool ANTIALIAS = (MODE_FLAGS & FLAG_ANTIALIAS) != 0u;
// Alpha only. Forward: a silhouette render (RGB stays the background, the aux's colour fields
// their initial values; alpha and its aux fields are the same bits). Backward: the upstream
// gradient has no RGB part (a silhouette loss), so the colour terms, which would add exact
// zeros, are left out: the same gradients, bit for bit.
const bool ALPHA_ONLY = (MODE_FLAGS & FLAG_ALPHA_ONLY) != 0u;
// Backward, surface colours with at most 32 texels a face: each partial's texel slots arrive
// unwritten, and the partial says which it wrote (`TEXEL_MASK_SLOT`), instead of every slot
// arriving zeroed by a fill of the whole chunk (see `raster_grad.glsl`).
const bool TEXEL_MASKS = (MODE_FLAGS & FLAG_TEXEL_MASKS) != 0u;

// Twin of `RasterPush` (src/raster/fine.rs).
layout(push_constant) uniform Push {
    uint width;            // rendered size (2× the output with anti-aliasing)
    uint height;
    uint face_count;
    uint view_count;       // views in this dispatch
    float inv_sigma;       // 1 / σ (the host's, rounded once)
    float cutoff;          // T = σ ln(1/ε_d − 1)
    float near;
    float far;
    float inv_gamma_range; // 1 / (γ (far − near))
    float background_depth; // far − ε (far − near): the background's softmax depth
    uint texture_res;      // R (surface colours)
    uint first_view;       // view of this dispatch's first view in setups, image and aux
    vec4 background;       // C_b (w unused)
    uint tile_size;        // tiled only: tile edge in pixels (a multiple of 8)
    uint tiles_x;          // tiled only: tiles per row, per column
    uint tiles_y;
    uint vertex_count;     // vertices per mesh of the batch (vertex colours)
    uint out_width;        // backward: output size (the upstream gradient's; half with AA)
    uint out_height;
    uint entry_total;      // backward, tiled: (face, tile) entries of the view group
    uint grad_stride;      // backward: floats per partial (vec4 records: 3 corners + colour slots)
    uint first_row;        // tiled only: the window's first tile row (tiles_y rows from it)
#ifndef FINE_BACKWARD
    uint pass_begin;       // forward with CARRY: this pass's faces, [pass_begin, pass_end) of a
    uint pass_end;         //   pixel's list (brute: of the view's faces; tiled: of the tile's run)
#else
    uint chunk_begin;      // backward: the first unit (tiled: entry slot; brute: (item, band))
    uint chunk_end;        //   of this chunk of partials, and one past its last
    uint split;            // backward, tiled: faces of a tile per workgroup; brute: rows per band
    uint parts;            // backward, tiled: workgroups per tile; brute: bands per view
#endif
} pc;

// `FaceColors::sample`: C_j at clipped barycentrics w̃, from the colours of mesh `mesh` of the
// batch (`vertex_count` colours per mesh in vertex mode, `face_count` R² texels in surface mode).
vec3 sample_color(uint mesh, uint face, vec3 wc) {
    if (VERTEX_COLORS) {
        uvec3 f = uvec3(faces[3u * face], faces[3u * face + 1u], faces[3u * face + 2u])
                + mesh * pc.vertex_count;
        vec3 c0 = color_at(f.x);
        vec3 c1 = color_at(f.y);
        vec3 c2 = color_at(f.z);
        return wc.x * c0 + wc.y * c1 + wc.z * c2;
    }
    uint r2 = pc.texture_res * pc.texture_res;
    uint t = (mesh * pc.face_count + face) * r2 + surface_texel_index(wc, pc.texture_res);
    return color_at(t);
}

// One pixel's running state over the faces it has seen.
struct PixelState {
    Alpha alpha;
    Softmax soft;
    bool hard_found;
    float hard_depth;
    vec3 hard_wc;   // the winning face's clipped barycentrics and mesh: its colour is sampled
    uint hard_mesh; // once, by `pixel_finish`, not for every face that covers the pixel
    uint hard_face;
};

PixelState pixel_init() {
    PixelState s;
    s.alpha = alpha_init(MODE_ALPHA);
    s.soft = softmax_init(pc.background.rgb, pc.background_depth);
    s.hard_found = false;
    s.hard_depth = 0.0;
    s.hard_wc = vec3(0.0);
    s.hard_mesh = 0u;
    s.hard_face = 0xffffffffu;
    return s;
}

// Folds face j (set up as `f`) into the state of the pixel centred at `p`.
// By selects rather than branches (on llvmpipe a branch skips nothing and costs masked stores):
// what it computes for an ignored face is discarded, and the state gets the bits the branching
// version would give. The colour gather stays in bounds whatever the numbers (texel indices are
// clamped).
void shade_face(inout PixelState s, Face f, uint j, vec2 p) {
    bool live = (f.flags & FACE_FINITE) != 0u && !(CULL && outside_bbox(f.bbox, p));
    vec3 w = barycentric(f, p);
    float d;
    bool covered = coverage(f, w, p, MODE_DIST, pc.inv_sigma, pc.cutoff, d);
    covered = covered && live;
    // Alpha counts every non-ignored face, whatever its depth or facing.
    alpha_add_if(s.alpha, MODE_ALPHA, d, covered);
    if (ALPHA_ONLY) {
        return; // a silhouette render: no depth, no colour
    }

    vec3 wc = clip_barycentric(w);
    float z;
    bool shaded = covered && depth_in_range(f, wc, pc.near, pc.far, z)
               && (DOUBLE_SIDED || (f.flags & FACE_FRONT) != 0u);
    if (MODE_RGB == RGB_SOFTMAX) {
        vec3 color = sample_color(f.mesh, j, wc);
        softmax_add_if(s.soft, z, d, color, pc.inv_gamma_range, shaded);
    } else {
        bool wins = shaded && inside_closed(w) && (!s.hard_found || z < s.hard_depth);
        s.hard_found = s.hard_found || wins;
        s.hard_depth = wins ? z : s.hard_depth;
        s.hard_wc = wins ? wc : s.hard_wc;
        s.hard_mesh = wins ? f.mesh : s.hard_mesh;
        s.hard_face = wins ? j : s.hard_face;
    }
}

#ifndef FINE_BACKWARD
// A face list too long for one invocation (llvmpipe ends an invocation's loops after 65 535
// iterations) is folded in passes over consecutive parts of it, in order: each pass but the
// last leaves every pixel's running state in `carry`, and the next resumes from it (constant 6,
// the host's choice when a list needs more than one pass). A pixel folds the same faces in the
// same order either way, so a split render is the unsplit one bit for bit. Without CARRY the
// binding is a placeholder and no code touches it. The includer defines CARRY_BINDING.
layout(constant_id = 6) const uint CARRY = 0u;

// `PixelState`, 64 bytes: alpha and softmax, then the hard colour's winner.
struct PixelCarry {
    vec4 a; // alpha.acc, alpha.zeros (bits), soft.ref_depth, soft.sum
    vec4 b; // soft.rgb, hard_depth
    vec4 c; // hard_wc, hard_face (bits; 0xffffffff: none yet)
    uvec4 d; // hard_mesh, unused
};
layout(std430, set = 0, binding = CARRY_BINDING) restrict buffer Carry { PixelCarry carry[]; };

void carry_store(PixelState s, uint id) {
    PixelCarry c;
    c.a = vec4(s.alpha.acc, uintBitsToFloat(s.alpha.zeros), s.soft.ref_depth, s.soft.sum);
    c.b = vec4(s.soft.rgb, s.hard_depth);
    c.c = vec4(s.hard_wc, uintBitsToFloat(s.hard_face));
    c.d = uvec4(s.hard_mesh, 0u, 0u, 0u);
    carry[id] = c;
}

PixelState carry_load(uint id) {
    PixelCarry c = carry[id];
    PixelState s;
    s.alpha.acc = c.a.x;
    s.alpha.zeros = floatBitsToUint(c.a.y);
    s.soft.ref_depth = c.a.z;
    s.soft.sum = c.a.w;
    s.soft.rgb = c.b.xyz;
    s.hard_depth = c.b.w;
    s.hard_wc = c.c.xyz;
    s.hard_face = floatBitsToUint(c.c.w);
    s.hard_found = s.hard_face != 0xffffffffu; // a winner's index is a face's, never ~0
    s.hard_mesh = c.d.x;
    return s;
}

// Writes the pixel's colour and aux at index `id` of the image.
void pixel_finish(PixelState s, uint id) {
    vec3 rgb;
    if (MODE_RGB == RGB_SOFTMAX) {
        rgb = softmax_resolve(s.soft);
    } else {
        // The winner's colour: the bits `shade_face` would have kept had it sampled every face
        // it saw. Sampled unconditionally (a select, as in `shade_face`), at face 0 where none
        // won, so the gather stays in bounds.
        vec3 winner = sample_color(s.hard_mesh, s.hard_found ? s.hard_face : 0u, s.hard_wc);
        rgb = s.hard_found ? winner : pc.background.rgb;
    }
    image[id] = vec4(rgb, alpha_resolve(s.alpha, MODE_ALPHA, pc.face_count));
    PixelAux a;
    a.softmax_ref_depth = s.soft.ref_depth;
    a.softmax_sum = s.soft.sum;
    a.alpha_acc = s.alpha.acc;
    a.alpha_zeros = s.alpha.zeros;
    a.hard_face = s.hard_face;
    a.pad0 = 0u;
    a.pad1 = 0u;
    a.pad2 = 0u;
    aux[id] = a;
}
#endif

#endif
