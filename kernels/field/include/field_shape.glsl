// Analytic fields for tests: f(p) = −sharpness · sd(p), sd the signed distance (negative inside)
// of a shape whose numbers are the field's parameters:
//   0 sphere (cx, cy, cz, r):           sd = |p − c| − r
//   1 box (cx, cy, cz, hx, hy, hz):     d = |p − c| − h, sd = |max(d, 0)| + min(max_i d_i, 0)
//   2 torus (cx, cy, cz, R, r), axis y: q = (|(p − c).xz| − R, (p − c).y), sd = |q| − r
// shape_sd also gives ∂sd/∂θ_j for every parameter (at most 6). The includer declares
// `params[]`. Twin: `crate::field::shape`.
#ifndef SOFTVK_FIELD_SHAPE_GLSL
#define SOFTVK_FIELD_SHAPE_GLSL

#define SHAPE_MAX_PARAMS 6u

// x / y, or 0 where y is 0 (the measure-zero points where a distance has no gradient).
float shape_ratio(float x, float y) {
    return y > 0.0 ? fm_div(x, y) : 0.0;
}

float shape_sd(uint kind, vec3 p, out float g[SHAPE_MAX_PARAMS]) {
    vec3 c = vec3(params[0], params[1], params[2]);
    vec3 d = p - c;
    for (uint j = 0u; j < SHAPE_MAX_PARAMS; ++j) {
        g[j] = 0.0;
    }
    if (kind == 0u) {
        float len = fm_length3(d);
        g[0] = -shape_ratio(d.x, len);
        g[1] = -shape_ratio(d.y, len);
        g[2] = -shape_ratio(d.z, len);
        g[3] = -1.0;
        return len - params[3];
    }
    if (kind == 1u) {
        vec3 h = vec3(params[3], params[4], params[5]);
        vec3 q = abs(d) - h;
        float m = max(q.x, max(q.y, q.z));
        vec3 dq; // ∂sd/∂q
        float sd;
        if (m > 0.0) {
            vec3 qp = max(q, vec3(0.0));
            float len = fm_length3(qp);
            dq = vec3(shape_ratio(qp.x, len), shape_ratio(qp.y, len), shape_ratio(qp.z, len));
            sd = len;
        } else {
            dq = q.x >= q.y && q.x >= q.z ? vec3(1.0, 0.0, 0.0)
               : (q.y >= q.z ? vec3(0.0, 1.0, 0.0) : vec3(0.0, 0.0, 1.0));
            sd = m;
        }
        vec3 gc = -dq * sign(d);
        g[0] = gc.x;
        g[1] = gc.y;
        g[2] = gc.z;
        g[3] = -dq.x;
        g[4] = -dq.y;
        g[5] = -dq.z;
        return sd;
    }
    float rho = fm_length2(d.xz);
    vec2 q = vec2(rho - params[3], d.y);
    float len = fm_length2(q);
    float nx = shape_ratio(q.x, len);
    float ny = shape_ratio(q.y, len);
    g[0] = -nx * shape_ratio(d.x, rho);
    g[1] = -ny;
    g[2] = -nx * shape_ratio(d.z, rho);
    g[3] = -nx;
    g[4] = -1.0;
    return len - params[4];
}

#endif
