//! What the two fine passes share (`kernels/raster/include/raster_fine.glsl`): the push constants, the
//! per-pixel [`PixelAux`] kept for the backward pass, and the tiled fine pass itself
//! (`kernels/raster/raster/raster_tiled.comp`), which visits per 8×8 block only the faces binned to its
//! tile ([`crate::primitives::binning`]) and is bit for bit the brute-force pass
//! ([`crate::raster::brute`]).

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::gpu::{Context, KernelVariants, Recorder, pass_size};
use crate::primitives::TileGrid;
use crate::raster::loops::tiled_forward_iterations;
use crate::raster::method::Method;
use crate::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};
use crate::raster::setup::dist_code;
use crate::raster::specs;

/// Per-pixel forward state kept for the backward pass. Twin of `PixelAux` in
/// `raster_fine.glsl` (and of `reference`'s); std430, 32 bytes, one per *rendered* pixel (at 2× with anti-aliasing),
/// view-major then row-major like the image.
///
/// With the softmax colour, `I = rgb_scaled / softmax_sum` where every term was scaled by
/// `e^{-max/γ}` and `max = (far − softmax_ref_depth) / (far − near)`: a face j at depth `z_j` with
/// coverage `D_j` has weight `D_j e^{(softmax_ref_depth − z_j) / (γ (far − near))} / softmax_sum`
/// in the pixel, and the background `e^{(softmax_ref_depth − z_b)/(γ (far − near))} / softmax_sum`
/// with `z_b = far − ε (far − near)`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PixelAux {
    /// The depth whose z̄ is the softmax's running maximum (the background's `far − ε (far −
    /// near)` when no face is nearer).
    pub softmax_ref_depth: f32,
    /// The softmax denominator `Σ_j D_j e^{(z̄_j − max)/γ} + e^{(ε − max)/γ}`.
    pub softmax_sum: f32,
    /// Alpha's running aggregate: prod `Π(1 − D_j)` over the factors that are not exactly 0,
    /// sum `Σ D_j`, hard 0 or 1.
    pub alpha_acc: f32,
    /// Alpha prod: how many factors `1 − D_j` were exactly 0 (then the alpha is 1, and
    /// `∂A/∂D_j` is the product of the others: `alpha_acc` for the one zero factor, if alone).
    pub alpha_zeros: u32,
    /// Hard colour: the index of the face whose colour the pixel shows, or `u32::MAX` for the
    /// background.
    pub hard_face: u32,
    /// std430 padding.
    pub pad: [u32; 3],
}

/// Push constants of both fine kernels. Twin of `Push` in `raster_fine.glsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct RasterPush {
    pub width: u32,
    pub height: u32,
    pub face_count: u32,
    pub view_count: u32,
    /// 1 / σ, taken in f64 and rounded once.
    pub inv_sigma: f32,
    pub cutoff: f32,
    pub near: f32,
    pub far: f32,
    pub inv_gamma_range: f32,
    pub background_depth: f32,
    pub texture_res: u32,
    pub first_view: u32,
    pub background: [f32; 4],
    pub tile_size: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub vertex_count: u32,
    pub out_width: u32,
    pub out_height: u32,
    pub entry_total: u32,
    pub grad_stride: u32,
    pub first_row: u32,
}

/// Push constants of the forward fine kernels: the shared ones, then the pass's part of each
/// pixel's face list (`CARRY` in `raster_fine.glsl`). Twin of `Push` without `FINE_BACKWARD`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct ForwardPush {
    pub fine: RasterPush,
    pub pass_begin: u32,
    pub pass_end: u32,
}

/// Bytes of one pixel's running state between passes (`PixelCarry` in `raster_fine.glsl`).
pub(crate) const CARRY_BYTES: u64 = 64;

