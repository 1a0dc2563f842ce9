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
// pixels as many at a time (a segment: `lanes` consecutive pixels of `morton_pixel`'s order, a
// `segment_shape` block; only the segments some of its faces' boxes meet), each lane loading
// one pixel's upstream. A ballot keeps the faces whose box touches the segment's pixels with a
// non-zero upstream (any other face adds nothing there), and the loop over its bits broadcasts
// each kept face with shuffles: every lane takes its pixel's contribution.
//
// The order of every sum is the pixels' and not the subgroup's, so that any subgroup size (4
// to 64 lanes) gives the same bits: a face's partial is the sum, one 2 × 2 quad after another
// in `morton_pixel`'s order, of each quad's `quad_sum`; the face's own lane adds the segment's
// quads to its running total one at a time. A texel slot gets its pixels' contributions one at
// a time in the same order, added to its value by the lowest lane of the segment on that texel.
// A lane or pixel with nothing to add adds -0.0 (`NEG_ZERO`), which changes no bit, so a
// segment or face skipped for having nothing to add gives what visiting it would. Against brute
// force the sums differ by float reassociation only.
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

// The tile size, when the host specializes it (constant 6; 0: `pc.tile_size`). As a constant,
// the segment loops' trip counts are known: the driver unrolls the loop over groups of 32
// segments (one group for tiles of 8 or 16 and 8 lanes), which as a loop cost spot-256's
// backward 4 % on llvmpipe, and divides by constants.
layout(constant_id = 6) const uint TILE_SIZE = 0u;

uint tile_size() {
    return TILE_SIZE != 0u ? TILE_SIZE : pc.tile_size;
}

// Constant 7, set only by softvk-raster's own unit tests (`GradKernels::counting_loops`):
// in place of each entry's partial the kernel writes what it counted, (the iterations its
// invocation had run by then of the loops whose trip counts depend on the input, the segments
// where the entry's face was kept, 0, 0) at the partial's first vec4, which the host's
// `loops::tiled_backward_iterations` must bound and `Binned::pair_counts` predict. At 0 the
// counts are dead code and the compiler drops them.
layout(constant_id = 7) const uint COUNT_LOOPS = 0u;
uint counted_iterations;
uint counted_kept;

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
        ++counted_iterations;
        uint mid = lo + (hi - lo) / 2u;
        if (pairs[mid] < s) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// Pixel centres along one axis, as `pixel_center` takes them: column c's x, row r's y.
float center_x(int c) {
    return pixel_center(uint(c), 0u, pc.width, pc.height).x;
}

float center_y(int r) {
    return pixel_center(0u, uint(r), pc.width, pc.height).y;
}

// The tile's pixel centres, taken once per tile instead of for every pixel of every segment a
// subgroup visits, and eight per face by `segment_rect` (each coordinate of a centre is a
// correctly rounded division, about 110 operations): lane k holds the x of the tile's column k
// and the y of its row k in `x0` and `y0`, those of column and row L + k in `x1` and `y1` (L
// lanes), and a lane finds any of them with one or two shuffles. Where the tile's side is at most 2 L and both
// sizes are known (the default tile of 8 from 4 lanes up); elsewhere every pixel takes its own,
// with the same function: the same bits.
struct TileCentres {
    float x0;
    float x1;
    float y0;
    float y1;
};

bool centre_table() {
    return TILE_SIZE != 0u && SUBGROUP_SIZE != 0u && TILE_SIZE <= 2u * subgroup_lanes();
}

TileCentres tile_centres(uint col0, uint row0) {
    uint lanes = subgroup_lanes();
    uint lane = gl_SubgroupInvocationID;
    TileCentres t;
    t.x0 = center_x(int(col0 + lane));
    t.y0 = center_y(int(row0 + lane));
    t.x1 = TILE_SIZE > lanes ? center_x(int(col0 + lanes + lane)) : 0.0;
    t.y1 = TILE_SIZE > lanes ? center_y(int(row0 + lanes + lane)) : 0.0;
    return t;
}

