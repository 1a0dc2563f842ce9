// Lambertian lighting in world space (SoftRas's, `src/lighting.rs`): L = I_a c_a
// + Σ_l I_l c_l max(0, n · d_l), with n the eps-normalized face normal (surface mode) or vertex
// normal sum (vertex mode). The f32 twin of `Lighting::light` and of the backward's
// `light_grad` and `normalize_eps_grad` (src/raster/reference_grad.rs). Includers bind
// `lights`: the ambient term I_a c_a, then per directional light its direction d_l and its
// I_l c_l (a vec4 each, the fourth float unused).
#ifndef SOFTVK_LIGHTING_GLSL
#define SOFTVK_LIGHTING_GLSL

// `NORMAL_EPS`: SoftRas's `F.normalize(.., eps=1e-6)`.
const float NORMAL_EPS = 1e-6;

// `face_normal_raw`: cross(v2 − v1, v0 − v1), twice the area.
vec3 face_normal_raw(vec3 p0, vec3 p1, vec3 p2) {
    return fm_cross(p2 - p1, p0 - p1);
}

vec3 normalize_eps(vec3 v) {
    return fm_div3(v, max(fm_length3(v), NORMAL_EPS));
}

// `Lighting::light`: the RGB factor for a unit normal over `directionals` lights.
vec3 light_factor(vec3 n, uint directionals) {
    vec3 l = lights[0].rgb;
    for (uint i = 0u; i < directionals; ++i) {
        l += lights[2u + 2u * i].rgb * max(fm_dot3(n, lights[1u + 2u * i].xyz), 0.0);
    }
    return l;
}

// `light_grad`: dL/d(unit normal) from dL/dL.
vec3 light_factor_grad(vec3 n, vec3 d_light, uint directionals) {
    vec3 g = vec3(0.0);
    for (uint i = 0u; i < directionals; ++i) {
        vec3 dir = lights[1u + 2u * i].xyz;
        if (fm_dot3(n, dir) > 0.0) {
            g += dir * fm_dot3(lights[2u + 2u * i].rgb, d_light);
        }
    }
    return g;
}

// `normalize_eps_grad`: dL/dv of v / max(|v|, eps) given dL/d(it).
vec3 normalize_eps_grad(vec3 v, vec3 g) {
    float len = fm_length3(v);
    if (len > NORMAL_EPS) {
        vec3 n = fm_div3(v, len);
        return fm_div3(g - n * fm_dot3(n, g), len);
    }
    return fm_div3(g, NORMAL_EPS);
}

#endif
