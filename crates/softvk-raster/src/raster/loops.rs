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

#[cfg(test)]
mod tests {
    use super::{tiled_backward_iterations, tiled_forward_iterations};
    use crate::camera::Camera;
    use crate::gpu::Context;
    use crate::lighting::Lighting;
    use crate::mesh::Mesh;
    use crate::raster::backward::{GradBuffers, GradKernels};
    use crate::raster::binned::Binned;
    use crate::raster::gpu::Renderer;
    use crate::raster::method::Method;
    use crate::raster::scene::GpuScene;
    use crate::raster::settings::RasterSettings;

    /// `faces` triangles far larger than the view, one behind the other: every face touches
    /// every pixel, so every tile's run is every face and each kernel loop runs its most.
    fn stacked(faces: u32) -> Mesh {
        let mut positions = Vec::new();
        for i in 0..faces {
            let z = -0.5 + i as f32 / faces as f32;
            positions.extend([[-8.0, -8.0, z], [8.0, -8.0, z], [0.0, 8.0, z]]);
        }
        let tris = (0..faces).map(|i| [3 * i, 3 * i + 1, 3 * i + 2]).collect();
        Mesh::new(positions, tris, 1).unwrap()
    }

    /// Views of every test scene: front and back (faces are double-sided), so the stacked
    /// faces fill both.
    const VIEWS: usize = 2;

    /// `mesh` on the GPU in two views of `size`² (no image edge inside an 8×8 block).
    fn scene(ctx: &Context, renderer: &Renderer, mesh: &Mesh, size: u32) -> GpuScene {
        assert_eq!(size % 8, 0);
        let settings = RasterSettings {
            width: size,
            height: size,
            ..RasterSettings::default()
        };
        let cameras: [Camera; VIEWS] = [Camera::default(), Camera::from_angles(2.732, 0.0, 180.0)];
        renderer
            .prepare(ctx, mesh, &cameras, &Lighting::unlit(), &settings)
            .unwrap()
    }

    /// The [start, end) of every tile's run of sorted entries, after a tiled run (tile 8) that
    /// binned both views in one group: tile t of view v is range v · tiles per view + t.
    fn tile_ranges(ctx: &Context, binned: &Binned<'_>, size: u32) -> Vec<[u32; 2]> {
        let [group] = binned.groups() else {
            panic!("one view group expected")
        };
        assert_eq!((group.first, group.views as usize), (0, VIEWS));
        let tiles = VIEWS * ((size / 8) * (size / 8)) as usize;
        ctx.read_buffer(binned.bins[0].ranges(), 0, tiles).unwrap()
    }

    /// What the kernel counted for one 8×8 tile, and the tile's run of binned faces.
    struct Tile {
        run: u64,
        /// The most loop iterations an invocation of the tile's had run when it wrote a pixel:
        /// its total, at its last pixel.
        iterations: u64,
        /// Faces shaded, summed over the tile's pixels.
        shaded: u64,
    }

    /// Renders `mesh` tiled ([`scene`]; alpha only if `silhouette`) with the forward counting
    /// its loops: what it counted per tile, the workgroup the host chose, and the host's count
    /// of visited (pixel, face) pairs.
    fn counted(ctx: &Context, mesh: &Mesh, size: u32, silhouette: bool) -> (Vec<Tile>, u32, u64) {
        let renderer = Renderer::new(ctx).unwrap().counting_loops();
        let mut scene = scene(ctx, &renderer, mesh, size);
        scene.set_silhouette_only(silhouette);
        let run = renderer
            .run(ctx, &mut scene, Method::Tiled { tile: 8 })
            .unwrap();
        let binned = run.binned();
        let pairs = binned.pair_counts(ctx).unwrap().forward;
        let per_row = size / 8;
        let per_view = (per_row * per_row) as usize;
        let mut tiles: Vec<Tile> = tile_ranges(ctx, &binned, size)
            .iter()
            .map(|r| Tile {
                run: u64::from(r[1] - r[0]),
                iterations: 0,
                shaded: 0,
            })
            .collect();
        let pixels = (size * size) as usize;
        let image: Vec<[f32; 4]> = ctx
            .read_buffer(&binned.scene.image, 0, VIEWS * pixels)
            .unwrap();
        for (i, p) in image.iter().enumerate() {
            let (view, row, col) = (i / pixels, (i % pixels) as u32 / size, i as u32 % size);
            let t = &mut tiles[view * per_view + ((row / 8) * per_row + col / 8) as usize];
            t.iterations = t.iterations.max(p[0] as u64);
            t.shaded += p[1] as u64;
        }
        let max_run = binned.groups()[0].max_tile_entries;
        let workgroup = crate::raster::fine::tiled_forward_workgroup(ctx, max_run);
        (tiles, workgroup, pairs)
    }