// Entry k (< the tile size) of a table's axis (`x0`, `x1` or `y0`, `y1`). Every lane must be
// active.
float centre_at(float s0, float s1, uint k) {
    uint lanes = subgroup_lanes();
    float a = subgroupShuffle(s0, k % lanes);
    if (TILE_SIZE <= lanes) {
        return a;
    }
    float b = subgroupShuffle(s1, k % lanes);
    return k < lanes ? a : b;
}

// `segment_rect` from the tile's centres: the same rect (centres grow with the column and fall
// with the row, so the columns in the box's x range are those past the ones left of it and up to
// the last at most its right, counted over the tile's columns inside the image; rows likewise).
uvec4 segment_rect_table(Face f, TileCentres t, uint col0, uint row0) {
    if ((f.flags & FACE_FINITE) == 0u) {
        return uvec4(1u, 0u, 0u, 0u);
    }
    uint left_of = 0u;  // tile columns whose centre is left of the box
    uint up_to = 0u;    // tile columns whose centre is at most its right
    uint above = 0u;    // tile rows whose centre is above the box
    uint down_to = 0u;  // tile rows whose centre is at least its bottom
    for (uint k = 0u; k < tile_size(); ++k) {
        float x = centre_at(t.x0, t.x1, k);
        float y = centre_at(t.y0, t.y1, k);
        bool column = col0 + k < pc.width;
        bool row = row0 + k < pc.height;
        left_of += column && x < f.bbox.x ? 1u : 0u;
        up_to += column && x <= f.bbox.z ? 1u : 0u;
        above += row && y > f.bbox.w ? 1u : 0u;
        down_to += row && y >= f.bbox.y ? 1u : 0u;
    }
    if (up_to <= left_of || down_to <= above) {
        return uvec4(1u, 0u, 0u, 0u);
    }
    return uvec4(left_of, above, up_to - 1u, down_to - 1u);
}

// The pixels of the tile whose first pixel is (col0, row0) that a segment must hold for face
// `f` to be kept there, as tile columns and rows x0, y0, x1, y1 (inclusive): those whose centres
// lie in `f`'s box in x and in y. The first and last such column and row are found by the
// binning's arithmetic and corrected by a step either way with the centres `pixel_center`
// computes, so a segment meets this rect when the ballot's own test (`!(hi.x < bbox.x || ...)`
// over the segment's pixels in the image) may keep the face. None (x0 > x1) for a face no pixel
// sees.
uvec4 segment_rect(Face f, uint col0, uint row0) {
    if ((f.flags & FACE_FINITE) == 0u) {
        return uvec4(1u, 0u, 0u, 0u);
    }
    int w = int(pc.width);
    int h = int(pc.height);
    float fw = float(w);
    float fh = float(h);
    float scale = min(fw, fh);
    // Estimates within a column or row of the exact ones, clamped to [-1, size] (±∞ boxes too).
    int right = int(clamp(floor((f.bbox.z * scale + (fw - 1.0)) * 0.5), -1.0, fw));
    int left = int(clamp(ceil((f.bbox.x * scale + (fw - 1.0)) * 0.5), -1.0, fw));
    int top = int(clamp(ceil(((fh - 1.0) - f.bbox.w * scale) * 0.5), -1.0, fh));
    int bottom = int(clamp(floor(((fh - 1.0) - f.bbox.y * scale) * 0.5), -1.0, fh));
    // right: the last column whose centre is at most bbox.z; left: the first at least bbox.x.
    right = right + 1 < w && center_x(right + 1) <= f.bbox.z ? right + 1 : right;
    right = right >= 0 && right < w && center_x(right) > f.bbox.z ? right - 1 : right;
    left = left - 1 >= 0 && center_x(left - 1) >= f.bbox.x ? left - 1 : left;
    left = left >= 0 && left < w && center_x(left) < f.bbox.x ? left + 1 : left;
    // top: the first row whose centre is at most bbox.w (y falls as rows go down); bottom: the
    // last at least bbox.y.
    top = top - 1 >= 0 && center_y(top - 1) <= f.bbox.w ? top - 1 : top;
    top = top >= 0 && top < h && center_y(top) > f.bbox.w ? top + 1 : top;
    bottom = bottom + 1 < h && center_y(bottom + 1) >= f.bbox.y ? bottom + 1 : bottom;
    bottom = bottom >= 0 && bottom < h && center_y(bottom) < f.bbox.y ? bottom - 1 : bottom;
    // A segment of columns [a, b] (b within the image) meets the box in x where a <= right and
    // b >= left.
    int c0 = int(col0);
    int r0 = int(row0);
    int t = int(tile_size());
    int x0 = max(left - c0, 0);
    int x1 = min(right - c0, t - 1);
    int y0 = max(top - r0, 0);
    int y1 = min(bottom - r0, t - 1);
    if (x1 < 0 || y1 < 0 || left >= w || top >= h || left > right || top > bottom) {
        return uvec4(1u, 0u, 0u, 0u);
    }
    return uvec4(uint(x0), uint(y0), uint(x1), uint(y1));
}