/// Records `passes` dispatches of a forward kernel, each over its part of the face lists
/// (`per_pass` faces) with a barrier between: what [`pass_size`] planned.
pub(crate) fn dispatch_passes(
    rec: &mut Recorder<'_>,
    kernel: &crate::gpu::Kernel,
    bindings: &[crate::gpu::BufferRange<'_>],
    fine: RasterPush,
    (passes, per_pass): (u64, u64),
    groups: u32,
) -> Result<()> {
    for pass in 0..passes {
        if pass > 0 {
            rec.barrier();
        }
        let bound = |k: u64| u32::try_from(k * per_pass).unwrap_or(u32::MAX);
        let push = ForwardPush {
            fine,
            pass_begin: bound(pass),
            pass_end: bound(pass + 1),
        };
        rec.dispatch(kernel, bindings, &push, groups)?;
    }
    Ok(())
}

const FLAG_DOUBLE_SIDED: u32 = 1;
const FLAG_VERTEX_COLORS: u32 = 2;
const FLAG_CULL: u32 = 4;
const FLAG_ANTIALIAS: u32 = 8;
const FLAG_ALPHA_ONLY: u32 = 16;
const FLAG_TEXEL_MASKS: u32 = 32;

/// The most texels a face may have for the backward's partials to carry a mask of the texel
/// slots they wrote (one 32-bit word) instead of arriving zeroed.
pub(crate) const MAX_MASKED_TEXELS: u32 = 32;

/// The fine kernels' modes: their specialization constants (`MODE_*` in `raster_fine.glsl`), one
/// pipeline per combination ([`crate::gpu::KernelVariants`]). Only the modes a render uses are
/// compiled into its kernels, which on llvmpipe halves the cost of a (pixel, face) pair: there a
/// branch never skips work, so a mode read at run time costs every mode's code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) struct FineModes {
    dist: u32,
    rgb: u32,
    alpha: u32,
    flags: u32,
}

impl FineModes {
    /// The modes of `s`; `cull` skips a face outside its grown box at a pixel (the tiled
    /// kernels always do; the box is conservative, so no pixel changes).
    pub fn new(s: &RasterSettings, cull: bool) -> Self {
        let mut flags = 0;
        if s.double_sided {
            flags |= FLAG_DOUBLE_SIDED;
        }
        if s.color_mode == ColorMode::Vertex {
            flags |= FLAG_VERTEX_COLORS;
        }
        if cull {
            flags |= FLAG_CULL;
        }
        // Only the backward reads it (the upstream gradient is at the output's size).
        if s.antialias {
            flags |= FLAG_ANTIALIAS;
        }
        FineModes {
            dist: dist_code(s.dist),
            rgb: match s.rgb {
                Rgb::Softmax => 0,
                Rgb::Hard => 1,
            },
            alpha: match s.alpha {
                Alpha::Prod => 0,
                Alpha::Sum => 1,
                Alpha::Hard => 2,
            },
            flags,
        }
    }

    /// Alpha only, if `alpha_only`: the forward renders no colour
    /// ([`crate::raster::gpu::GpuScene::set_silhouette_only`]) and the backward leaves out the
    /// colour terms of an upstream gradient with no RGB part
    /// ([`crate::raster::backward::GradBuffers::set_alpha_only`]).
    pub fn alpha_only_if(mut self, alpha_only: bool) -> Self {
        if alpha_only {
            self.flags |= FLAG_ALPHA_ONLY;
        }
        self
    }

    /// Backward only, if `masks`: each partial carries a mask of the texel slots it wrote, and
    /// its slots need no zeroing first (surface colours with at most [`MAX_MASKED_TEXELS`]
    /// texels a face; `TEXEL_MASKS` in `raster_fine.glsl`).
    pub(crate) fn texel_masks_if(mut self, masks: bool) -> Self {
        if masks {
            self.flags |= FLAG_TEXEL_MASKS;
        }
        self
    }

    /// The specialization constants, by `constant_id`: the modes, the subgroup size the tiled
    /// kernels may rely on ([`known_subgroup_size`]), then the tiled kernels' `workgroup` size
    /// ([`tiled_forward_workgroup`], [`tiled_backward_workgroup`]; the brute-force kernels have
    /// no constant 5, and any value does for them). `grad_tiled.comp` takes one more, the tile
    /// size (constant 6), which its caller appends.
    pub fn constants(&self, ctx: &Context, workgroup: u32) -> [u32; 6] {
        [
            self.dist,
            self.rgb,
            self.alpha,
            self.flags,
            known_subgroup_size(ctx),
            workgroup,
        ]
    }
}

