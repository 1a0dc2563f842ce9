//! Folding a loop too long for one shader invocation into passes.
//!
//! llvmpipe ends a shader invocation's loops after 65 535 iterations in all
//! ([`crate::gpu::DeviceInfo::shader_loop_limit`]). A kernel whose invocations fold a list (a
//! pixel's faces, a ray's anchors, a mask's words) whose length depends on the input runs in
//! passes over consecutive parts of the list where it must, each pass but the last leaving its
//! running state in a buffer for the next: the same elements in the same order, so the same
//! bits as one pass.

/// How many elements of lists of up to `run` one pass takes: `run` itself when one pass stays
/// under the loop cap `limit` (or there is none), else as many as the cap allows, evened out
/// over the passes that needs (`run.div_ceil(per_pass)` of them). `iterations(n)` is one
/// invocation's loop count for a pass of `n` elements (growing with `n`). At least 1.
pub fn pass_size(run: u64, limit: Option<u64>, iterations: impl Fn(u64) -> u64) -> u64 {
    let run = run.max(1);
    let Some(limit) = limit else {
        return run;
    };
    if iterations(run) <= limit {
        return run;
    }
    // The most elements one pass takes, then even passes.
    let (mut lo, mut hi) = (1, run);
    while lo < hi {
        let mid = lo + (hi - lo).div_ceil(2);
        if iterations(mid) <= limit {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    run.div_ceil(run.div_ceil(lo))
}
