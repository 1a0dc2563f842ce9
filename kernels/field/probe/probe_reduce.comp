#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, backward, step 3: dL/dφ_j = coef · Σ over views, then over the tiles of anchor
// j's item in that view (its tile rectangle, row by row: the order of the generic binning's
// item-major slots), of the partials, in that fixed order. An entry is found from the masks:
// the tile's first entry, the anchor's word's prefix in the tile, and the set bits below its
// own (`bin_mask_counts.comp`).
// One invocation per anchor, one writer per output: deterministic. coef is 2 / (number of rays)
// times the gradient's weight. Twin: `probe::prober::cpu::backward`.
#include "common.glsl"

layout(local_size_x = 64) in;

// Per item: (x0 | x1 << 16, y0 | y1 << 16) of its tile rectangle, or all ones when not binned
// (`probe_items.comp`).
layout(std430, set = 0, binding = 0) readonly buffer Rects { uvec2 rects[]; };
layout(std430, set = 0, binding = 1) readonly buffer Masks { uint masks[]; };
layout(std430, set = 0, binding = 2) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 3) readonly buffer WordPrefix { uint word_prefix[]; };
layout(std430, set = 0, binding = 4) readonly buffer Partials { float partials[]; };
layout(std430, set = 0, binding = 5) buffer DPhi { float d_phi[]; };

// Twin of `ReducePush` (src/probe/prober/).
layout(push_constant) uniform Push {
    uint anchors;
    uint views;
    uint entries;        // entries of the binning
    uint accumulate;     // add to d_phi instead of overwriting it
    float coef;
    uint words_per_tile; // W = ⌈anchors / 32⌉
    uint tiles_x;
    uint tiles_y;
} pc;

void main() {
    uint anchor = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (anchor >= pc.anchors) {
        return;
    }
    uint tiles_per_view = pc.tiles_x * pc.tiles_y;
    uint word = anchor / 32u;
    uint below = (1u << (anchor & 31u)) - 1u;
    float s = 0.0;
    for (uint view = 0u; view < pc.views; ++view) {
        uvec2 rect = rects[view * pc.anchors + anchor];
        if (rect.x == 0xFFFFFFFFu) {
            continue;
        }
        uint x0 = rect.x & 0xFFFFu;
        uint x1 = rect.x >> 16u;
        uint y0 = rect.y & 0xFFFFu;
        uint y1 = rect.y >> 16u;
        for (uint ty = y0; ty <= y1; ++ty) {
            for (uint tx = x0; tx <= x1; ++tx) {
                uint t = view * tiles_per_view + ty * pc.tiles_x + tx;
                uint w = t * pc.words_per_tile + word;
                s += partials[offsets[t] + word_prefix[w] + uint(bitCount(masks[w] & below))];
            }
        }
    }
    float g = pc.coef * s;
    d_phi[anchor] = pc.accumulate != 0u ? d_phi[anchor] + g : g;
}