    /// The tiled forward's loop bound (what the host holds to llvmpipe's cap of 65 535
    /// iterations an invocation) and its visited-pair count are the kernel's own counts: a
    /// change to `raster_tiled.comp`'s loops or to `tiled_forward_iterations` /
    /// `Binned::pair_counts` without the other fails here.
    #[test]
    fn the_forward_loop_bound_and_pair_counts_are_what_the_kernel_counts() {
        let Some(ctx) = softvk_testing::gpu() else {
            return;
        };
        let subgroup = ctx.info().subgroup_size;
        // Every face touches every pixel: the bound is reached in every tile, but for its
        // margin of 2.
        for faces in [1, 7, 40] {
            let (tiles, workgroup, pairs) = counted(&ctx, &stacked(faces), 16, false);
            for t in &tiles {
                assert_eq!(t.run, u64::from(faces));
                assert_eq!(
                    t.iterations + 2,
                    tiled_forward_iterations(t.run, subgroup, workgroup),
                    "{faces} faces, workgroup {workgroup}"
                );
                assert_eq!(t.shaded, 64 * t.run);
            }
            assert_eq!(tiles.iter().map(|t| t.shaded).sum::<u64>(), pairs);
        }
        // A real mesh, whose faces touch some subgroups' pixels and not others: the bound
        // holds, and the host counts the pairs the kernel shaded.
        let (tiles, workgroup, pairs) = counted(&ctx, &Mesh::icosphere(2), 32, false);
        assert!(tiles.iter().any(|t| t.run > 1 && t.shaded < 64 * t.run));
        for t in &tiles {
            assert!(t.iterations + 2 <= tiled_forward_iterations(t.run, subgroup, workgroup));
        }
        assert_eq!(tiles.iter().map(|t| t.shaded).sum::<u64>(), pairs);
    }

    /// A silhouette render on a CPU device folds each batch into every segment of its block
    /// (`raster_tiled.comp`'s alpha-only path): fewer iterations than the general path's
    /// bound, which the host still holds it to, and the same visited pairs.
    #[test]
    fn the_silhouette_forward_stays_within_the_loop_bound_and_visits_the_same_pairs() {
        let Some(ctx) = softvk_testing::gpu() else {
            return;
        };
        let subgroup = ctx.info().subgroup_size;
        for (mesh, size) in [(stacked(40), 16), (Mesh::icosphere(2), 32)] {
            let (tiles, workgroup, pairs) = counted(&ctx, &mesh, size, true);
            let (general, _, general_pairs) = counted(&ctx, &mesh, size, false);
            for (t, g) in tiles.iter().zip(&general) {
                assert_eq!((t.run, t.shaded), (g.run, g.shaded));
                assert!(t.iterations + 2 <= tiled_forward_iterations(t.run, subgroup, workgroup));
                // One subgroup a workgroup (a CPU device): the swapped loops ran, one batch
                // iteration for every segment's of the general path.
                if workgroup == subgroup && t.run > 0 {
                    assert!(
                        t.iterations < g.iterations,
                        "{} vs {}",
                        t.iterations,
                        g.iterations
                    );
                }
            }
            assert_eq!(pairs, general_pairs);
            assert_eq!(tiles.iter().map(|t| t.shaded).sum::<u64>(), pairs);
        }
    }