/// Invocations per workgroup of `raster_tiled.comp` for tiles of at most `run` faces: 64 (one
/// per pixel of the 8×8 block), or on a CPU device ([`Context::cpu_workgroups`]) as few whole
/// subgroups as llvmpipe's loop cap allows for `run` (each invocation then shades a pixel of
/// `64 / workgroup` segments, one after another). llvmpipe runs every subgroup of a workgroup
/// as a coroutine with a set-up cost of its own: an empty kernel over spot-256's 1 024 blocks
/// took 1.6 ms with 64 invocations a block and 0.6 ms with 8 (the latter in a phase where every
/// pass ran 1.7× slower), and spot-256's tiled forward 6.5 % less time (BENCHMARKS.md). A GPU
/// runs the subgroups side by side: one pixel each.
pub(crate) fn tiled_forward_workgroup(ctx: &Context, run: u64) -> u32 {
    forward_workgroup(
        ctx.cpu_workgroups(),
        known_subgroup_size(ctx),
        ctx.info().shader_loop_limit(),
        run,
    )
}

/// [`tiled_forward_workgroup`] for a device that is a CPU or not, with subgroups of `lanes`
/// (0: unknown) and a loop cap of `limit`.
fn forward_workgroup(cpu: bool, lanes: u32, limit: Option<u64>, run: u64) -> u32 {
    if !cpu || lanes == 0 {
        return 64;
    }
    let mut workgroup = lanes;
    while workgroup < 64
        && limit.is_some_and(|l| tiled_forward_iterations(run, lanes, workgroup) > l)
    {
        workgroup *= 2;
    }
    workgroup
}

/// Invocations per workgroup of `grad_tiled.comp` (its `local_size_x_id = 5`): one subgroup on
/// a CPU device ([`Context::cpu_workgroups`]), 64 elsewhere. A workgroup takes one tile's
/// faces, a subgroup `lanes` of them at a time; most tiles hold fewer faces than 64 (spot-256:
/// 24 on average). A GPU runs a workgroup's subgroups side by side, and the spare ones leave at
/// once. llvmpipe runs them one after another as coroutines with a set-up cost each (an empty
/// kernel over spot-256's 1 024 blocks of 64 invocations takes 1.6 ms): with one subgroup a
/// workgroup, a tile's faces go through that subgroup batch after batch, and spot-256's
/// backward took 5.6 % less time (BENCHMARKS.md). Needs the subgroup size known
/// ([`known_subgroup_size`]); 64 otherwise.
pub(crate) fn tiled_backward_workgroup(ctx: &Context) -> u32 {
    let lanes = known_subgroup_size(ctx);
    if ctx.cpu_workgroups() && lanes != 0 {
        lanes
    } else {
        64
    }
}

/// The subgroup size the 64-invocation tiled kernels are specialized for (`SUBGROUP_SIZE` in
/// `kernels/raster/include/subgroup_face.glsl`), or 0 to let them read `gl_SubgroupSize`. The device's
/// `subgroupSize` is what a SPIR-V 1.5 compute pipeline without subgroup-size control sees, so
/// it is known whenever it is a power of two that divides the workgroup (the lanes then form
/// whole subgroups, which the butterfly sums need).
pub(crate) fn known_subgroup_size(ctx: &Context) -> u32 {
    let size = ctx.info().subgroup_size;
    if size.is_power_of_two() && size <= 64 {
        size
    } else {
        0
    }
}

impl RasterPush {
    /// The push constants for `view_count` views of a `width × height` rendered image (first
    /// view 0, no tiles: set those fields for a group or the tiled kernel).
    pub fn new(
        s: &RasterSettings,
        width: u32,
        height: u32,
        face_count: u32,
        view_count: u32,
        vertex_count: u32,
        texture_res: u32,
    ) -> Self {
        let range = s.far - s.near;
        let inv_gamma_range = if s.rgb == Rgb::Softmax {
            (1.0 / (s.gamma * range)).min(f64::from(f32::MAX)) as f32
        } else {
            0.0
        };
        let hard = s.dist == Dist::Hard;
        RasterPush {
            width,
            height,
            face_count,
            view_count,
            inv_sigma: if hard { 1.0 } else { (1.0 / s.sigma) as f32 },
            cutoff: if hard { 0.0 } else { s.cutoff() as f32 },
            near: s.near as f32,
            far: s.far as f32,
            inv_gamma_range,
            background_depth: (s.far - s.eps * range) as f32,
            texture_res,
            first_view: 0,
            background: [
                s.background[0] as f32,
                s.background[1] as f32,
                s.background[2] as f32,
                0.0,
            ],
            tile_size: 0,
            tiles_x: 0,
            tiles_y: 0,
            vertex_count,
            out_width: 0,
            out_height: 0,
            entry_total: 0,
            grad_stride: 0,
            first_row: 0,
        }
    }
}

