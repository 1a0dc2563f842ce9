// Shared by every softvk kernel. Dispatches larger than maxComputeWorkGroupCount[0] are folded
// into 2D grids by the host (`Recorder::dispatch`), so kernels address work by this linear index.
#ifndef SOFTVK_COMMON_GLSL
#define SOFTVK_COMMON_GLSL

// softvk's own maths, for every kernel: no builtin whose result a driver chooses.
#include "fmath.glsl"

uint linear_group_id() {
    return gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
}

// Word i of a texel buffer read as uvec4 texels, four words a texel (the (anchor, tile)
// entries of sphere probing). `i` is evaluated twice: pass a plain value.
#define ENTRY_WORD(texels, i) (imageLoad(texels, int((i) >> 2u))[(i) & 3u])

#endif
