// Broadcasting one lane's face or pixel to its whole subgroup, one shuffle per 32-bit word: how
// the tiled kernels share work without shared memory or barriers. (On llvmpipe a barrier is a
// coroutine switch per 8-lane vector, and a load inside a loop is a scalar loop over the lanes,
// while a shuffle is one permute.) Includers enable GL_KHR_shader_subgroup_shuffle.
#ifndef SOFTVK_SUBGROUP_FACE_GLSL
#define SOFTVK_SUBGROUP_FACE_GLSL

#include "raster.glsl"

// Lane `i`'s face.
Face face_shuffle(Face f, uint i) {
    Face g;
    g.v[0] = subgroupShuffle(f.v[0], i);
    g.v[1] = subgroupShuffle(f.v[1], i);
    g.v[2] = subgroupShuffle(f.v[2], i);
    g.inv[0] = subgroupShuffle(f.inv[0], i);
    g.inv[1] = subgroupShuffle(f.inv[1], i);
    g.inv[2] = subgroupShuffle(f.inv[2], i);
    g.bbox = subgroupShuffle(f.bbox, i);
    g.flags = subgroupShuffle(f.flags, i);
    g.mesh = subgroupShuffle(f.mesh, i);
    return g;
}

// Lanes this subgroup has in the workgroup: at most the workgroup's size (a subgroup may be
// wider than a 64-invocation workgroup). Never assume a size: 8 on llvmpipe with AVX2, 32 on
// NVIDIA, 64 or 32 on AMD.
uint subgroup_lanes(uint workgroup_size) {
    return min(gl_SubgroupSize, workgroup_size);
}

// Words of a subgroup ballot in use.
uint ballot_words() {
    return (gl_SubgroupSize + 31u) / 32u;
}

#endif
