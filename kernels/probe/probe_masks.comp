#version 460
#extension GL_GOOGLE_include_directive : require
// Sphere probing, binning step 1 (in place of the generic binning's count, scatter and sort):
// one invocation per anchor item (view-major). An item the binning would keep (FLAG_VALID, a
// tile rectangle: `tile_rect`, the generic binning's own) sets its anchor's bit in the anchor
// mask of every tile of its rectangle: tile t's anchors are the set bits of words
// `[t · W, (t + 1) · W)`, W = ⌈anchors / 32⌉, lowest first in anchor order, so a scan of the
// words' bit counts (`probe_mask_counts.comp`, then the scan) lists each tile's anchors in the
// order the binning's stable sort gives. The rectangle is also written (packed, `NO_RECT` when
// the item is not binned) for the gradient sum (`probe_reduce.comp`). Integer `atomicOr`: the
// result does not depend on the order of the writes. Twin: `binning::cpu::tile_rect`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Items { float items[]; };
layout(std430, set = 0, binding = 1) buffer Masks { uint masks[]; };
// Per item: (x0 | x1 << 16, y0 | y1 << 16) of its tile rectangle, or NO_RECT.
layout(std430, set = 0, binding = 2) writeonly buffer Rects { uvec2 rects[]; };

#include "binning.glsl"

#define NO_RECT uvec2(0xFFFFFFFFu)

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.item_count) {
        return;
    }
    vec4 box;
    uvec4 rect;
    if (!(item_box(pc.first_item + id, box) && tile_rect(box, rect))) {
        rects[id] = NO_RECT;
        return;
    }
    rects[id] = uvec2(rect.x | (rect.z << 16u), rect.y | (rect.w << 16u));
    uint view = id / pc.items_per_view;
    uint item = id - view * pc.items_per_view;
    uint words = (pc.items_per_view + 31u) / 32u;
    uint tile_base = view * pc.tiles_x * pc.tiles_y;
    uint bit = 1u << (item & 31u);
    for (uint ty = rect.y; ty <= rect.w; ++ty) {
        for (uint tx = rect.x; tx <= rect.z; ++tx) {
            atomicOr(masks[(tile_base + ty * pc.tiles_x + tx) * words + item / 32u], bit);
        }
    }
}