// The contributions of the faces the ballot `kept` holds (lane q's `f`, face index `face`,
// partial at `o`) at this lane's pixel of the segment (upstream `u`, `live` where it has one), in
// index order: each face's three corners' sums (and colours) go to its own lane's `acc`
// (`cacc`, its texel slots), a quad at a time in pixel order (see the header).
// Face q's (lane q's `f`, face index `face`, partial at `o`) contribution at this lane's pixel
// (upstream `u`, `live` where it has one): its three corners' sums (and colours) go to lane q's
// `acc` (`cacc`, its texel slots), a quad at a time in pixel order (see the header). Every lane
// must be active.
void fold_face(uint q, Face f, uint face, uint o, Upstream u, bool live,
               inout vec3 acc[3], inout vec3 cacc[3], inout uint written) {
    uint lanes = subgroup_lanes();
    uint lane = gl_SubgroupInvocationID;
    counted_kept += lane == q ? 1u : 0u;
    uint fq = subgroupShuffle(face, q);
    FaceGrad g;
    bool hit = live && pixel_face_grad(face_shuffle(f, q), fq, u, g);
    bool mine = lane == q;
    for (uint c = 0u; c < 3u; ++c) {
        // With an alpha-only upstream no depth has a gradient: z stays +0.
        if (ALPHA_ONLY) {
            vec2 quad = quad_sum(hit ? g.screen[c].xy : vec2(NEG_ZERO));
            for (uint j = 0u; j < lanes; j += 4u) {
                vec2 sum = subgroupShuffle(quad, j);
                acc[c].xy += mine ? sum : vec2(NEG_ZERO);
            }
        } else {
            vec3 quad = quad_sum(hit ? g.screen[c] : vec3(NEG_ZERO));
            for (uint j = 0u; j < lanes; j += 4u) {
                vec3 sum = subgroupShuffle(quad, j);
                acc[c] += mine ? sum : vec3(NEG_ZERO);
            }
        }
    }
    if (ALPHA_ONLY) {
        return;
    }
    bool colored = hit && g.colored;
    if (VERTEX_COLORS) {
        for (uint c = 0u; c < 3u; ++c) {
            vec3 quad = quad_sum(colored ? g.color[c] : vec3(NEG_ZERO));
            for (uint j = 0u; j < lanes; j += 4u) {
                vec3 sum = subgroupShuffle(quad, j);
                cacc[c] += mine ? sum : vec3(NEG_ZERO);
            }
        }
    } else {
        // Texel slots: each of the segment's pixels on a texel of face q adds its
        // contribution to the texel's slot, one after another in pixel order. The
        // lowest of them does the adding (one read-modify-write per face and
        // segment, each lane on its own texel, rather than one per pixel: on
        // llvmpipe each is a scalar loop over the lanes): first it finds the lanes
        // on its texel, then it reads the slot and adds their values in lane order.
        uint texel = colored ? g.texel : 0xFFFFFFFFu;
        uint same = 0u; // the lanes (up to 32 of them) on this lane's texel
        bool leader = colored;
        for (uint k = 0u; k < lanes; ++k) {
            bool on = subgroupShuffle(texel, k) == texel;
            same |= on && k < 32u ? 1u << k : 0u;
            leader = leader && !(on && k < lane);
        }
        uint oq = subgroupShuffle(o, q);
        uint bit = leader ? 1u << texel : 0u;
        vec4 old = vec4(0.0);
        if (TEXEL_MASKS) {
            // A slot face q's partial has not written yet is written, not read
            // (the read was a cache miss); then face q's lane notes the slots its
            // leaders wrote.
            uint seen = subgroupShuffle(written, q);
            if (leader && (seen & bit) != 0u) {
                old = partials[oq + PARTIAL_COLORS + texel];
            }
        } else if (leader) {
            old = partials[oq + PARTIAL_COLORS + texel];
        }
        vec3 sum = old.xyz;
        for (uint k = 0u; k < lanes; ++k) {
            vec3 value = subgroupShuffle(g.color[0], k);
            bool on = k < 32u ? (same & (1u << k)) != 0u
                              : subgroupShuffle(texel, k) == texel;
            sum += on ? value : vec3(NEG_ZERO);
        }
        if (leader) {
            partials[oq + PARTIAL_COLORS + texel] = vec4(sum, old.w);
        }
        if (TEXEL_MASKS) {
            uint bits = lane_or(bit);
            written |= mine ? bits : 0u;
        }
    }
}