/// Pixel rows of `grid`'s window of tile rows (the image's last tile row may be partial).
pub(crate) fn window_pixel_rows(grid: &TileGrid) -> u32 {
    let first = grid.first_row * grid.tile_size;
    grid.height
        .saturating_sub(first)
        .min(grid.tiles_y.saturating_mul(grid.tile_size))
}

/// The buffers one tiled fine pass reads and writes, by the kernel's block names (generated by
/// `build.rs` from `raster_tiled.comp`): as [`crate::raster::brute::BruteBindings`], plus the
/// sorted bin entries (`pairs`: [`crate::primitives::Bins::entries`]), the face of every
/// item-major slot (`pair_items`: [`crate::primitives::Bins::entry_items`]) and the per-tile
/// ranges of the group's views (`ranges`: [`crate::primitives::Bins::ranges`]).
pub use crate::raster::specs::RasterTiledBindings as TiledBindings;

/// The tiled fine pass's pipelines, one per combination of modes, each built on first use.
pub struct TiledRaster {
    kernel: KernelVariants,
    /// The kernel writes its loop and face counts in place of colours (constant 7).
    count_loops: bool,
}

impl TiledRaster {
    /// No pipeline is built yet: each mode combination's is built the first time it records.
    pub fn new(_ctx: &Context) -> Result<Self> {
        Ok(Self {
            kernel: KernelVariants::new(&specs::RASTER_TILED),
            count_loops: false,
        })
    }

    /// The pass writes, in place of each pixel's colour, `(the loop iterations its invocation
    /// had run by then, the faces it shaded for the pixel, 0, 0)`: what the host's loop bound
    /// (the driver's loop cap) and pair counts must predict. For this crate's own tests
    /// (`raster::loops`) only.
    #[cfg(test)]
    pub(crate) fn counting_loops(mut self) -> Self {
        self.count_loops = true;
        self
    }

