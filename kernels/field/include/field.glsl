// Shared by the implicit-field kernels (`kernels/field/field/`): φ = sigmoid(f) of a logit f, and points
// normalised to the field's bounding cube. Twin: `crate::field::cpu`.
#ifndef SOFTVK_FIELD_GLSL
#define SOFTVK_FIELD_GLSL

float field_sigmoid(float f) {
    return fm_sigmoid(f);
}

// `cube` = (centre, half-size): the cube [-1, 1]^3 after normalisation.
vec3 field_normalize(vec3 p, vec4 cube) {
    return fm_div3(p - cube.xyz, cube.w);
}

#endif
