#version 460
#extension GL_GOOGLE_include_directive : require
// `interpolate`, forward: per pixel, out = u a_0 + v a_1 + (1 − u − v) a_2 of its triangle's
// corner attributes (rast's u, v as given), and for each differentiated attribute n (index
// diff[n]) (∂a/∂X, ∂a/∂Y) = (du/dX (a_0 − a_2) + dv/dX (a_1 − a_2), du/dY (…) + dv/dY (…)).
// All zero where nothing is drawn (an id of 0 or past the triangles). `pc.instanced`: attr
// holds one set of V rows per minibatch item, else one shared set. Twin:
// `reference::interpolate`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Attr { float attr[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
layout(std430, set = 0, binding = 2) readonly buffer Rast { vec4 rast[]; };
layout(std430, set = 0, binding = 3) readonly buffer RastDb { vec4 rast_db[]; };
layout(std430, set = 0, binding = 4) readonly buffer Diff { uint diff[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Out { float out_attr[]; };
layout(std430, set = 0, binding = 6) writeonly buffer OutDa { float out_da[]; };

#define HARD_NO_POSITIONS
#include "hard.glsl"

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (i >= pc.batch * pixels) {
        return;
    }
    uint a = pc.attr_count;
    uint n = pc.diff_count;
    vec4 r = rast[i];
    if (!(r.w >= 1.0) || !(r.w <= float(pc.tri_count))) {
        for (uint j = 0u; j < a; ++j) {
            out_attr[i * a + j] = 0.0;
        }
        for (uint k = 0u; k < 2u * n; ++k) {
            out_da[i * 2u * n + k] = 0.0;
        }
        return;
    }
    uint t = uint(r.w) - 1u;
    uint base = pc.instanced != 0u ? (i / pixels) * pc.vertex_count : 0u;
    uint r0 = (base + tri[3u * t]) * a;
    uint r1 = (base + tri[3u * t + 1u]) * a;
    uint r2 = (base + tri[3u * t + 2u]) * a;
    precise float w2 = 1.0 - r.x - r.y;
    for (uint j = 0u; j < a; ++j) {
        precise float v = r.x * attr[r0 + j] + r.y * attr[r1 + j] + w2 * attr[r2 + j];
        out_attr[i * a + j] = v;
    }
    if (n == 0u) {
        return;
    }
    vec4 db = rast_db[i];
    for (uint k = 0u; k < n; ++k) {
        uint j = diff[k];
        precise float du = attr[r0 + j] - attr[r2 + j];
        precise float dv = attr[r1 + j] - attr[r2 + j];
        precise float dx = db.x * du + db.z * dv;
        precise float dy = db.y * du + db.w * dv;
        out_da[i * 2u * n + 2u * k] = dx;
        out_da[i * 2u * n + 2u * k + 1u] = dy;
    }
}
