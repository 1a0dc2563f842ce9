#version 460
#extension GL_GOOGLE_include_directive : require
// `interpolate`, backward, the slot kernel (`hard_grads.glsl`): per (item, tile) slot, for each
// attribute j and corner k, the sum in pixel order over the tile's pixels that show the item of
// b_k dy_j (b = (u, v, 1 − u − v)) and, for each n with diff[n] = j, of the rast_db terms
// (corner 0: gx du/dX + gy du/dY, corner 1: gx dv/dX + gy dv/dY, corner 2: minus both), as
// partials[slot · 3A + k A + j]. `pc.diff_count` = 0: no rast_db terms. Twin:
// `reference::interpolate_grad`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, set = 0, binding = 1) readonly buffer Rast { vec4 rast[]; };
layout(std430, set = 0, binding = 2) readonly buffer RastDb { vec4 rast_db[]; };
layout(std430, set = 0, binding = 3) readonly buffer Diff { uint diff[]; };
layout(std430, set = 0, binding = 4) readonly buffer Dy { float dy[]; };
layout(std430, set = 0, binding = 5) readonly buffer Dda { float dda[]; };
layout(std430, set = 0, binding = 6) readonly buffer Boxes { uint boxes[]; };
layout(std430, set = 0, binding = 7) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 8) writeonly buffer Partials { float partials[]; };

#define HARD_NO_POSITIONS
#define HARD_GRADS_SLOTS
#include "hard.glsl"
#include "hard_grads.glsl"

void main() {
    uint slot = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (slot >= pc.slots) {
        return;
    }
    uvec3 st = slot_tile(slot);
    uint item = st.x;
    uint b = item / pc.items_per_view;
    uint a = pc.attr_count;
    uint n = pc.diff_count;
    uint x0 = 8u * st.y;
    uint y0 = 8u * st.z;
    uint x1 = min(x0 + 8u, pc.width);
    uint y1 = min(y0 + 8u, pc.height);
    for (uint j = 0u; j < a; ++j) {
        precise vec3 g = vec3(0.0);
        for (uint y = y0; y < y1; ++y) {
            for (uint x = x0; x < x1; ++x) {
                uint i = (b * pc.height + y) * pc.width + x;
                vec4 r = rast[i];
                uint t;
                if (pixel_item(i, r.w, t) != item) {
                    continue;
                }
                float up = dy[i * a + j];
                precise float w2 = 1.0 - r.x - r.y;
                g += vec3(r.x * up, r.y * up, w2 * up);
                for (uint k = 0u; k < n; ++k) {
                    if (diff[k] != j) {
                        continue;
                    }
                    vec4 db = rast_db[i];
                    float gx = dda[i * 2u * n + 2u * k];
                    float gy = dda[i * 2u * n + 2u * k + 1u];
                    precise float gdu = gx * db.x + gy * db.y;
                    precise float gdv = gx * db.z + gy * db.w;
                    g += vec3(gdu, gdv, -(gdu + gdv));
                }
            }
        }
        uint o = slot * 3u * a;
        partials[o + j] = g.x;
        partials[o + a + j] = g.y;
        partials[o + 2u * a + j] = g.z;
    }
}