// The faces the ballot `kept` holds, in index order (`fold_face`).
void fold_kept(uvec4 kept, Face f, uint face, uint o, Upstream u, bool live,
               inout vec3 acc[3], inout vec3 cacc[3], inout uint written) {
    for (uint word = 0u; word < ballot_words(); ++word) {
        ++counted_iterations;
        uint mask = kept[word];
        while (mask != 0u) {
            ++counted_iterations;
            uint q = 32u * word + uint(findLSB(mask));
            mask &= mask - 1u;
            fold_face(q, f, face, o, u, live, acc, cacc, written);
        }
    }
}

// The visits of one group of at most 32 segments, from segment `group0` on, of the batch whose
// lane holds face `f` (index `face`, partial at `o`): the segments some face's box reaches
// (each lane's `reach`, the subgroup's union), one after another in segment order, each with
// its upstream, its ballot of the faces whose box meets its live pixels' and those faces'
// contributions (see the header).
void visit_group(uint group0, uint segments, Face f, uint face, uint o, uvec4 reach,
                 TileCentres centres, uint tx, uint ty, uint gview, inout vec3 acc[3],
                 inout vec3 cacc[3], inout uint written) {
    uint lanes = subgroup_lanes();
    uint lane = gl_SubgroupInvocationID;
    uint pixels = tile_size() * tile_size();
    float inf = uintBitsToFloat(0x7f800000u);
    uvec2 shape = segment_shape(lanes);
    uint count = min(32u, segments - group0);
    uint mine = 0u;
    for (uint s = 0u; s < count; ++s) {
        ++counted_iterations;
        uvec2 at = morton_pixel((group0 + s) * lanes, tile_size());
        bool in_reach = reach.x <= reach.z && at.x <= reach.z && at.x + shape.x > reach.x
                     && at.y <= reach.w && at.y + shape.y > reach.y;
        mine |= in_reach ? 1u << s : 0u;
    }
    uint todo = lane_or(mine);
    while (todo != 0u) {
        ++counted_iterations;
        uint base = (group0 + uint(findLSB(todo))) * lanes;
        todo &= todo - 1u;
        uint i = base + lane;
        uvec2 at = morton_pixel(i, tile_size());
        uint col = tx * tile_size() + at.x;
        uint row = (pc.first_row + ty) * tile_size() + at.y;
        bool live = i < pixels && lane < lanes && col < pc.width && row < pc.height;
        vec2 p;
        if (centre_table()) {
            p = vec2(centre_at(centres.x0, centres.x1, at.x),
                     centre_at(centres.y0, centres.y1, at.y));
        } else {
            p = pixel_center(col, row, pc.width, pc.height);
        }
        Upstream u = live ? load_upstream_at(gview, col, row, p) : zero_upstream();
        live = live && !upstream_is_zero(u);
        vec2 lo = lane_min(live ? u.p : vec2(inf));
        vec2 hi = lane_max(live ? u.p : vec2(-inf));
        uvec4 kept = subgroupBallot(face_meets_box(f, lo, hi));
        fold_kept(kept, f, face, o, u, live, acc, cacc, written);
    }
}

