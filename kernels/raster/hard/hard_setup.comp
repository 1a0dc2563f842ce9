#version 460
#extension GL_GOOGLE_include_directive : require
// The hard rasterizer, step 1: one invocation per item (minibatch item b, triangle slot j);
// slot j of item b is triangle `ranges[b].x + j` when j < ranges[b].y (instanced mode: every
// triangle, the host's ranges are (0, T)). It decides how the triangle's coverage is tested
// (`reference::coverage`) and writes the item the binning and the depth pass read:
// - wholly beyond one frustum plane, or snapped to zero area: not binned;
// - every corner with w > 0, |z| <= w and |x|·8W, |y|·8H <= 2^21 w: snapped, corners
//   round-half-even(x/w · 8W) (sub-pixel units from the viewport centre), counter-clockwise
//   (corners 1 and 2 swapped when clockwise), with each edge's fill-rule bit (left or bottom
//   edges are inclusive), boxed by its snapped corners (shrunk by the binning's widening);
// - else the homogeneous test, boxed by its projection when every w > 0 and by the whole image
//   when a corner is behind the eye.
// Boxes are in the binning's pixel-centre coordinates (`binning.glsl`: x/S·W, y/S·H in NDC
// units, S = min(W, H); the binning widens them by a pixel on each side).
#include "common.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Pos { float pos[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tri { uint tri[]; };
// Per minibatch item: (first triangle, count).
layout(std430, set = 0, binding = 2) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Items { float items[]; };
// How many items take the homogeneous test (the host clears it): with none, the depth pass
// runs without its loop over them.
layout(std430, set = 0, binding = 4) buffer Counts { uint homogeneous_items; };

#include "hard.glsl"

bool beyond(vec4 p0, vec4 p1, vec4 p2) {
    for (int axis = 0; axis < 3; ++axis) {
        if ((p0[axis] > p0.w && p1[axis] > p1.w && p2[axis] > p2.w)
            || (-p0[axis] > p0.w && -p1[axis] > p1.w && -p2[axis] > p2.w)) {
            return true;
        }
    }
    return false;
}

bool snappable(vec4 p) {
    precise float sx = abs(p.x) * float(8u * pc.width);
    precise float sy = abs(p.y) * float(8u * pc.height);
    precise float lim = SNAP_LIMIT * p.w;
    return p.w > 0.0 && abs(p.z) <= p.w && sx <= lim && sy <= lim;
}

ivec2 snap(vec4 p) {
    precise float x = fm_div_rn(p.x, p.w) * float(8u * pc.width);
    precise float y = fm_div_rn(p.y, p.w) * float(8u * pc.height);
    return ivec2(roundEven(x), roundEven(y));
}

// The edge a → b includes the centres on it: a left edge (going down) or a bottom edge
// (horizontal, going right), counter-clockwise with y up.
uint inclusive(ivec2 a, ivec2 b) {
    int dx = b.x - a.x;
    int dy = b.y - a.y;
    return (dy < 0 || (dy == 0 && dx > 0)) ? 1u : 0u;
}

void write_item(uint o, bool binned, vec4 box, uint t, uint mode, uint inc, ivec2 q0, ivec2 q1,
                ivec2 q2, vec3 plane) {
    items[o] = box.x;
    items[o + 1u] = box.y;
    items[o + 2u] = box.z;
    items[o + 3u] = box.w;
    items[o + 4u] = uintBitsToFloat(binned ? ITEM_BINNED : 0u);
    items[o + 5u] = uintBitsToFloat(t);
    items[o + 6u] = uintBitsToFloat(mode);
    items[o + 7u] = uintBitsToFloat(inc);
    items[o + 8u] = intBitsToFloat(q0.x);
    items[o + 9u] = intBitsToFloat(q0.y);
    items[o + 10u] = intBitsToFloat(q1.x);
    items[o + 11u] = intBitsToFloat(q1.y);
    items[o + 12u] = intBitsToFloat(q2.x);
    items[o + 13u] = intBitsToFloat(q2.y);
    items[o + 14u] = plane.x;
    items[o + 15u] = plane.y;
    items[o + 16u] = plane.z;
    items[o + 17u] = 0.0;
    items[o + 18u] = 0.0;
    items[o + 19u] = 0.0;
}

