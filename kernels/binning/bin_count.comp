#version 460
#extension GL_GOOGLE_include_directive : require
// Binning, step 1: how many tiles each item's box touches (0 for an item that is not binned).
// One invocation per item. An exclusive scan of these counts gives every item its slot in the
// pair list, and the total sizes that list exactly. Twin: `binning::cpu::bin`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Items { float items[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Counts { uint counts[]; };

#include "binning.glsl"

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.item_count) {
        return;
    }
    vec4 box;
    uvec4 rect;
    uint count = 0u;
    if (item_box(pc.first_item + id, box) && tile_rect(box, rect)) {
        count = (rect.z - rect.x + 1u) * (rect.w - rect.y + 1u);
    }
    counts[id] = count;
}
