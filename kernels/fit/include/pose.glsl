// A rigid pose on the GPU (`src/fit/pose/`): p' = R(ω) (p − c) + c + t, R(ω) = exp([ω]×), and
// the rotation's left Jacobian, in f32. Twins: `rotation_matrix`, `left_jacobian` (f64).
// Where f32 needs another arrangement of the same formula than the f64 twin, it is said here:
// (1 − cos θ) is taken as 2 sin²(θ/2) (no cancellation), and (θ − sin θ)/θ³ from its series
// below θ = 0.5 (the closed form cancels in f32 up to there).
#ifndef SOFTVK_POSE_GLSL
#define SOFTVK_POSE_GLSL

// The parameters: ω at floats [0, 3), t at [pc.translation_at, pc.translation_at + 3) (both
// ranges start at a bindable offset: the two Adam optimizers step them apart).
layout(std430, set = 0, binding = 0) buffer Params { float params[]; };

mat3 cross_matrix(vec3 v) {
    return mat3(vec3(0.0, v.z, -v.y), vec3(-v.z, 0.0, v.x), vec3(v.y, -v.x, 0.0));
}

// R(ω) = I + sin θ/θ [ω]× + (1 − cos θ)/θ² [ω]×².
mat3 rotation_matrix(vec3 w) {
    float t2 = fm_dot3(w, w);
    float t = fm_sqrt(t2);
    float a = 1.0 - fm_div(t2, 6.0);
    float b = 0.5 - fm_div(t2, 24.0);
    if (t >= 1e-3) {
        float s = fm_sin(0.5 * t);
        a = fm_div(fm_sin(t), t);
        b = fm_div(2.0 * s * s, t2);
    }
    mat3 k = cross_matrix(w);
    return mat3(1.0) + a * k + b * fm_mul33m(k, k);
}

// J_l(ω) = I + (1 − cos θ)/θ² [ω]× + (θ − sin θ)/θ³ [ω]×².
mat3 left_jacobian(vec3 w) {
    float t2 = fm_dot3(w, w);
    float t = fm_sqrt(t2);
    float a = 0.5 - fm_div(t2, 24.0);
    float b = fm_div(1.0, 6.0) - fm_div(t2, 120.0) + fm_div(t2 * t2, 5040.0)
            - fm_div(t2 * t2 * t2, 362880.0);
    if (t >= 1e-3) {
        float s = fm_sin(0.5 * t);
        a = fm_div(2.0 * s * s, t2);
    }
    if (t >= 0.5) {
        b = fm_div(t - fm_sin(t), t2 * t);
    }
    mat3 k = cross_matrix(w);
    return mat3(1.0) + a * k + b * fm_mul33m(k, k);
}

#endif