// The alpha-only path on tiles of 8 (see `main`): segment k's pixel of this lane, its upstream
// and the box of its live pixels, loaded once per tile (a set of variables per segment: a loop
// over an array of them would index it per lane, on llvmpipe a gather and a scatter per
// access; nested loops are not unrolled); segments past the tile's 64 pixels are never live
// and never visited (a constant condition once the subgroup size is specialized).
#define SEGMENT_LOAD(k)                                                                   \
    uvec2 at##k = morton_pixel(uint(k) * lanes + lane, 8u);                                \
    uint col##k##_ = col0 + at##k.x;                                                       \
    uint row##k##_ = row0 + at##k.y;                                                       \
    bool live##k = by_segment && uint(k) < tile_segments && col##k##_ < pc.width            \
                && row##k##_ < pc.height;                                                  \
    vec2 p##k = vec2(centre_at(centres.x0, centres.x1, at##k.x),                           \
                     centre_at(centres.y0, centres.y1, at##k.y));                          \
    Upstream u##k = live##k ? load_upstream_at(gview, col##k##_, row##k##_, p##k)           \
                            : zero_upstream();                                             \
    live##k = live##k && !upstream_is_zero(u##k);                                          \
    vec2 lo##k = lane_min(live##k ? u##k.p : vec2(inf));                                   \
    vec2 hi##k = lane_max(live##k ? u##k.p : vec2(-inf));

// The faces of the batch whose lane holds face `f` that segment k's ballot keeps (the general
// path's test: the face's box against the box of the segment's live pixels), as bits
// k * lanes .. (k + 1) * lanes - 1 of the 64 in `kept`, and segment k's upstream picked for the
// segment `seg` of a kept bit.
#define SEGMENT_KEEP(k)                                                                   \
    if (uint(k) < tile_segments) {                                                         \
        uvec4 ballot = subgroupBallot(face_meets_box(f, lo##k, hi##k));                    \
        if (lanes == 64u) {                                                                \
            kept = ballot.xy;                                                              \
        } else {                                                                           \
            uint at_bit = uint(k) * lanes;                                                 \
            uint bits = ballot.x & (lanes == 32u ? 0xffffffffu : (1u << lanes) - 1u);      \
            kept[at_bit / 32u] |= bits << (at_bit % 32u);                                  \
        }                                                                                  \
    }

#define SEGMENT_PICK(k)                                                                   \
    if (uint(k) < tile_segments && seg == uint(k)) {                                       \
        u = u##k;                                                                          \
        live = live##k;                                                                    \
    }

void main() {
    counted_iterations = 0u;
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
    uint pixels = tile_size() * tile_size();

    uint lane = gl_SubgroupInvocationID;
    uint col0 = tx * tile_size();
    uint row0 = (pc.first_row + ty) * tile_size();
    TileCentres centres = TileCentres(0.0, 0.0, 0.0, 0.0);
    if (centre_table()) {
        centres = tile_centres(col0, row0);
    }
    // A silhouette's backward on tiles of 8 with a known subgroup size: every segment's
    // upstream is loaded once per tile, not once per batch that reaches it (fit-120: about 17
    // batches a tile), and every batch visits every segment, the ballot keeping its faces as
    // the general path's does (which skips only segments whose ballot would be empty): the
    // same sums, bit for bit, without the reach and its skipping. (A colour upstream is too
    // large to hold per segment, and tiles of 16 or more have too many segments.)
    bool by_segment = ALPHA_ONLY && TILE_SIZE == 8u && SUBGROUP_SIZE >= 4u
                   && SUBGROUP_SIZE <= 64u && centre_table();
    uint tile_segments = 64u / lanes;
    float inf = uintBitsToFloat(0x7f800000u);
    SEGMENT_LOAD(0) SEGMENT_LOAD(1) SEGMENT_LOAD(2) SEGMENT_LOAD(3)
    SEGMENT_LOAD(4) SEGMENT_LOAD(5) SEGMENT_LOAD(6) SEGMENT_LOAD(7)
    SEGMENT_LOAD(8) SEGMENT_LOAD(9) SEGMENT_LOAD(10) SEGMENT_LOAD(11)
    SEGMENT_LOAD(12) SEGMENT_LOAD(13) SEGMENT_LOAD(14) SEGMENT_LOAD(15)
    // The workgroup's faces go to its subgroups `lanes` at a time, round robin.
    for (uint start = first + gl_SubgroupID * lanes; start < last;
         start += gl_NumSubgroups * lanes) {
        ++counted_iterations;
        counted_kept = 0u;
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
        // A constant after specialization: one of the two paths is compiled.
        if (by_segment) {
            // Every segment's kept faces as one mask of (segment, lane) bits, taken in order
            // (segment by segment, each face's contributions in pixel order) by one loop: a
            // loop on llvmpipe runs its body once even when it is skipped, so a loop per
            // segment would cost a pass of the per-pair maths per segment with nothing kept.
            uvec2 kept = uvec2(0u);
            SEGMENT_KEEP(0) SEGMENT_KEEP(1) SEGMENT_KEEP(2) SEGMENT_KEEP(3)
            SEGMENT_KEEP(4) SEGMENT_KEEP(5) SEGMENT_KEEP(6) SEGMENT_KEEP(7)
            SEGMENT_KEEP(8) SEGMENT_KEEP(9) SEGMENT_KEEP(10) SEGMENT_KEEP(11)
            SEGMENT_KEEP(12) SEGMENT_KEEP(13) SEGMENT_KEEP(14) SEGMENT_KEEP(15)
            for (uint word = 0u; word < 2u; ++word) {
                ++counted_iterations;
                uint mask = kept[word];
                while (mask != 0u) {
                    ++counted_iterations;
                    uint bit = 32u * word + uint(findLSB(mask));
                    mask &= mask - 1u;
                    uint seg = bit / lanes;
                    Upstream u = zero_upstream();
                    bool live = false;
                    SEGMENT_PICK(0) SEGMENT_PICK(1) SEGMENT_PICK(2) SEGMENT_PICK(3)
                    SEGMENT_PICK(4) SEGMENT_PICK(5) SEGMENT_PICK(6) SEGMENT_PICK(7)
                    SEGMENT_PICK(8) SEGMENT_PICK(9) SEGMENT_PICK(10) SEGMENT_PICK(11)
                    SEGMENT_PICK(12) SEGMENT_PICK(13) SEGMENT_PICK(14) SEGMENT_PICK(15)
                    fold_face(bit - seg * lanes, f, face, o, u, live, acc, cacc, written);
                }
            }
        } else {
            // Segments 32 at a time, only those some face of the batch may touch. A segment
            // no face touches would cost a whole visit: on llvmpipe a loop runs its first
            // iteration whatever its condition (with no lane active, but every instruction),
            // so the empty ballot's loop below would still run the per-pair maths once; on
            // spot-256 45 % of the (segment, batch) pairs were such. Each lane marks the
            // segments its face's box may reach (`segment_rect`: those holding a pixel centre
            // inside it, in x and in y) and the subgroup takes the union; a segment skipped
            // so has no pixel where the face adds anything, so every sum is the same, bit for
            // bit.
            uint segments = (pixels + lanes - 1u) / lanes;
            uvec4 reach = centre_table() ? segment_rect_table(f, centres, col0, row0)
                                         : segment_rect(f, col0, row0);
            // With the tile and subgroup sizes known, one group needs no loop around it (a loop
            // level cost spot-256's backward 4 % on llvmpipe, even run once).
            if (TILE_SIZE != 0u && SUBGROUP_SIZE != 0u && segments <= 32u) {
                visit_group(0u, segments, f, face, o, reach, centres, tx, ty, gview, acc, cacc,
                            written);
            } else {
                for (uint group0 = 0u; group0 < segments; group0 += 32u) {
                    ++counted_iterations;
                    visit_group(group0, segments, f, face, o, reach, centres, tx, ty, gview, acc,
                                cacc, written);
                }
            }
        }
        if (COUNT_LOOPS != 0u) {
            if (has) {
                partials[o] = vec4(float(counted_iterations), float(counted_kept), 0.0, 0.0);
            }
        } else if (has) {
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
