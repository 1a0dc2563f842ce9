//! nvdiffrast's primitives on the GPU: [`HardRasterizer`].
//!
//! A rasterization is four steps over buffers the caller owns (positions, triangles and the
//! range table in; keys, `rast` and `rast_db` out) and scratch the rasterizer owns (items,
//! bins):
//!
//! 1. **Setup** (`kernels/raster/hard/hard_setup.comp`): per (minibatch item, triangle slot) an item:
//!    how its coverage is tested, its snapped corners and its box
//!    ([`HardRasterizer::record_setup`], with the binning's count).
//! 2. **Binning** ([`crate::primitives::binning`], 8-pixel tiles), exact: its count is read back
//!    between two submissions ([`HardRasterizer::bin`], [`HardRasterizer::record_sort`]).
//! 3. **Depth** (`hard_depth.comp`): per pixel the nearest surface's key, in passes over crowded
//!    tiles where the driver caps loops; after a given layer's keys for depth peeling
//!    ([`HardRasterizer::record_depth`]).
//! 4. **Shade** (`hard_shade.comp`): `rast` and `rast_db` from the keys
//!    ([`HardRasterizer::record_shade`]).
//!
//! [`HardRasterizer::rasterize`] does all of it from host slices.

mod antialias;
mod interpolate;
mod raster;
mod raster_grad;
pub mod texture;

pub use interpolate::InterpolateGradBuffers;
pub use raster_grad::vertex_lists;

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::{Shape, Topology};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, PassTime, Recorder, Timer};
use crate::primitives::binning::{BinJob, Binner, Bins, ItemLayout, TileGrid};
use crate::primitives::scan::{Scan, ScanScratch};
use crate::raster::specs;

/// Words of one rasterizer item (`ITEM_WORDS` in `kernels/raster/include/hard.glsl`).
const ITEM_WORDS: u32 = 20;

/// Tile edge of the depth pass's workgroups (8×8 pixels).
const TILE: u32 = 8;

/// Push constants of every kernel of the family (`Push` in `kernels/raster/include/hard.glsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct HardPush {
    width: u32,
    height: u32,
    batch: u32,
    tri_count: u32,
    vertex_count: u32,
    items_per_view: u32,
    instanced: u32,
    peel: u32,
    tiles_x: u32,
    tiles_y: u32,
    pass_begin: u32,
    pass_end: u32,
    box_scale: f32,
    ndc_dx: f32,
    ndc_dy: f32,
    rows: u32,
    slots: u32,
    dims: u32,
    attr_count: u32,
    diff_count: u32,
    grow: u32,
    channels: u32,
    items: u32,
    pad0: u32,
}

/// What one rasterization is over, planned on the host: the shape, the range table the kernels
/// read, the binning job and the depth pass's pass size. Made by [`HardPlan::new`], which
/// checks everything the kernels rely on.
#[derive(Clone, Debug)]
pub struct HardPlan {
    shape: Shape,
    ranges: Vec<[u32; 2]>,
    job: BinJob,
    push: HardPush,
    /// Entries of a tile's run one depth pass visits at most.
    pass_items: u64,
}

