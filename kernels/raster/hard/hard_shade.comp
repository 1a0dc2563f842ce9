#version 460
#extension GL_GOOGLE_include_directive : require
// The hard rasterizer, step 4: per pixel, from its depth key, nvdiffrast's outputs
// `rast = (u, v, z/w, id + 1)` and `rast_db = (du/dX, du/dY, dv/dX, dv/dY)` (all zero where
// nothing is drawn), recomputed from the triangle's clip-space corners at the pixel centre:
// u = a_0/Σa and v = a_1/Σa each clamped to [0, 1] and scaled down to a sum of at most 1, z/w
// (the key's) clamped to [−1, 1], and the pixel derivatives from the clamped u, v. Twin:
// `reference::shade`.
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Pos { float pos[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
layout(std430, set = 0, binding = 2) readonly buffer Keys { uvec2 keys[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Rast { vec4 rast[]; };
layout(std430, set = 0, binding = 4) writeonly buffer RastDb { vec4 rast_db[]; };

#include "hard.glsl"

void main() {
    uint i = linear_group_id() * 64u + gl_LocalInvocationIndex;
    uint pixels = pc.width * pc.height;
    if (i >= pc.batch * pixels) {
        return;
    }
    uvec2 key = keys[i];
    if (key.y == 0u || key.y > pc.tri_count) {
        rast[i] = vec4(0.0);
        rast_db[i] = vec4(0.0);
        return;
    }
    uint b = i / pixels;
    uint p = i - b * pixels;
    uint y = p / pc.width;
    uint x = p - y * pc.width;
    uint t = key.y - 1u;
    vec4 p0 = corner(b, t, 0u);
    vec4 p1 = corner(b, t, 1u);
    vec4 p2 = corner(b, t, 2u);
    vec3 a = edge_areas(p0, p1, p2, pixel_ndc(x, y));
    precise float at = a.x + a.y + a.z;
    float iw = fm_rcp(at);
    precise float u0 = clamp(a.x * iw, 0.0, 1.0);
    precise float v0 = clamp(a.y * iw, 0.0, 1.0);
    precise float s = u0 + v0;
    float scale = s > 1.0 ? fm_rcp(s) : 1.0;
    precise float u = u0 * scale;
    precise float v = v0 * scale;
    // ∂a_k/∂f: for a_0 = p_1' × p_2', (y_1 w_2 − w_1 y_2, w_1 x_2 − x_1 w_2); likewise a_1, a_2.
    precise vec2 d0 = vec2(p1.y * p2.w - p1.w * p2.y, p1.w * p2.x - p1.x * p2.w);
    precise vec2 d1 = vec2(p2.y * p0.w - p2.w * p0.y, p2.w * p0.x - p2.x * p0.w);
    precise vec2 d2 = vec2(p0.y * p1.w - p0.w * p1.y, p0.w * p1.x - p0.x * p1.w);
    precise vec2 dt = d0 + d1 + d2;
    precise float sx = pc.ndc_dx * iw;
    precise float sy = pc.ndc_dy * iw;
    precise vec4 db = vec4(sx * (d0.x - u * dt.x), sy * (d0.y - u * dt.y),
                           sx * (d1.x - v * dt.x), sy * (d1.y - v * dt.y));
    float zw = clamp(uintBitsToFloat(key.x), -1.0, 1.0);
    rast[i] = vec4(u, v, zw, float(key.y));
    rast_db[i] = db;
}
