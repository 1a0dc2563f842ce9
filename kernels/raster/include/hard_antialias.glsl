// nvdiffrast's `antialias` (`softvk::raster::hard::gpu`), what its kernels share: the work list's
// records and the pixel frame. Twin: `src/raster/hard/antialias/` (f64), whose module docs give
// every rule; the kernels follow it operation for operation in f32 on softvk's maths.
//
// The work list (`hard_antialias_pairs.comp`) holds per pixel i = (b·H + y)·W + x one uvec4:
// (α bits, info) of its right pair (pixel 0 = i, pixel 1 = i + 1) then (α bits, info) of its
// next-row pair (pixel 1 = i + W). info 0: the pair is not blended (or does not exist, past the
// last column or row); else bit 0 set, bit 1 the triangle is pixel 1's (σ = −1), bits 2–3 the
// edge k (the one opposite vertex k, from vertex k + 1 to k + 2, mod 3). The triangle is the id of
// the pixel it was taken from (rast's fourth channel − 1).
#ifndef SOFTVK_HARD_ANTIALIAS_GLSL
#define SOFTVK_HARD_ANTIALIAS_GLSL

// No opposite vertex across an edge (the host's topology buffer).
const uint AA_NO_VERTEX = 0xFFFFFFFFu;

bool aa_blended(uint info) {
    return (info & 1u) != 0u;
}

bool aa_from_second(uint info) {
    return (info & 2u) != 0u;
}

uint aa_edge(uint info) {
    return (info >> 2) & 3u;
}

// The pixel changed by a pair with weight α: pixel 0 when α > 0, else pixel 1.
bool aa_targets_first(float alpha) {
    return alpha > 0.0;
}

#ifndef HARD_NO_POSITIONS
// Clip-space position of vertex v of minibatch item b's set.
vec4 aa_vertex(uint b, uint v) {
    if (pc.instanced != 0u) {
        v += b * pc.vertex_count;
    }
    return vec4(pos[4u * v], pos[4u * v + 1u], pos[4u * v + 2u], pos[4u * v + 3u]);
}

// `pixel_frame`: p in pixel units relative to the centre of pixel (cx, cy),
// ((X · (1/W_c)) · W/2 − (cx + 1/2 − W/2), likewise y); 1/W_c correctly rounded.
vec2 aa_frame(vec4 p, uint cx, uint cy) {
    precise float hx = 0.5 * float(pc.width);
    precise float hy = 0.5 * float(pc.height);
    float inv_w = fm_div_rn(1.0, p.w);
    precise float ox = (float(cx) + 0.5) - hx;
    precise float oy = (float(cy) + 0.5) - hy;
    precise float fx = (p.x * inv_w) * hx - ox;
    precise float fy = (p.y * inv_w) * hy - oy;
    return vec2(fx, fy);
}
#endif

#endif
