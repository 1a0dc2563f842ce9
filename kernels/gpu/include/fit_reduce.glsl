// The fixed-order workgroup reduction of the fit kernels (`kernels/fit/fit/`). Each invocation of a
// 256-wide workgroup hands in its own partial (a sequential sum over a fixed stride); the tree
// then adds element t + s into t for s = 128, 64, ..., 1. The order depends only on the
// workgroup size, never on timing: repeated runs are bit-identical. No float atomics.
#ifndef SOFTVK_FIT_REDUCE_GLSL
#define SOFTVK_FIT_REDUCE_GLSL

#define FIT_REDUCE_SIZE 256u

shared vec4 fit_reduce_shared[FIT_REDUCE_SIZE];

// Call from uniform control flow with every invocation of the workgroup; all get the sum.
vec4 workgroup_sum(vec4 x) {
    uint t = gl_LocalInvocationIndex;
    fit_reduce_shared[t] = x;
    barrier();
    for (uint s = FIT_REDUCE_SIZE / 2u; s > 0u; s >>= 1u) {
        if (t < s) {
            fit_reduce_shared[t] += fit_reduce_shared[t + s];
        }
        barrier();
    }
    return fit_reduce_shared[0];
}

#endif
