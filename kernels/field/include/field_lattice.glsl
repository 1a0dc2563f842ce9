// The lattice marching cubes samples: res nodes per axis over the cube, node (x, y, z) at index
// x + res (y + res z) and position c + h (2 (x, y, z) / (res − 1) − 1), so the cube's faces are
// lattice planes. Twin: `crate::field::mcubes::cpu::lattice_point`.
#ifndef SOFTVK_FIELD_LATTICE_GLSL
#define SOFTVK_FIELD_LATTICE_GLSL

uvec3 lattice_coords(uint node, uint res) {
    return uvec3(node % res, (node / res) % res, node / (res * res));
}

vec3 lattice_point(uvec3 q, vec4 cube, uint res) {
    return cube.xyz + cube.w * (fm_div3(2.0 * vec3(q), float(res - 1u)) - 1.0);
}

#endif
