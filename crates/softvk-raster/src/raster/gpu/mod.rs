//! The GPU forward as a script of stages, for the CLI, tests and benchmarks:
//!
//! 1. light on the host (f64, as SoftRas lights before projection) and upload ([`Renderer::prepare`]);
//! 2. face setup, one invocation per (view, face);
//! 3. [`Method::Tiled`]: binning (count → scan → scatter → sort by tile → ranges,
//!    [`crate::primitives::binning`]) and the tiled fine pass; or [`Method::Brute`]: every face
//!    for every pixel;
//! 4. the 2×2 average with anti-aliasing, and read back.
//!
//! A scene is one mesh seen from many views, or a batch of meshes of equal topology, each seen
//! from its views ([`Renderer::prepare_batch`]); either renders in one submission per group.
//!
//! Binning sizes its entry list exactly: the count pass's total is read back before the rest is
//! recorded (two submissions per group of views). Views are binned in groups small enough that
//! the count cannot wrap and the entries fit one storage-buffer binding; a group whose entries do
//! not fit is split and re-counted, down to one view, and a view whose entries alone do not fit
//! is split into windows of tile rows ([`TileGrid::window`]), each binned, rendered and
//! differentiated alone (a face's gradient sums its windows' partials in tile order, the order
//! of one binning, so the result is bit for bit the same). [`Renderer`] makes the pipelines
//! once; a [`GpuScene`] keeps a scene's buffers so it can be rendered again (benchmarks record
//! it once and resubmit).
//!
//! Loops that must not wait for the count (fitting, a host engine's frames) bin *guarded*
//! instead: [`Renderer::reserve_guarded`] returns [`GuardedBins`], every view as one group with
//! a capacity of entries, and [`Renderer::record_forward_guarded`] records the forward into any
//! command buffer over them, with the sort over the whole capacity (sentinel keys) and
//! everything after the count gated on the GPU by an [`IterationGate`]: no read-back, no
//! submission.
//!
//! The two modes are types ([`crate::raster::binned`]): [`Renderer::run`] returns an
//! [`ExactRun`], which [`Renderer::record_forward`] replays; a guarded forward needs its
//! [`GuardedBins`]. Every forward gives a [`Binned`] (the scene and how its faces were binned),
//! which its backward ([`GradKernels::record`], [`Renderer::backward`]) takes. It borrows the
//! scene, so nothing re-bins it in between.

mod prepare;
mod render;
mod run;
mod stages;

use crate::error::Result;
use crate::gpu::Context;
#[cfg(doc)]
use crate::gpu::gate::IterationGate;
use crate::primitives::binning::{Binner, Bins, TileGrid};
#[cfg(doc)]
use crate::raster::backward::GradIo;
use crate::raster::backward::{GradBuffers, GradKernels};
pub use crate::raster::binned::{Binned, ExactRun, GuardedBins, PairCounts};
use crate::raster::brute::BruteRaster;
use crate::raster::fine::{CARRY_BYTES, PixelAux, TiledRaster};
use crate::raster::loops::tiled_forward_iterations;
pub use crate::raster::method::{DEFAULT_TILE, Method};
use crate::raster::reference_grad::Gradients;
pub use crate::raster::scene::{Frames, GpuScene, ViewGroup};
use crate::raster::settings::RasterSettings;
use crate::raster::setup::{FaceSetupKernel, GpuFaceSetup};

/// The forward's pipelines, made once per context.
pub struct Renderer {
    setup: FaceSetupKernel,
    brute: BruteRaster,
    tiled: TiledRaster,
    binner: Binner,
    grad: GradKernels,
    entry_budget: Option<u64>,
}

/// The most entries any tile of a group holds, read back from its ranges.
fn max_tile_run(ctx: &Context, bins: &Bins, tiles: u64) -> Result<u64> {
    let ranges: Vec<[u32; 2]> = ctx.read_buffer(bins.ranges(), 0, tiles as usize)?;
    Ok(ranges
        .iter()
        .map(|r| u64::from(r[1] - r[0]))
        .max()
        .unwrap_or(0))
}