impl HardPlan {
    /// Plans the rasterization of `shape` on `ctx`'s device.
    pub fn new(ctx: &Context, shape: &Shape) -> Result<Self> {
        if shape.width == 0
            || shape.height == 0
            || shape.width > super::MAX_SIZE
            || shape.height > super::MAX_SIZE
        {
            return Err(Error::Input(format!(
                "rasterize: resolution {}x{} (height x width) is outside 1..={}",
                shape.height,
                shape.width,
                super::MAX_SIZE
            )));
        }
        let batch = shape.batch();
        if batch == 0 {
            return Err(Error::Input("rasterize: the minibatch is empty".into()));
        }
        let ranges = match &shape.topology {
            Topology::Instanced { .. } => vec![[0, shape.triangle_count]; batch as usize],
            Topology::Ranged(r) => r.clone(),
        };
        let items_per_view = ranges.iter().map(|r| r[1]).max().unwrap_or(0).max(1);
        let pixels = shape.pixels() as u64;
        let limit = u64::from(ctx.info().limits.max_storage_buffer_range);
        if 16 * pixels > limit || pixels > u64::from(u32::MAX) {
            return Err(Error::DeviceLimit {
                kind: LimitKind::StorageBinding,
                what: format!(
                    "rasterize: rast of {batch} × {}x{} pixels",
                    shape.height, shape.width
                ),
                need: 16 * pixels,
                max: limit,
                device: ctx.info().name.clone(),
                hint: "rasterize fewer minibatch items at once or a smaller resolution",
            });
        }
        let grid = TileGrid::new(shape.width, shape.height, TILE)?;
        // The depth pass's loops per invocation, counted as if the driver unrolled none: per
        // batch of `m` staged entries (m = min(8, subgroup size), 1 when unknown) one, three
        // (the edges) and per entry 2 × (1 + 8) (snapped and homogeneous, each over a row's
        // eight pixels); 64 spare for the loops outside the batches.
        let pass_items = match ctx.info().shader_loop_limit() {
            Some(cap) => {
                let m = u64::from(crate::raster::fine::known_subgroup_size(ctx).clamp(1, 8));
                (cap - 64) * m / (4 + 18 * m)
            }
            None => u64::from(u32::MAX),
        };
        let job = BinJob {
            grid,
            layout: ItemLayout {
                stride_words: ITEM_WORDS,
                box_offset: 0,
                flag_offset: 4,
                flag_mask: 1,
            },
            items_per_view,
            views: batch,
            first_item: 0,
        };
        let s = f64::from(shape.width.min(shape.height));
        let push = HardPush {
            width: shape.width,
            height: shape.height,
            batch,
            tri_count: shape.triangle_count,
            vertex_count: shape.vertex_count,
            items_per_view,
            instanced: u32::from(matches!(shape.topology, Topology::Instanced { .. })),
            peel: 0,
            tiles_x: grid.tiles_x,
            tiles_y: grid.tiles_y,
            pass_begin: 0,
            pass_end: 0,
            box_scale: (1.0 / (8.0 * s)) as f32,
            ndc_dx: (2.0 / f64::from(shape.width)) as f32,
            ndc_dy: (2.0 / f64::from(shape.height)) as f32,
            rows: 0,
            slots: 0,
            dims: 0,
            attr_count: 0,
            diff_count: 0,
            grow: 0,
            channels: 0,
            items: batch * items_per_view,
            pad0: 0,
        };
        Ok(Self {
            shape: shape.clone(),
            ranges,
            job,
            push,
            pass_items,
        })
    }

    /// The shape planned for.
    pub fn shape(&self) -> &Shape {
        &self.shape
    }

    /// `(first triangle, count)` per minibatch item, as the kernels read them (one `[u32; 2]`
    /// each): what the caller's ranges buffer must hold.
    pub fn range_table(&self) -> &[[u32; 2]] {
        &self.ranges
    }

    /// Pixels over the minibatch.
    pub fn pixels(&self) -> u64 {
        self.shape.pixels() as u64
    }

    fn items_bytes(&self) -> u64 {
        self.job.item_count() * u64::from(ITEM_WORDS) * 4
    }

    /// The depth passes needed when no tile's run is longer than `longest` entries.
    pub fn depth_passes(&self, longest: u64) -> u64 {
        longest.div_ceil(self.pass_items).max(1)
    }
}

/// The inputs every step reads, in the caller's buffers.
#[derive(Clone, Copy)]
pub struct HardInputs<'a> {
    /// f32 clip-space positions, [`Shape::pos_len`] of them.
    pub pos: BufferRange<'a>,
    /// Three u32 vertex indices per triangle.
    pub tri: BufferRange<'a>,
    /// [`HardPlan::range_table`].
    pub ranges: BufferRange<'a>,
}

/// One rasterized layer as the host gets it, `[B, H, W, 4]` f32 (nvdiffrast's layout).
#[derive(Clone, Debug, PartialEq)]
pub struct HardLayer {
    /// `(u, v, z/w, id + 1)`.
    pub rast: Vec<f32>,
    /// `(du/dX, du/dY, dv/dX, dv/dY)`.
    pub rast_db: Vec<f32>,
    /// Per pixel the drawn surface's depth key `(z/w bits, id + 1)` (`[0, 0]`: none), what the
    /// next depth-peeling layer starts after.
    pub keys: Vec<[u32; 2]>,
}

