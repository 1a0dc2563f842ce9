// Sphere probing (SPEC §5), shared by the kernels of `kernels/field/probe/`: the structs the host
// writes (twins in `src/probe/`), the counter-based random numbers of the sampler, the ray of a
// sample and its hit test, and the aggregation G of a ray's hits.
//
// Every operation that decides something discrete (which pixel, which anchor a ray hits, which
// tile) is an add, a subtract or a multiply marked `precise`: Vulkan rounds those correctly and
// `precise` forbids fused multiply-adds, so the CPU twins reproduce every decision bit for bit.
#ifndef SOFTVK_PROBE_GLSL
#define SOFTVK_PROBE_GLSL

// Twin of `ProbeView` (src/probe/targets.rs); 160 bytes. Screen position of a world point p:
// (a0·(p, 1) / a2·(p, 1), a1·(p, 1) / a2·(p, 1)); depth: depth·(p, 1). The line of points that
// project to screen point s is o0 + s.x ox + s.y oy + t (d0 + s.x dx + s.y dy).
// Texels (uvec4) of a `ProbeView` read as a texel buffer: a0, a1, a2, depth, ... in order.
#define PROBE_VIEW_TEXELS 10u
struct ProbeView {
    vec4 a0;
    vec4 a1;
    vec4 a2;
    vec4 depth;
    vec4 o0;
    vec4 ox;
    vec4 oy;
    vec4 d0;
    vec4 dx;
    vec4 dy;
};

// Twin of `Ray` (src/probe/sampler.rs); 16 bytes. (px, py): continuous pixel position, column
// and row from the top-left corner of the image; label: the silhouette at its pixel (0 or 1).
struct Ray {
    float px;
    float py;
    uint view;
    float label;
};

// Twin of `RayOut` (src/probe/prober/); 16 bytes. aux: max and LSE: the anchor of the
// largest φ (the first on a tie); union: the count of hits whose 1 − φ is 0; NO_HIT without
// hits. aux_f: union: the product of the
// other (nonzero) 1 − φ.
struct RayOut {
    float psi;
    float err2;
    uint aux;
    float aux_f;
};

// An anchor in one view, as the items kernel writes it for the binning (`ItemLayout`: stride 8
// words, box at 0, flags at 4). Twin of `ProbeItem` (src/probe/prober/); 32 bytes.
struct ProbeItem {
    vec4 box;    // screen box (x_min, y_min, x_max, y_max) of the anchor's sphere
    uint flags;  // FLAG_*
    float sx;    // the centre's screen position
    float sy;
    float depth; // the centre's depth
};
#define FLAG_VALID 1u  // every corner of the anchor's τ-cube is in front of the camera
#define FLAG_INSIDE 2u // the centre projects into the silhouette

#define AGG_MAX 0u
#define AGG_LSE 1u
#define AGG_UNION 2u
#define NO_HIT 0xFFFFFFFFu

// PCG hash (Jarzynski and Olano 2020, "Hash functions for GPU rendering"): a bijection of u32.
// Twin: `probe::rng::pcg_hash`.
uint pcg_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// The `draw`-th random word (draw < 8) of sample `index` of the stream with key `key`.
uint rand_u32(uint key, uint index, uint draw) {
    return pcg_hash(key ^ pcg_hash(index * 8u + draw));
}

// Uniform in [0, 1), exactly representable.
float unit_float(uint h) {
    return float(h >> 8u) * (1.0 / 16777216.0);
}

// Uniform in (0, 1] (a logarithm's argument).
float unit_float_open0(uint h) {
    return float((h >> 8u) + 1u) * (1.0 / 16777216.0);
}

// floor(h · n / 2^32): an index uniform in [0, n).
uint scale_u32(uint h, uint n) {
    uint hi;
    uint lo;
    umulExtended(h, n, hi, lo);
    return hi;
}

// a·(p, 1), in the twin's order.
float affine(vec4 a, vec3 p) {
    precise float r = a.x * p.x + a.y * p.y + a.z * p.z + a.w;
    return r;
}

// Screen coordinates of a continuous pixel position: x_s = (2 px − W) / S, y_s = (H − 2 py) / S
// (pixel centres land on the SPEC's pixel centres), with 1/S from the host.
vec2 pixel_to_screen(float px, float py, float w, float h, float inv_s) {
    precise float sx = (2.0 * px - w) * inv_s;
    precise float sy = (h - 2.0 * py) * inv_s;
    return vec2(sx, sy);
}