/// The most entries any tile of the group holds, or an upper bound of it: the entry count
/// where that alone shows one pass of the tiled forward stays under the driver's loop cap, else
/// the exact largest tile, read back (past the cap the forward folds that tile in passes, and
/// more passes than needed would cost time).
fn tile_run_bound(
    ctx: &Context,
    bins: &Bins,
    grid: &TileGrid,
    views: u32,
    total: u64,
    faces: u32,
) -> Result<u64> {
    // A tile belongs to one view, and a face enters a tile at most once.
    let total = total.min(u64::from(faces));
    let Some(limit) = ctx.info().shader_loop_limit() else {
        return Ok(total);
    };
    if tiled_forward_iterations(total, ctx.info().subgroup_size, 64) <= limit {
        return Ok(total);
    }
    max_tile_run(ctx, bins, grid.tiles_per_view() * u64::from(views))
}

/// The most views of a mesh of `faces` faces one scene holds within the device's storage
/// bindings: each view adds its faces' setups, its image and its pixels' aux (and running
/// state, where passes may be needed) to one binding each. At least 1 (a view that does not
/// fit is the scene's own error).
pub fn views_per_scene(ctx: &Context, faces: u64, settings: &RasterSettings) -> usize {
    let scale = if settings.antialias { 4 } else { 1 };
    let pixels = u64::from(settings.width) * u64::from(settings.height) * scale;
    let carry = if may_need_passes(ctx, faces.min(u64::from(u32::MAX)) as u32) {
        CARRY_BYTES
    } else {
        0
    };
    let per_view = [
        faces * std::mem::size_of::<GpuFaceSetup>() as u64,
        16 * pixels,
        std::mem::size_of::<PixelAux>() as u64 * pixels,
        carry * pixels,
    ];
    let max = u64::from(ctx.info().limits.max_storage_buffer_range);
    per_view
        .iter()
        .filter(|&&bytes| bytes > 0)
        .map(|bytes| max / bytes)
        .min()
        .unwrap_or(u64::MAX)
        .clamp(1, u64::from(u32::MAX)) as usize
}

/// Whether a forward over `faces` faces could need more than one pass on this device (brute
/// force's face list, or a tile holding every face): then the scene keeps a carry buffer.
fn may_need_passes(ctx: &Context, faces: u32) -> bool {
    let faces = u64::from(faces);
    ctx.info().shader_loop_limit().is_some_and(|limit| {
        faces + 2 > limit || tiled_forward_iterations(faces, ctx.info().subgroup_size, 64) > limit
    })
}

impl Renderer {
    /// Builds every pipeline of the forward.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            setup: FaceSetupKernel::new(ctx)?,
            brute: BruteRaster::new(ctx)?,
            tiled: TiledRaster::new(ctx)?,
            binner: Binner::new(ctx)?,
            grad: GradKernels::new(ctx)?,
            entry_budget: None,
        })
    }

    /// Caps the (face, tile) entries one binning may hold (their buffers take about 28 bytes
    /// each); views are binned in smaller groups to stay under it. Without a budget the cap is
    /// what one storage-buffer binding holds (`maxStorageBufferRange / 8`).
    pub fn with_entry_budget(mut self, entries: u64) -> Self {
        self.entry_budget = Some(entries.max(1));
        self
    }

    /// A renderer whose tiled forward writes, in place of each pixel's colour, `(the loop
    /// iterations the kernel's invocation had run by then, the faces it shaded for the pixel,
    /// 0, 0)` ([`TiledRaster::counting_loops`]), so that tests hold the host's loop bounds and
    /// pair counts to what the kernel did. For this crate's own tests (`raster::loops`) only.
    #[cfg(test)]
    pub(crate) fn counting_loops(mut self) -> Self {
        self.tiled = self.tiled.counting_loops();
        self
    }

    /// The backward's pipelines (for callers that record the backward themselves).
    pub fn grad_kernels(&self) -> &GradKernels {
        &self.grad
    }

    /// The backward of the forward that left `binned`: dL/d(world positions, raw colours, and
    /// with `cameras` the cameras) given `d_image` = dL/d(output RGBA), view-major. A
    /// convenience over [`GradKernels::record`]: uploads, one submission, read-back; the host
    /// adds lighting's and the cameras' share in f64.
    pub fn backward(
        &self,
        ctx: &Context,
        binned: &Binned<'_>,
        d_image: &[[f32; 4]],
        cameras: bool,
    ) -> Result<Gradients> {
        let scene = binned.scene();
        let gb = GradBuffers::new(ctx, binned)?;
        gb.set_d_image(ctx, scene, d_image)?;
        ctx.submit_and_wait(|rec| self.grad.record(rec, binned, &gb, &gb.io()))?;
        self.grad.finish(ctx, scene, &gb, &gb.io(), cameras)
    }
}