/// The gradients of `interpolate`, f32.
#[derive(Clone, Debug, PartialEq)]
pub struct InterpolateGrads32 {
    /// Same shape as `attr`.
    pub attr: Vec<f32>,
    /// `[B, H, W, 4]`.
    pub rast: Vec<f32>,
    /// `[B, H, W, 4]`.
    pub rast_db: Vec<f32>,
}

/// The arrays `antialias` reads, f32, in nvdiffrast's layouts.
#[derive(Clone, Copy, Debug)]
pub struct AntialiasArgs<'a> {
    /// `[B, H, W, C]`.
    pub color: &'a [f32],
    /// `[B, H, W, 4]`, as `rasterize` wrote it.
    pub rast: &'a [f32],
    /// `[B, V, 4]` (instanced) or `[V, 4]`.
    pub pos: &'a [f32],
    /// Whether `pos` holds one set of vertices per minibatch item.
    pub instanced: bool,
    /// V.
    pub vertex_count: u32,
    /// `[T, 3]`.
    pub tri: &'a [[u32; 3]],
    /// B, H, W, C.
    pub batch: u32,
    /// H.
    pub height: u32,
    /// W.
    pub width: u32,
    /// C.
    pub channels: u32,
}

/// Scratch of the backward's fixed-order reduction (`kernels/raster/include/hard_grads.glsl`): the
/// items' visible boxes, their slot counts and first slots, the per-slot partials and the
/// per-item sums.
#[derive(Default)]
struct GradScratch {
    boxes: Option<Buffer>,
    counts: Option<Buffer>,
    offsets: Option<Buffer>,
    scan: Option<ScanScratch>,
    partials: Option<Buffer>,
    item_grads: Option<Buffer>,
    /// Read back by [`HardRasterizer::read_slots`].
    slots: Option<u64>,
}

fn device_buffer<'a>(
    ctx: &Context,
    slot: &'a mut Option<Buffer>,
    name: &str,
    bytes: u64,
) -> Result<&'a Buffer> {
    if slot.as_ref().is_none_or(|b| b.size() < bytes) {
        *slot = None;
        *slot = Some(ctx.create_buffer(name, bytes.max(256), MemoryKind::Device)?);
    }
    Ok(slot.as_ref().expect("made above"))
}

/// nvdiffrast's primitives on the GPU: their pipelines, the binning and scratch.
pub struct HardRasterizer {
    setup: Arc<Kernel>,
    /// Tiles per workgroup of `depth` ([`depth_tiles_per_group`]).
    depth_tiles: u32,
    /// The set-up's count of homogeneous items (one `u32`, host-mapped: [`HardRasterizer::bin`]
    /// reads it with no submission of its own).
    counts: Buffer,
    /// Whether any item of the last set-up is homogeneous, once [`HardRasterizer::bin`] read it.
    homogeneous: Option<bool>,
    shade: Arc<Kernel>,
    grad_boxes: Arc<Kernel>,
    grad_count: Arc<Kernel>,
    grad_reduce: Arc<Kernel>,
    grad_gather: Arc<Kernel>,
    raster_grad: Arc<Kernel>,
    interp: Arc<Kernel>,
    interp_pixel_grad: Arc<Kernel>,
    interp_grad: Arc<Kernel>,
    /// `antialias`'s kernels and scratch.
    aa: antialias::AntialiasKernels,
    scan: Scan,
    grads: GradScratch,
    binner: Binner,
    bins: Bins,
    items: Option<Buffer>,
    /// Read back by [`HardRasterizer::bin`]: the entries of the last binning.
    entries: Option<u64>,
    host: HostBuffers,
    /// GPU timestamps of the slice entry points' passes ([`HardRasterizer::time_passes`]).
    timer: Option<Timer>,
    timings: Vec<PassTime>,
}

/// Host-visible buffers the slice entry points reuse (grown, never shrunk).
#[derive(Default)]
struct HostBuffers {
    inputs: Option<Buffer>,
    outputs: Option<Buffer>,
}

fn host_buffer<'a>(
    ctx: &Context,
    slot: &'a mut Option<Buffer>,
    name: &str,
    bytes: u64,
    kind: MemoryKind,
) -> Result<&'a mut Buffer> {
    if slot.as_ref().is_none_or(|b| b.size() < bytes) {
        *slot = None; // free the old one first
        *slot = Some(ctx.create_buffer(name, bytes.max(256), kind)?);
    }
    Ok(slot.as_mut().expect("made above"))
}