    /// Records the tiled fine pass over views `first_view .. first_view + view_count`, binned on
    /// `grid` (the rendered size) by one binning whose tiles are numbered from the group's first
    /// view, where no tile holds more than `max_run` entries (the binning's
    /// [`crate::raster::gpu::ViewGroup::max_tile_entries`]). On a driver that caps shader loops,
    /// tiles of more faces than one invocation may loop over are folded in passes
    /// (`b.carry` then holds 64 bytes per pixel). On a CPU device
    /// it sizes the workgroups: one subgroup shades a whole 8×8 block where the driver's loop cap
    /// allows for a pass's faces, more where it does not. An overstated `max_run` costs only
    /// speed; an understated one lets llvmpipe's loop cap drop faces of the crowded tiles.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        b: &TiledBindings<'_>,
        settings: &RasterSettings,
        grid: &TileGrid,
        face_count: u32,
        first_view: u32,
        view_count: u32,
        vertex_count: u32,
        texture_res: u32,
        silhouette_only: bool,
        max_run: u64,
    ) -> Result<()> {
        Method::check_tile(grid.tile_size)?;
        let last = u64::from(first_view) + u64::from(view_count);
        let pixels = u64::from(grid.width) * u64::from(grid.height);
        let what = format!(
            "raster_tiled over views {first_view}..{last} of {}x{} pixels and {face_count} faces",
            grid.width, grid.height
        );
        b.image.require(16 * pixels * last, &what)?;
        b.aux.require(32 * pixels * last, &what)?;
        b.setups
            .require(128 * u64::from(face_count) * last, &what)?;
        b.ranges
            .require(8 * grid.tiles_per_view() * u64::from(view_count), &what)?;
        if pixels * last > u64::from(u32::MAX) || face_count == 0 {
            return Err(Error::Limit(format!(
                "raster_tiled: {} pixels and {face_count} faces (need 1..2^32 pixels, > 0 faces)",
                pixels * last
            )));
        }
        let mut push = RasterPush::new(
            settings,
            grid.width,
            grid.height,
            face_count,
            view_count,
            vertex_count,
            texture_res,
        );
        // Tiles past the loop cap are folded in passes.
        let ctx = rec.context();
        let subgroup = ctx.info().subgroup_size;
        let per_pass = pass_size(max_run, ctx.info().shader_loop_limit(), |faces| {
            tiled_forward_iterations(faces, subgroup, 64)
        });
        let passes = max_run.max(1).div_ceil(per_pass);
        if passes > 1 {
            b.carry.require(CARRY_BYTES * pixels * last, &what)?;
        }
        let mut constants = FineModes::new(settings, true)
            .alpha_only_if(silhouette_only)
            .constants(ctx, tiled_forward_workgroup(ctx, per_pass))
            .to_vec();
        constants.push(u32::from(passes > 1));
        constants.push(u32::from(self.count_loops));
        let kernel = self.kernel.get(ctx, &constants)?;
        push.first_view = first_view;
        push.tile_size = grid.tile_size;
        push.tiles_x = grid.tiles_x;
        push.tiles_y = grid.tiles_y;
        push.first_row = grid.first_row;
        let blocks = u64::from(grid.width.div_ceil(8))
            * u64::from(window_pixel_rows(grid).div_ceil(8))
            * u64::from(view_count);
        let groups = u32::try_from(blocks)
            .map_err(|_| Error::Limit(format!("raster_tiled: {blocks} workgroups")))?;
        dispatch_passes(
            rec,
            &kernel,
            &b.for_kernel(&kernel)?,
            push,
            (passes, per_pass),
            groups,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forward_workgroups_widen_only_where_the_loop_cap_asks() {
        const CAP: u64 = 65_535;
        // A GPU, or an unknown subgroup size: one invocation a pixel.
        assert_eq!(forward_workgroup(false, 32, None, 100), 64);
        assert_eq!(forward_workgroup(true, 0, Some(CAP), 100), 64);
        // llvmpipe: one subgroup a block while its 8 rounds fit, then wider.
        assert_eq!(forward_workgroup(true, 8, Some(CAP), 100), 8);
        assert_eq!(forward_workgroup(true, 8, None, 1 << 30), 8);
        for run in [100, 6_000, 8_000, 20_000, 40_000, 52_000] {
            let wg = forward_workgroup(true, 8, Some(CAP), run);
            assert!(
                wg.is_power_of_two() && (8..=64).contains(&wg),
                "{run}: {wg}"
            );
            assert!(tiled_forward_iterations(run, 8, wg) <= CAP, "{run}: {wg}");
            if wg > 8 {
                assert!(
                    tiled_forward_iterations(run, 8, wg / 2) > CAP,
                    "{run}: {wg}"
                );
            }
        }
        assert_eq!(forward_workgroup(true, 8, Some(CAP), 8_000), 16);
        // Past what even 64 invocations take: 64 (and the tile is folded in passes).
        assert_eq!(forward_workgroup(true, 8, Some(CAP), 60_000), 64);
    }

    #[test]
    fn passes_split_only_past_the_cap_and_evenly() {
        const CAP: u64 = 65_535;
        let tiled = |faces| tiled_forward_iterations(faces, 8, 64);
        // Under the cap, or with none: one pass of everything.
        assert_eq!(pass_size(52_000, Some(CAP), tiled), 52_000);
        assert_eq!(pass_size(1 << 40, None, tiled), 1 << 40);
        assert_eq!(pass_size(0, Some(CAP), tiled), 1);
        for run in [52_500, 60_000, 200_000, 327_680, 5_000_000] {
            let per_pass = pass_size(run, Some(CAP), tiled);
            let passes = run.div_ceil(per_pass);
            assert!(passes > 1 && tiled(per_pass) <= CAP, "{run}: {per_pass}");
            // No fewer passes would do, and they are even: the last is short of the others by
            // fewer faces than there are passes.
            assert!(tiled(run.div_ceil(passes - 1)) > CAP, "{run}: {passes}");
            assert!(run - (passes - 1) * per_pass + passes >= per_pass, "{run}");
        }
        // Brute force: a face an iteration, and two more.
        assert_eq!(pass_size(65_533, Some(CAP), |f| f + 2), 65_533);
        assert_eq!(pass_size(150_000, Some(CAP), |f| f + 2), 50_000);
    }

    #[test]
    fn shared_structs_match_the_kernels_layout() {
        for spec in [&specs::RASTER_BRUTE, &specs::RASTER_TILED] {
            assert_eq!(
                std::mem::size_of::<ForwardPush>() as u32,
                spec.push_constant_size,
                "{}",
                spec.name
            );
        }
        assert_eq!(std::mem::offset_of!(RasterPush, background), 48);
        assert_eq!(std::mem::size_of::<PixelAux>(), 32);
        assert_eq!(specs::RASTER_TILED.bindings.len(), 9);
        assert_eq!(specs::RASTER_BRUTE.bindings.len(), 6);
    }
}