// The ray (a line) of screen point s in view v: origin and (unnormalized) direction.
void view_ray(ProbeView v, vec2 s, out vec3 o, out vec3 d) {
    precise vec3 oo = v.o0.xyz + s.x * v.ox.xyz + s.y * v.oy.xyz;
    precise vec3 dd = v.d0.xyz + s.x * v.dx.xyz + s.y * v.dy.xyz;
    o = oo;
    d = dd;
}

// τ² of a ray with `label`: inside rays use τ, outside rays their own radius (`tau_outside`).
float ray_tau2(float label, float tau2, float tau2_outside) {
    return label >= 0.5 ? tau2 : tau2_outside;
}

// τ² |d|², the right-hand side of the hit test.
float hit_bound(vec3 d, float tau2) {
    precise float dd = d.x * d.x + d.y * d.y + d.z * d.z;
    precise float b = tau2 * dd;
    return b;
}

// Does the line (o, d) pass within τ of p: |(p − o) × d|² < τ² |d|².
bool ray_hits(vec3 o, vec3 d, float bound, vec3 p) {
    precise vec3 v = p - o;
    precise float cx = v.y * d.z - v.z * d.y;
    precise float cy = v.z * d.x - v.x * d.z;
    precise float cz = v.x * d.y - v.y * d.x;
    precise float c2 = cx * cx + cy * cy + cz * cz;
    return c2 < bound;
}

// The tile (view-major over all views) holding continuous pixel position (px, py).
uint ray_tile(Ray r, uint width, uint height, uint tile_size, uint tiles_x, uint tiles_y) {
    uint col = min(uint(r.px), width - 1u);
    uint row = min(uint(r.py), height - 1u);
    return r.view * tiles_x * tiles_y + (row / tile_size) * tiles_x + col / tile_size;
}

// The aggregation G of a ray's hits, one hit at a time, in anchor order.
struct Agg {
    float m;     // max / LSE: the running maximum
    float s;     // LSE: Σ exp((φ − m) / T); union: Π of the nonzero (1 − φ)
    uint aux;    // max, LSE: the anchor of the maximum; union: the count of zero (1 − φ)
    uint count;  // hits
};

Agg agg_init(uint mode) {
    return Agg(0.0, 1.0, mode == AGG_UNION ? 0u : NO_HIT, 0u);
}

void agg_add(inout Agg g, uint mode, float inv_t, float phi, uint anchor) {
    if (mode == AGG_MAX) {
        if (g.count == 0u || phi > g.m) {
            g.m = phi;
            g.aux = anchor;
        }
    } else if (mode == AGG_LSE) {
        if (g.count == 0u) {
            g.m = phi;
            g.s = 1.0;
            g.aux = anchor;
        } else if (phi > g.m) {
            g.s = g.s * fm_exp((g.m - phi) * inv_t) + 1.0;
            g.m = phi;
            g.aux = anchor;
        } else {
            g.s += fm_exp((phi - g.m) * inv_t);
        }
    } else {
        float f = 1.0 - phi;
        if (f == 0.0) {
            g.aux += 1u;
        } else {
            g.s *= f;
        }
    }
    g.count += 1u;
}

// ψ and the ray's state for the backward (no hit: ψ = 0, aux = NO_HIT).
RayOut agg_finish(Agg g, uint mode, float temperature, float label) {
    RayOut r;
    r.aux = g.aux;
    r.aux_f = 0.0;
    if (g.count == 0u) {
        r.psi = 0.0;
        r.aux = NO_HIT;
    } else if (mode == AGG_MAX) {
        r.psi = g.m;
    } else if (mode == AGG_LSE) {
        r.psi = g.m + temperature * fm_log(g.s);
    } else {
        r.psi = g.aux > 0u ? 1.0 : 1.0 - g.s;
        r.aux_f = g.s;
    }
    float e = r.psi - label;
    r.err2 = e * e;
    return r;
}

// dψ/dφ of one hit anchor with value `phi`, given the ray's forward result.
float agg_grad(RayOut r, uint mode, float inv_t, float phi) {
    if (mode == AGG_LSE) {
        return fm_exp((phi - r.psi) * inv_t);
    }
    // Union: Π over the other hits of (1 − φ).
    float f = 1.0 - phi;
    if (r.aux == 0u) {
        return fm_div(r.aux_f, f);
    }
    if (r.aux == 1u && f == 0.0) {
        return r.aux_f;
    }
    return 0.0;
}

#endif