/// Byte offsets of consecutive parts of one buffer, each 256-byte aligned (a storage binding's
/// offset alignment on any device); the last entry is the total.
fn layout_of(parts: &[u64]) -> Vec<u64> {
    let mut at = vec![0u64];
    for &p in parts {
        let next = at.last().expect("non-empty") + p.max(4).next_multiple_of(256);
        at.push(next);
    }
    at
}

fn put<T: Pod>(bytes: &mut [u8], at: u64, data: &[T]) {
    let data: &[u8] = bytemuck::cast_slice(data);
    bytes[at as usize..at as usize + data.len()].copy_from_slice(data);
}

fn get<T: Pod>(bytes: &[u8], at: u64, out: &mut [T]) {
    let len = std::mem::size_of_val(out);
    bytemuck::cast_slice_mut::<T, u8>(out).copy_from_slice(&bytes[at as usize..at as usize + len]);
}

/// Tiles per workgroup of `hard_depth.comp` (eight invocations each, one per row): one on a CPU
/// device ([`Context::cpu_workgroups`]: one llvmpipe subgroup, which stages each binned item
/// once and keeps a row's eight keys in registers), eight elsewhere (64 invocations, whole warps
/// and waves). The same bits either way.
fn depth_tiles_per_group(ctx: &Context) -> u32 {
    if ctx.cpu_workgroups() { 1 } else { 8 }
}

impl HardRasterizer {
    /// Builds the pipelines (from the context's cache) and empty scratch.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            setup: ctx.kernel(&specs::HARD_SETUP, &[])?,
            depth_tiles: depth_tiles_per_group(ctx),
            counts: ctx.create_buffer("hard rasterizer counts", 4, MemoryKind::Readback)?,
            homogeneous: None,
            shade: ctx.kernel(&specs::HARD_SHADE, &[])?,
            grad_boxes: ctx.kernel(&specs::HARD_GRAD_BOXES, &[])?,
            grad_count: ctx.kernel(&specs::HARD_GRAD_COUNT, &[])?,
            grad_reduce: ctx.kernel(&specs::HARD_GRAD_REDUCE, &[])?,
            grad_gather: ctx.kernel(&specs::HARD_GRAD_GATHER, &[])?,
            raster_grad: ctx.kernel(&specs::HARD_RASTER_GRAD, &[])?,
            interp: ctx.kernel(&specs::HARD_INTERP, &[])?,
            interp_pixel_grad: ctx.kernel(&specs::HARD_INTERP_PIXEL_GRAD, &[])?,
            interp_grad: ctx.kernel(&specs::HARD_INTERP_GRAD, &[])?,
            aa: antialias::AntialiasKernels::new(ctx)?,
            scan: Scan::new(ctx)?,
            grads: GradScratch::default(),
            binner: Binner::new(ctx)?,
            bins: Bins::new(ctx)?,
            items: None,
            entries: None,
            host: HostBuffers::default(),
            timer: None,
            timings: Vec::new(),
        })
    }

    /// Times every pass of the slice entry points with GPU timestamps from now on: what
    /// benchmarks read with [`HardRasterizer::take_timings`].
    pub fn time_passes(&mut self, ctx: &Context) -> Result<()> {
        self.timer = Some(Timer::new(ctx, 32)?);
        Ok(())
    }

    /// The pass times recorded since the last call, in order.
    pub fn take_timings(&mut self) -> Vec<PassTime> {
        std::mem::take(&mut self.timings)
    }

    /// The (item, tile) entries of the last binning (after [`HardRasterizer::bin`]): each is
    /// 64 (pixel, triangle) pairs the depth pass visits.
    pub fn entries(&self) -> Option<u64> {
        self.entries
    }

    /// Submits what `f` records and waits, timed when [`HardRasterizer::time_passes`] asked.
    fn submit(
        &mut self,
        ctx: &Context,
        f: impl FnOnce(&mut Self, &mut Recorder<'_>) -> Result<()>,
    ) -> Result<()> {
        let mut timer = self.timer.take();
        let result = ctx.submit_and_wait_timed(timer.as_mut(), |rec| f(self, rec));
        let times = match (&result, &timer) {
            (Ok(()), Some(t)) => t.results(ctx),
            _ => Ok(Vec::new()),
        };
        self.timer = timer;
        result?;
        self.timings.extend(times?);
        Ok(())
    }
}
