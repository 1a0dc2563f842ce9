//! How many loop iterations one invocation of each raster kernel runs, from the real counts:
//! what the host bounds against a driver's loop cap
//! ([`crate::gpu::DeviceInfo::shader_loop_limit`]) to size workgroups, split work or fold it
//! in passes.

/// Lanes of a subgroup that the 64-invocation tiled kernels use, and the 32-bit words of its
/// ballot.
pub(crate) fn subgroup_lanes(subgroup: u32) -> (u64, u64) {
    let lanes = u64::from(subgroup.clamp(1, 64));
    (lanes, u64::from(subgroup.max(1)).div_ceil(32))
}

/// Loop iterations one invocation of `raster_tiled.comp` runs for a tile of `run` faces with
/// subgroups of `subgroup` lanes and workgroups of `workgroup` invocations: per round (one of
/// the `64 / workgroup` pixels it shades) one iteration, per batch of one face per lane one
/// iteration and one per ballot word, and at most one per face of the run.
pub(crate) fn tiled_forward_iterations(run: u64, subgroup: u32, workgroup: u32) -> u64 {
    let (lanes, words) = subgroup_lanes(subgroup);
    let rounds = 64u64.div_ceil(u64::from(workgroup.clamp(1, 64)));
    rounds * (1 + run + run.div_ceil(lanes) * (1 + words)) + 2
}

/// What `grad_tiled.comp` does per kept face besides the screen sums, for its loop count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ColorWork {
    /// Alpha-only upstream: nothing.
    None,
    /// Vertex colours: three more sums.
    Vertex,
    /// Surface texels: one loop over the segment's coloured pixels.
    Texels,
}

/// Loop iterations one invocation of `grad_tiled.comp` runs for a tile of `run` entries when a
/// workgroup of `workgroup` invocations takes at most `faces` of them, with subgroups of
/// `subgroup` lanes: two binary searches over the run (for the chunk's sub-run), then per batch
/// (a subgroup's lanes' faces, every `workgroup` faces of the workgroup's) one iteration, the
/// final writes (3) and per segment of `lanes` pixels one iteration, one per ballot word, and
/// per kept face (at most `lanes`) one iteration, the three screen sums and the colour work.
pub(crate) fn tiled_backward_iterations(
    run: u64,
    tile: u32,
    faces: u64,
    (subgroup, workgroup, color): (u32, u32, ColorWork),
) -> u64 {
    let (lanes, words) = subgroup_lanes(subgroup);
    let segments = (u64::from(tile) * u64::from(tile)).div_ceil(lanes);
    let per_face = 1
        + 3
        + match color {
            ColorWork::None => 0,
            ColorWork::Vertex => 3,
            ColorWork::Texels => words + lanes,
        };
    let search = u64::from(u64::BITS - run.leading_zeros());
    // Per group of 32 segments one iteration, per segment one of the pre-pass that finds those
    // a face touches, and for each of those (at most all) the visits.
    let batch =
        1 + 3 + segments.div_ceil(32) + segments + segments * (1 + words + lanes * per_face);
    2 * search + faces.min(run).div_ceil(u64::from(workgroup.max(1))) * batch + 2
}

/// Loop iterations one invocation of `grad_brute.comp` runs for a band of `rows` rows of
/// `width` pixels.
pub(crate) fn brute_backward_iterations(rows: u64, width: u32) -> u64 {
    rows * (u64::from(width) + 1) + 2
}

/// Loop iterations one invocation of `grad_reduce.comp` runs to add at most `units` partials.
pub(crate) fn reduce_iterations(units: u64) -> u64 {
    units + 2
}

/// Loop iterations one invocation (one face) of `grad_reduce_texels.comp` runs over `views`
/// views and `texels` texels, adding at most `units` partials in all per texel (with masks,
/// a loop over the units for their union first).
pub(crate) fn texel_reduce_iterations(views: u64, units: u64, texels: u64) -> u64 {
    views * (2 + texels) + (texels + 1) * units + 2
}
