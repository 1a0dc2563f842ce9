// Shared by every softvk kernel. Dispatches larger than maxComputeWorkGroupCount[0] are folded
// into 2D grids by the host (`Recorder::dispatch`), so kernels address work by this linear index.
#ifndef SOFTVK_COMMON_GLSL
#define SOFTVK_COMMON_GLSL

uint linear_group_id() {
    return gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
}

#endif
