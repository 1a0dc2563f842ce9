// The dense grid field: res^3 logits at the lattice nodes x_i = c + h (2 i / (res - 1) - 1) of the
// cube (cell corners; the cube's own corners are nodes), node (x, y, z) at index
// x + res (y + res z); trilinear inside the cube, and a point outside takes the value of the
// nearest point of the cube (clamped grid coordinates). The includer declares `params[]`
// (unless it defines GRID_NO_PARAMS).
// Twin: `crate::field::cpu` (`grid_locate`, `grid_weights`).
#ifndef SOFTVK_FIELD_GRID_GLSL
#define SOFTVK_FIELD_GRID_GLSL

// The cell (in [0, res - 2]^3) and the fractions t in [0, 1]^3 of `p`. The cell is clamped as
// integers too, so even a NaN point never indexes out of bounds.
void grid_locate(vec3 p, vec4 cube, uint res, out uvec3 cell, out vec3 t) {
    float r1 = float(res - 1u);
    vec3 g = clamp((field_normalize(p, cube) + 1.0) * (0.5 * r1), vec3(0.0), vec3(r1));
    vec3 f = min(floor(g), vec3(r1 - 1.0));
    cell = min(uvec3(max(f, vec3(0.0))), uvec3(res - 2u));
    t = g - vec3(cell);
}

// Trilinear weights of the cell's corners k = x + 2 y + 4 z: k = 0..3 in `lo`, 4..7 in `hi`.
void grid_weights(vec3 t, out vec4 lo, out vec4 hi) {
    vec3 u = 1.0 - t;
    vec4 xy = vec4(u.x * u.y, t.x * u.y, u.x * t.y, t.x * t.y);
    lo = xy * u.z;
    hi = xy * t.z;
}

// GRID_NO_PARAMS: the includer only needs the weights (and has no `params[]`).
#ifndef GRID_NO_PARAMS
uint grid_node(uvec3 cell, uint k, uint res) {
    uvec3 v = cell + uvec3(k & 1u, (k >> 1u) & 1u, (k >> 2u) & 1u);
    return v.x + res * (v.y + res * v.z);
}

float grid_logit(uvec3 cell, vec3 t, uint res) {
    vec4 lo, hi;
    grid_weights(t, lo, hi);
    vec4 v_lo = vec4(params[grid_node(cell, 0u, res)], params[grid_node(cell, 1u, res)],
                     params[grid_node(cell, 2u, res)], params[grid_node(cell, 3u, res)]);
    vec4 v_hi = vec4(params[grid_node(cell, 4u, res)], params[grid_node(cell, 5u, res)],
                     params[grid_node(cell, 6u, res)], params[grid_node(cell, 7u, res)]);
    return fm_dot4(lo, v_lo) + fm_dot4(hi, v_hi);
}
#endif

#endif