    /// The tiled backward's loop bound holds the iterations its kernel counts (those of the
    /// loops whose trip counts depend on the input: the slot searches, the batches, the
    /// groups and segments visited, the ballot words and kept faces; the loops of constant
    /// trip counts, the compiler's to unroll, are not counted), and the host counts the
    /// (segment, face) pairs the kernel evaluates. The bound also counts the constant loops
    /// of every kept face (the screen sums, the texel search) as if they were not unrolled:
    /// on 40 stacked faces at 8 lanes it is 4 319 where the kernel counts 445.
    #[test]
    fn the_backward_loop_bound_and_pair_counts_hold_what_the_kernel_counts() {
        let Some(ctx) = softvk_testing::gpu() else {
            return;
        };
        let subgroup = ctx.info().subgroup_size;
        let lanes = u64::from(subgroup.clamp(1, 64));
        let counting = GradKernels::new(&ctx).unwrap().counting_loops();
        // Alpha only too: `grad_tiled.comp`'s per-segment path on tiles of 8 (every segment's
        // upstream loaded once per tile) counts its own loops.
        for (mesh, size, dense, alpha_only) in [
            (stacked(1), 16, true, false),
            (stacked(40), 16, true, false),
            (Mesh::icosphere(2), 32, false, false),
            (stacked(40), 16, true, true),
            (Mesh::icosphere(2), 32, false, true),
        ] {
            let renderer = Renderer::new(&ctx).unwrap();
            let mut scene = scene(&ctx, &renderer, &mesh, size);
            let run = renderer
                .run(&ctx, &mut scene, Method::Tiled { tile: 8 })
                .unwrap();
            let binned = run.binned();
            let pairs = binned.pair_counts(&ctx).unwrap().backward;
            let mut gb = GradBuffers::new(&ctx, &binned).unwrap();
            gb.set_alpha_only(alpha_only);
            let pixels = (size * size) as usize * VIEWS;
            gb.set_d_image(&ctx, binned.scene, &vec![[1.0; 4]; pixels])
                .unwrap();
            ctx.submit_and_wait(|rec| counting.record(rec, &binned, &gb, &gb.io()))
                .unwrap();
            let ranges = tile_ranges(&ctx, &binned, size);
            let entries = binned.entries() as usize;
            let slots: Vec<u32> = ctx
                .read_buffer(binned.bins[0].entries(), 0, entries)
                .unwrap();
            let vec4s = (gb.stride / 4) as usize;
            let partials: Vec<[f32; 4]> =
                ctx.read_buffer(&gb.partials, 0, entries * vec4s).unwrap();
            let work = (
                subgroup,
                crate::raster::fine::tiled_backward_workgroup(&ctx),
                gb.color_work(binned.scene),
            );
            let mut kept = 0;
            for r in &ranges {
                let run = u64::from(r[1] - r[0]);
                let counts: Vec<[f32; 4]> = slots[r[0] as usize..r[1] as usize]
                    .iter()
                    .map(|&s| partials[s as usize * vec4s])
                    .collect();
                let most = counts.iter().map(|c| c[0] as u64).max().unwrap_or(0);
                assert!(
                    most <= tiled_backward_iterations(run, 8, run, work),
                    "run {run}"
                );
                kept += counts.iter().map(|c| c[1] as u64).sum::<u64>();
                if dense {
                    // Every face is kept in each of the tile's segments.
                    assert!(counts.iter().all(|c| c[1] as u64 == 64u64.div_ceil(lanes)));
                }
            }
            if alpha_only {
                // The per-segment path keeps a face wherever its box meets the box of the
                // segment's live pixel centres; the general path (which the host counts) also
                // skips a segment none of whose pixel centres lies in the face's box in x or
                // in y, where the face adds nothing: a superset, the same sums.
                assert!(lanes * kept >= pairs, "{} < {pairs}", lanes * kept);
            } else {
                assert_eq!(lanes * kept, pairs);
            }
        }
    }
}