// The plane z/w = C + A x + B y through the corners' NDC points, as (A, B, C): z/w is affine in
// NDC over a triangle in front of the eye (a projective map keeps planes). Edge-on corners (no
// such plane) give a non-finite plane, which the depth pass never draws.
vec3 depth_plane(vec4 p0, vec4 p1, vec4 p2) {
    precise vec3 q0 = vec3(fm_div_rn(p0.x, p0.w), fm_div_rn(p0.y, p0.w), fm_div_rn(p0.z, p0.w));
    precise vec3 q1 = vec3(fm_div_rn(p1.x, p1.w), fm_div_rn(p1.y, p1.w), fm_div_rn(p1.z, p1.w));
    precise vec3 q2 = vec3(fm_div_rn(p2.x, p2.w), fm_div_rn(p2.y, p2.w), fm_div_rn(p2.z, p2.w));
    precise vec3 e1 = q1 - q0;
    precise vec3 e2 = q2 - q0;
    vec3 n = fm_cross(e1, e2);
    float a = fm_div(-n.x, n.z);
    float b = fm_div(-n.y, n.z);
    precise float c = q0.z - a * q0.x - b * q0.y;
    return vec3(a, b, c);
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.batch * pc.items_per_view) {
        return;
    }
    uint b = id / pc.items_per_view;
    uint j = id - b * pc.items_per_view;
    uint o = id * ITEM_WORDS;
    uvec2 range = ranges[b];
    ivec2 zero = ivec2(0);
    if (j >= range.y) {
        write_item(o, false, vec4(0.0), 0u, 0u, 0u, zero, zero, zero, vec3(0.0));
        return;
    }
    uint t = range.x + j;
    vec4 p0 = corner(b, t, 0u);
    vec4 p1 = corner(b, t, 1u);
    vec4 p2 = corner(b, t, 2u);
    if (beyond(p0, p1, p2)) {
        write_item(o, false, vec4(0.0), t, 0u, 0u, zero, zero, zero, vec3(0.0));
        return;
    }
    if (snappable(p0) && snappable(p1) && snappable(p2)) {
        ivec2 q0 = snap(p0);
        ivec2 q1 = snap(p1);
        ivec2 q2 = snap(p2);
        int hi;
        uint lo;
        mul_sub64(q1.x - q0.x, q2.y - q0.y, q1.y - q0.y, q2.x - q0.x, hi, lo);
        if (hi == 0 && lo == 0u) {
            write_item(o, false, vec4(0.0), t, 0u, 0u, zero, zero, zero, vec3(0.0));
            return;
        }
        if (hi < 0) {
            ivec2 swap = q1;
            q1 = q2;
            q2 = swap;
        }
        uint inc = inclusive(q0, q1) | (inclusive(q1, q2) << 1u) | (inclusive(q2, q0) << 2u);
        // The box shrunk by 30 units (1 7/8 pixels) on each side: the binning widens it by two
        // pixels (`binning.glsl`: one for its rounding out, one more), so its tiles are those
        // holding the pixel centres within 1/8 pixel of the snapped corners' box, and a
        // triangle whose box holds no centre (lo > hi after shrinking) is binned nowhere.
        ivec2 lo_corner = min(q0, min(q1, q2)) + 30;
        ivec2 hi_corner = max(q0, max(q1, q2)) - 30;
        precise vec4 box = vec4(float(lo_corner.x) * pc.box_scale, float(lo_corner.y) * pc.box_scale,
                                float(hi_corner.x) * pc.box_scale, float(hi_corner.y) * pc.box_scale);
        write_item(o, true, box, t, MODE_SNAPPED, inc, q0, q1, q2, depth_plane(p0, p1, p2));
        return;
    }
    vec4 box = vec4(-1e30, -1e30, 1e30, 1e30);
    if (p0.w > 0.0 && p1.w > 0.0 && p2.w > 0.0) {
        // NDC x · W/S = x/w · 8W · box_scale.
        precise vec3 xs = vec3(fm_div_rn(p0.x, p0.w), fm_div_rn(p1.x, p1.w), fm_div_rn(p2.x, p2.w))
                        * (float(8u * pc.width) * pc.box_scale);
        precise vec3 ys = vec3(fm_div_rn(p0.y, p0.w), fm_div_rn(p1.y, p1.w), fm_div_rn(p2.y, p2.w))
                        * (float(8u * pc.height) * pc.box_scale);
        box = vec4(min(xs.x, min(xs.y, xs.z)), min(ys.x, min(ys.y, ys.z)),
                   max(xs.x, max(xs.y, xs.z)), max(ys.x, max(ys.y, ys.z)));
    }
    write_item(o, true, box, t, MODE_HOMOGENEOUS, 0u, zero, zero, zero, vec3(0.0));
    atomicAdd(homogeneous_items, 1u);
}
