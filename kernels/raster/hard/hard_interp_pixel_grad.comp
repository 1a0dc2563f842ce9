#version 460
#extension GL_GOOGLE_include_directive : require
// `interpolate`, backward, per pixel: the gradients of rast (u: Σ_j dy_j (a_0j − a_2j), v:
// Σ_j dy_j (a_1j − a_2j); z/w and the id none) and of rast_db (du/dX: Σ_n gx_n (a_0 − a_2)_{diff n},
// du/dY with gy, dv/dX, dv/dY with a_1 − a_2), in attribute order. `pc.diff_count` = 0: no
// rast_db gradient (left zero). Twin: `reference::interpolate_grad`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Attr { float attr[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
layout(std430, set = 0, binding = 2) readonly buffer Rast { vec4 rast[]; };
layout(std430, set = 0, binding = 3) readonly buffer Diff { uint diff[]; };
layout(std430, set = 0, binding = 4) readonly buffer Dy { float dy[]; };
layout(std430, set = 0, binding = 5) readonly buffer Dda { float dda[]; };
layout(std430, set = 0, binding = 6) writeonly buffer GradRast { vec4 grad_rast[]; };
layout(std430, set = 0, binding = 7) writeonly buffer GradRastDb { vec4 grad_rast_db[]; };

#define HARD_NO_POSITIONS
#include "hard.glsl"

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (i >= pc.batch * pixels) {
        return;
    }
    vec4 r = rast[i];
    if (!(r.w >= 1.0) || !(r.w <= float(pc.tri_count))) {
        grad_rast[i] = vec4(0.0);
        grad_rast_db[i] = vec4(0.0);
        return;
    }
    uint a = pc.attr_count;
    uint n = pc.diff_count;
    uint t = uint(r.w) - 1u;
    uint base = pc.instanced != 0u ? (i / pixels) * pc.vertex_count : 0u;
    uint r0 = (base + tri[3u * t]) * a;
    uint r1 = (base + tri[3u * t + 1u]) * a;
    uint r2 = (base + tri[3u * t + 2u]) * a;
    precise float gu = 0.0;
    precise float gv = 0.0;
    for (uint j = 0u; j < a; ++j) {
        float up = dy[i * a + j];
        gu += up * (attr[r0 + j] - attr[r2 + j]);
        gv += up * (attr[r1 + j] - attr[r2 + j]);
    }
    grad_rast[i] = vec4(gu, gv, 0.0, 0.0);
    precise vec4 gdb = vec4(0.0);
    for (uint k = 0u; k < n; ++k) {
        uint j = diff[k];
        float gx = dda[i * 2u * n + 2u * k];
        float gy = dda[i * 2u * n + 2u * k + 1u];
        precise float du = attr[r0 + j] - attr[r2 + j];
        precise float dv = attr[r1 + j] - attr[r2 + j];
        gdb += vec4(gx * du, gy * du, gx * dv, gy * dv);
    }
    grad_rast_db[i] = gdb;
}
