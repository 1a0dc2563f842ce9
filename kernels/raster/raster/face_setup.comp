#version 460
#extension GL_GOOGLE_include_directive : require
// Face setup (SoftRas `forward_soft_rasterize_inv`), one invocation per (view, face): the screen
// vertices (projected by `vertex_project.comp`), the inverse barycentric matrix with the clamped
// determinant, facing, and the grown screen box. Twin: `reference::project_faces` +
// `reference::setup_face`.
#include "common.glsl"
#include "raster.glsl"

layout(local_size_x = 64) in;

#include "view.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Positions { float positions[]; };
layout(std430, set = 0, binding = 1) readonly buffer Faces { uint faces[]; };
layout(std430, set = 0, binding = 2) readonly buffer Views { View views[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Setups { FaceSetup setups[]; };
// Every vertex of every view on screen (`vertex_project.comp`): (x_s, y_s, z, 0), view-major.
layout(std430, set = 0, binding = 4) readonly buffer Screen { vec4 screen[]; };

layout(push_constant) uniform Push {
    uint face_count;
    uint view_count;
    uint dist;           // DIST_*
    float radius;        // √T, T the squared-distance cut-off
    float degenerate_k;  // |det| <= degenerate_k * Σ|terms|: numerically degenerate
    float bary_margin;   // growth factor on the barycentric box's 3√T/s, for det rounding
    float pad_rel;       // box padding per unit of coordinate magnitude
    uint vertex_count;   // vertices per mesh of the batch
    uint position_offset;  // floats before vertex 0's x (`VertexLayout`)
    uint position_stride;  // floats from one vertex's x to the next's
} pc;

// Vertex `vertex` of the view's mesh, in world space.
vec3 world_position(View view, uint vertex) {
    uint v = view.mesh * pc.vertex_count + vertex;
    uint at = pc.position_offset + pc.position_stride * v;
    return vec3(positions[at], positions[at + 1u], positions[at + 2u]);
}

// The screen determinant det [[x_s], [y_s], [1, 1, 1]] of a look-at view's face, from its world
// vertices `q` (screen depths `z`) rather than from its screen vertices. With the rotation's
// rows r_x, r_y, r_z and the face's world normal n = (q1 - q0) × (q2 - q0), exactly:
// - perspective: det(R) n · (q0 - eye) / (tan² a z0 z1 z2), det(R) = (r_x × r_y) · r_z;
// - orthographic: s² (r_x × r_y) · n.
// The same number as the screen vertices' determinant, but in f32 that one is noise for a face
// seen nearly edge-on: each screen coordinate carries a few ulp of rounding relative to its
// magnitude (the rotation of p - eye, |p - eye| ≫ |x_s|), a large fraction of a sliver's width,
// and the sign can come out wrong (spot's face 548, eye (2.1321714, 0.43412045, 1.2310098) in
// f32: det -3.2e-9 in f64, positive from the f32 screen vertices). The sign decides where the
// clipped barycentrics of a pixel beside the sliver put it (its depth and texel there): a wrong
// one moved the face's softmax weight there by e^{0.37} and its neighbours' colour gradients by
// 7.5 %. Here the rounding is a few ulp of |n| |q0 - eye| (the world positions' differences
// are exact or nearly): the median error over spot's faces is 1e-7 of the determinant, against
// 3e-6 from the screen vertices, and only a face within ~1e-6 rad of edge-on can still get the
// wrong sign. For the screen-space camera (R = I, s = 1) this is ((q1 - q0) × (q2 - q0)) · z,
// the screen vertices' translated form bit for bit (rasterize's results do not change).
float look_at_det(View view, vec3 q0, vec3 q1, vec3 q2, vec3 z) {
    precise vec3 a = q1 - q0;
    precise vec3 b = q2 - q0;
    precise vec3 n = vec3(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
    vec3 rx = view.rows[0].xyz;
    vec3 ry = view.rows[1].xyz;
    vec3 rz = view.rows[2].xyz;
    precise vec3 k = vec3(rx.y * ry.z - rx.z * ry.y, rx.z * ry.x - rx.x * ry.z,
                          rx.x * ry.y - rx.y * ry.x);
    if (view.projection == PROJ_ORTHOGRAPHIC) {
        precise float kn = k.x * n.x + k.y * n.y + k.z * n.z;
        precise float s2 = view.param * view.param;
        return s2 * kn;
    }
    precise vec3 e = q0 - view.eye.xyz;
    precise float triple = n.x * e.x + n.y * e.y + n.z * e.z;
    precise float det_r = k.x * rz.x + k.y * rz.y + k.z * rz.z;
    precise float t2 = view.param * view.param;
    precise float zzz = z.x * z.y * z.z;
    return fm_div_rn(fm_div_rn(det_r * triple, t2), zzz);
}

bool finite3(vec3 v) {
    return !any(isinf(v)) && !any(isnan(v));
}

void main() {
    uint id = linear_group_id() * 64u + gl_LocalInvocationIndex;
    if (id >= pc.face_count * pc.view_count) {
        return;
    }
    uint view_index = id / pc.face_count;
    uint face = id - view_index * pc.face_count;
    View view = views[view_index];
    vec3 q0 = world_position(view, faces[3u * face]);
    vec3 q1 = world_position(view, faces[3u * face + 1u]);
    vec3 q2 = world_position(view, faces[3u * face + 2u]);
    // The corners on screen, projected once per vertex (`to_screen`, `vertex_project.comp`).
    uint first = view_index * pc.vertex_count;
    vec3 p0 = screen[first + faces[3u * face]].xyz;
    vec3 p1 = screen[first + faces[3u * face + 1u]].xyz;
    vec3 p2 = screen[first + faces[3u * face + 2u]].xyz;

    FaceSetup s;
    s.v[0] = vec4(p0, 0.0);
    s.v[1] = vec4(p1, 0.0);
    s.v[2] = vec4(p2, 0.0);

    // The determinant of [[x], [y], [1, 1, 1]] of the screen vertices in its translated form
    // (x1 - x0)(y2 - y0) - (x2 - x0)(y1 - y0): the same number as the twin's expansion, but in
    // f32 its rounding is relative to the face's size, not to its distance from the origin.
    // `precise` keeps the compiler from fusing it into an fma. Only the degeneracy test and the
    // matrix projection use it; a look-at view takes the determinant from the world vertices
    // (`look_at_det`), where the screen vertices' rounding does not enter. Its sign is the
    // SPEC's facing test `(y2 - y0)(x1 - x0) < (y1 - y0)(x2 - x0)`; the fine and backward
    // kernels read it from the setup (`FaceSetup::det`), never recompute it.
    precise float ta = (p1.x - p0.x) * (p2.y - p0.y);
    precise float tb = (p2.x - p0.x) * (p1.y - p0.y);
    precise float screen_det = ta - tb;
    float det = view.projection == PROJ_MATRIX
        ? screen_det
        : look_at_det(view, q0, q1, q2, vec3(p0.z, p1.z, p2.z));
    float clamped = det > 0.0 ? max(det, MIN_DET) : min(det, -MIN_DET);
    // Correctly rounded, as every per-face division here: the setup is per face, and the
    // barycentrics of a pixel near an edge are that sensitive.
    vec3 n0 = vec3(p1.y - p2.y, p2.x - p1.x, p1.x * p2.y - p2.x * p1.y);
    vec3 n1 = vec3(p2.y - p0.y, p0.x - p2.x, p2.x * p0.y - p0.x * p2.y);
    vec3 n2 = vec3(p0.y - p1.y, p1.x - p0.x, p0.x * p1.y - p1.x * p0.y);
    s.inv[0] = vec4(fm_div_rn3(n0, clamped), 0.0);
    s.inv[1] = vec4(fm_div_rn3(n1, clamped), 0.0);
    s.inv[2] = vec4(fm_div_rn3(n2, clamped), 0.0);

    bool finite = finite3(p0) && finite3(p1) && finite3(p2);
    // `reference::is_numerically_degenerate` at f32 rounding, with a wide margin: a face whose
    // screen determinant is within degenerate_k Σ|terms| of its rounding has barycentrics that
    // are noise scaled by the clamp near its supporting line, not bounded by its vertices; it
    // gets the infinite box. Only the box (binning, culling) depends on this flag, never a
    // pixel's value. A face not flagged has both determinants within a few percent of the
    // exact one.
    bool degenerate = !(abs(screen_det) > pc.degenerate_k * (abs(ta) + abs(tb)));
    s.flags = (det < 0.0 ? FACE_FRONT : 0u) | (finite ? FACE_FINITE : 0u)
            | (degenerate ? FACE_DEGENERATE : 0u);

    // `reference::face_screen_bbox_grown`.
    float inf = uintBitsToFloat(0x7f800000u);
    if (degenerate || !finite) {
        s.bbox = vec4(-inf, -inf, inf, inf);
    } else {
        float x0 = min(min(p0.x, p1.x), p2.x);
        float y0 = min(min(p0.y, p1.y), p2.y);
        float x1 = max(max(p0.x, p1.x), p2.x);
        float y1 = max(max(p0.y, p1.y), p2.y);
        vec4 b;
        if (pc.dist == DIST_EUCLIDEAN) {
            b = vec4(x0 - pc.radius, y0 - pc.radius, x1 + pc.radius, y1 + pc.radius);
        } else if (pc.dist == DIST_HARD) {
            b = vec4(x0, y0, x1, y1);
        } else {
            // The triangle scaled about its centroid by 1 + 3√T/s, s = min(|det| / MIN_DET, 1);
            // bary_margin covers the f32 determinant's relative error (below 1/degenerate_k's
            // multiple for any face not flagged degenerate).
            float sc = min(fm_div(abs(det), MIN_DET), 1.0);
            float k = 1.0 + fm_div(3.0 * pc.radius * pc.bary_margin, sc);
            float cx = fm_div(p0.x + p1.x + p2.x, 3.0);
            float cy = fm_div(p0.y + p1.y + p2.y, 3.0);
            b = vec4(cx + k * (x0 - cx), cy + k * (y0 - cy), cx + k * (x1 - cx), cy + k * (y1 - cy));
        }
        // f32 rounding in w and d² is relative to the coordinates' magnitude: pad by it.
        float mag = max(max(max(abs(x0), abs(x1)), max(abs(y0), abs(y1))), 1.0);
        float pad = pc.pad_rel * mag;
        s.bbox = vec4(b.x - pad, b.y - pad, b.z + pad, b.w + pad);
    }
    s.mesh = view.mesh;
    s.det = det;
    // The reciprocals every kernel that loads the face multiplies by, once.
    Face f = face_none();
    f.v[0] = p0;
    f.v[1] = p1;
    f.v[2] = p2;
    f.det = det;
    face_reciprocals(f);
    for (uint k = 0u; k < 3u; ++k) {
        s.v[k].w = f.inv_z[k];
        s.inv[k].w = f.inv_len2[k];
    }
    s.inv_det = f.inv_det;
    setups[id] = s;
}
