//! nvdiffrast's primitives on the GPU: [`HardRasterizer`].
//!
//! A rasterization is four steps over buffers the caller owns (positions, triangles and the
//! range table in; keys, `rast` and `rast_db` out) and scratch the rasterizer owns (items,
//! bins):
//!
//! 1. **Setup** (`kernels/hard/hard_setup.comp`): per (minibatch item, triangle slot) an item:
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
pub mod texture;

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::reference::AttrLayout;
use super::{Shape, Topology};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{
    Buffer, BufferRange, Context, Kernel, MemoryKind, PassTime, Recorder, Timer, groups, specs,
};
use crate::primitives::binning::{BinJob, Binner, Bins, ItemLayout, TileGrid};
use crate::primitives::scan::{Scan, ScanScratch};

/// Words of one rasterizer item (`ITEM_WORDS` in `kernels/include/hard.glsl`).
const ITEM_WORDS: u32 = 20;

/// Tile edge of the depth pass's workgroups (8×8 pixels).
const TILE: u32 = 8;

/// Push constants of every kernel of the family (`Push` in `kernels/include/hard.glsl`).
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

/// Scratch of the backward's fixed-order reduction (`kernels/include/hard_grads.glsl`): the
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

/// Per output row (a vertex of one set of vertices), its (item, corner) list as
/// `item · 3 + corner`, in minibatch, triangle, corner order: CSR offsets (rows + 1) and
/// entries. `per_item`: every minibatch item has its own set of vertices (rows B·V), else one
/// set shared by all (rows V).
pub fn vertex_lists(plan: &HardPlan, tri: &[[u32; 3]], per_item: bool) -> (Vec<u32>, Vec<u32>) {
    let v = plan.shape.vertex_count as usize;
    let rows = if per_item { plan.ranges.len() * v } else { v };
    let mut counts = vec![0u32; rows + 1];
    let mut pairs = Vec::new();
    for (b, r) in plan.ranges.iter().enumerate() {
        for j in 0..r[1] {
            let t = (r[0] + j) as usize;
            let item = b as u32 * plan.push.items_per_view + j;
            for (k, &vertex) in tri[t].iter().enumerate() {
                let row = if per_item { b * v } else { 0 } + vertex as usize;
                counts[row + 1] += 1;
                pairs.push((row, 3 * item + k as u32));
            }
        }
    }
    for r in 0..rows {
        counts[r + 1] += counts[r];
    }
    let mut next = counts.clone();
    let mut entries = vec![0u32; pairs.len()];
    for (row, e) in pairs {
        entries[next[row] as usize] = e;
        next[row] += 1;
    }
    (counts, entries)
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

    /// Step 1 and the binning's count: records the setup of `plan`'s items and the count pass.
    /// Submit it, then call [`HardRasterizer::bin`].
    pub fn record_setup(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        inputs: HardInputs<'_>,
    ) -> Result<()> {
        let ctx = rec.context();
        let bytes = plan.items_bytes();
        if self.items.as_ref().is_none_or(|b| b.size() < bytes) {
            self.items = None;
            self.items =
                Some(ctx.create_buffer("hard rasterizer items", bytes, MemoryKind::Device)?);
        }
        self.bins.reserve(ctx, &plan.job)?;
        self.entries = None;
        Self::check_inputs(plan, &inputs)?;
        self.homogeneous = None;
        let items = self.items.as_ref().expect("reserved above").range(0, bytes);
        rec.pass("hard setup", |rec| {
            let counts = self.counts.range(0, 4);
            rec.fill(counts, 0);
            rec.dispatch(
                &self.setup,
                &specs::HardSetupBindings {
                    pos: inputs.pos,
                    tri: inputs.tri,
                    ranges: inputs.ranges,
                    items,
                    counts,
                }
                .for_kernel(&self.setup)?,
                &plan.push,
                groups(plan.job.item_count(), 64)?,
            )
        })?;
        rec.pass("hard binning count", |rec| {
            self.binner.record_count(rec, &self.bins, items, &plan.job)
        })
    }

    fn check_inputs(plan: &HardPlan, inputs: &HardInputs<'_>) -> Result<()> {
        inputs
            .pos
            .require(4 * plan.shape.pos_len() as u64, "rasterize positions")?;
        inputs.tri.require(
            12 * u64::from(plan.shape.triangle_count).max(1),
            "rasterize triangles",
        )?;
        inputs
            .ranges
            .require(8 * plan.ranges.len() as u64, "rasterize ranges")
    }

    /// Reads the binning's entry count back (after [`HardRasterizer::record_setup`]'s
    /// submission completed) and sizes the entry buffers for it; reads too whether any item
    /// takes the homogeneous test, so that [`HardRasterizer::record_depth`] can record the
    /// depth pass specialized for none (on llvmpipe a loop's body runs at least once, over
    /// no lanes or not).
    pub fn bin(&mut self, ctx: &Context) -> Result<u64> {
        let total = self.bins.read_total(ctx)?;
        // The depth pass fetches the entries as whole 16-byte texels.
        self.bins
            .reserve_entries(ctx, total.max(1).next_multiple_of(4))?;
        let bytes = self
            .counts
            .mapped()
            .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
        let homogeneous = u32::from_ne_bytes(bytes[..4].try_into().expect("four bytes"));
        self.entries = Some(total);
        self.homogeneous = Some(homogeneous > 0);
        Ok(total)
    }

    fn entry_count(&self) -> Result<u64> {
        self.entries.ok_or_else(|| {
            Error::Misuse("hard rasterizer: the binning's count is not read yet (bin)".into())
        })
    }

    fn items_range(&self, plan: &HardPlan) -> Result<BufferRange<'_>> {
        self.items
            .as_ref()
            .map(|b| b.range(0, plan.items_bytes()))
            .ok_or_else(|| Error::Misuse("hard rasterizer: record_setup has not run".into()))
    }

    /// Step 2's second half: records the binning's lists (after [`HardRasterizer::bin`]).
    pub fn record_sort(&self, rec: &mut Recorder<'_>, plan: &HardPlan) -> Result<()> {
        self.entry_count()?;
        let items = self.items_range(plan)?;
        rec.pass("hard binning lists", |rec| {
            self.binner.record_sort(rec, &self.bins, items, &plan.job)
        })
    }

    /// The longest tile run the depth pass can meet without reading the ranges.
    pub fn longest_run_bound(&self, plan: &HardPlan) -> Result<u64> {
        Ok(u64::from(plan.job.items_per_view).min(self.entry_count()?))
    }

    /// Reads the binning's tile ranges back (after a submission of
    /// [`HardRasterizer::record_sort`]) and returns the longest run.
    pub fn longest_run(&self, ctx: &Context, plan: &HardPlan) -> Result<u64> {
        let ranges: Vec<[u32; 2]> =
            ctx.read_buffer(self.bins.ranges(), 0, plan.job.tile_count() as usize)?;
        Ok(ranges
            .iter()
            .map(|r| u64::from(r[1].saturating_sub(r[0])))
            .max()
            .unwrap_or(0))
    }

    /// Step 3: records `passes` depth passes ([`HardPlan::depth_passes`]) into `keys` (8 bytes
    /// a pixel), after [`HardRasterizer::record_sort`]; with `previous` (a layer's keys), the
    /// next depth-peeling layer.
    pub fn record_depth(
        &self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        inputs: HardInputs<'_>,
        keys: BufferRange<'_>,
        previous: Option<BufferRange<'_>>,
        passes: u64,
    ) -> Result<()> {
        let total = self.entry_count()?;
        let pixels = plan.pixels();
        Self::check_inputs(plan, &inputs)?;
        keys.require(8 * pixels, "rasterize keys")?;
        if let Some(p) = &previous {
            p.require(8 * pixels, "the previous layer's keys")?;
        }
        let items = self.items_range(plan)?;
        let tiles = plan.job.tile_count();
        let entries = total.max(1);
        let keys = keys.sub(0, 8 * pixels);
        let homogeneous = self.homogeneous.unwrap_or(true);
        // `hard_depth.comp` specialized for peeling or not and for homogeneous items or none
        // (the context keeps each pipeline once made).
        let depth = &rec.context().kernel(
            &specs::HARD_DEPTH,
            &[
                crate::raster::fine::known_subgroup_size(rec.context()),
                8 * self.depth_tiles,
                u32::from(previous.is_some()),
                u32::from(homogeneous),
            ],
        )?;
        // Entries are fetched as 16-byte texels: whole ones (`bin` reserved them).
        let entry_bytes = (4 * entries).next_multiple_of(16);
        rec.pass("hard depth", |rec| {
            rec.fill(keys, 0);
            for pass in 0..passes {
                let begin = pass * plan.pass_items;
                let end = (begin + plan.pass_items).min(u64::from(u32::MAX));
                let push = HardPush {
                    pass_begin: begin as u32,
                    pass_end: end as u32,
                    peel: u32::from(previous.is_some()),
                    ..plan.push
                };
                rec.dispatch(
                    depth,
                    &specs::HardDepthBindings {
                        pos: inputs.pos,
                        tri: inputs.tri,
                        items,
                        pairs: self.bins.entries().range(0, entry_bytes),
                        pair_items: self.bins.entry_items().range(0, entry_bytes),
                        tile_ranges: self.bins.ranges().range(0, 8 * tiles),
                        keys,
                        prev_keys: previous.unwrap_or(keys),
                    }
                    .for_kernel(depth)?,
                    &push,
                    u32::try_from(tiles.div_ceil(u64::from(self.depth_tiles)))
                        .map_err(|_| Error::Input("rasterize: image too large".into()))?,
                )?;
            }
            Ok(())
        })
    }

    /// Step 4: records `rast` and `rast_db` (16 bytes a pixel each) from `keys`.
    pub fn record_shade(
        &self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        inputs: HardInputs<'_>,
        keys: BufferRange<'_>,
        rast: BufferRange<'_>,
        rast_db: BufferRange<'_>,
    ) -> Result<()> {
        let pixels = plan.pixels();
        Self::check_inputs(plan, &inputs)?;
        keys.require(8 * pixels, "rasterize keys")?;
        rast.require(16 * pixels, "rast")?;
        rast_db.require(16 * pixels, "rast_db")?;
        rec.pass("hard shade", |rec| {
            rec.dispatch(
                &self.shade,
                &specs::HardShadeBindings {
                    pos: inputs.pos,
                    tri: inputs.tri,
                    keys: keys.sub(0, 8 * pixels),
                    rast: rast.sub(0, 16 * pixels),
                    rast_db: rast_db.sub(0, 16 * pixels),
                }
                .for_kernel(&self.shade)?,
                &plan.push,
                groups(pixels, 64)?,
            )
        })
    }

    /// Rasterizes `pos` (f32, [`Shape::pos_len`]) with `tri`; with `previous` (a layer's
    /// keys), the next depth-peeling layer. Waits for the device.
    pub fn rasterize(
        &mut self,
        ctx: &Context,
        shape: &Shape,
        pos: &[f32],
        tri: &[[u32; 3]],
        previous: Option<&[[u32; 2]]>,
    ) -> Result<HardLayer> {
        shape.check(tri)?;
        shape.check_pos(pos)?;
        let plan = HardPlan::new(ctx, shape)?;
        let pixels = plan.pixels();
        if let Some(p) = previous {
            if p.len() as u64 != pixels {
                return Err(Error::Input(format!(
                    "rasterize: the previous layer has {} pixels, this one {pixels}",
                    p.len()
                )));
            }
        }
        let at = layout_of(&[
            4 * pos.len() as u64,
            12 * tri.len() as u64,
            8 * plan.ranges.len() as u64,
            8 * pixels,
        ]);
        let input = host_buffer(
            ctx,
            &mut self.host.inputs,
            "hard inputs",
            at[4],
            MemoryKind::Upload,
        )?;
        {
            let bytes = input
                .mapped_mut()
                .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
            put(bytes, at[0], pos);
            put(bytes, at[1], tri);
            put(bytes, at[2], &plan.ranges);
            if let Some(p) = previous {
                put(bytes, at[3], p);
            }
        }
        let out_at = layout_of(&[8 * pixels, 16 * pixels, 16 * pixels]);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "hard outputs",
            out_at[3],
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made above");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            let inputs = HardInputs {
                pos: input.range(at[0], 4 * (pos.len() as u64).max(1)),
                tri: input.range(at[1], 12 * (tri.len() as u64).max(1)),
                ranges: input.range(at[2], 8 * plan.ranges.len() as u64),
            };
            let prev = previous.map(|_| input.range(at[3], 8 * pixels));
            let keys = output.range(out_at[0], 8 * pixels);
            let rast = output.range(out_at[1], 16 * pixels);
            let rast_db = output.range(out_at[2], 16 * pixels);
            self.submit(ctx, |s, rec| s.record_setup(rec, &plan, inputs))?;
            self.bin(ctx)?;
            let bound = self.longest_run_bound(&plan)?;
            let sorted_first = plan.depth_passes(bound) > 1;
            let mut passes = 1;
            if sorted_first {
                self.submit(ctx, |s, rec| s.record_sort(rec, &plan))?;
                passes = plan.depth_passes(self.longest_run(ctx, &plan)?);
            }
            self.submit(ctx, |s, rec| {
                if !sorted_first {
                    s.record_sort(rec, &plan)?;
                }
                s.record_depth(rec, &plan, inputs, keys, prev, passes)?;
                s.record_shade(rec, &plan, inputs, keys, rast, rast_db)
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let n = pixels as usize;
            let mut layer = HardLayer {
                rast: vec![0.0; 4 * n],
                rast_db: vec![0.0; 4 * n],
                keys: vec![[0, 0]; n],
            };
            get(bytes, out_at[0], &mut layer.keys);
            get(bytes, out_at[1], &mut layer.rast);
            get(bytes, out_at[2], &mut layer.rast_db);
            Ok(layer)
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }

    /// The backward's first step over `rast` (16 bytes a pixel, as the forward wrote it): the
    /// items' visible boxes, widened by `grow` pixels, and their slots. Submit it, then call
    /// [`HardRasterizer::read_slots`].
    pub fn record_visible_tiles(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        rast: BufferRange<'_>,
        ranges: BufferRange<'_>,
        grow: u32,
    ) -> Result<()> {
        let ctx = rec.context();
        let items = plan.job.item_count();
        let pixels = plan.pixels();
        rast.require(16 * pixels, "rast")?;
        ranges.require(8 * plan.ranges.len() as u64, "rasterize ranges")?;
        device_buffer(ctx, &mut self.grads.boxes, "hard visible boxes", 16 * items)?;
        device_buffer(ctx, &mut self.grads.counts, "hard slot counts", 4 * items)?;
        device_buffer(ctx, &mut self.grads.offsets, "hard first slots", 4 * items)?;
        if self
            .grads
            .scan
            .as_ref()
            .is_none_or(|s| s.capacity() < items)
        {
            self.grads.scan = None;
            self.grads.scan = Some(ScanScratch::new(ctx, items)?);
        }
        self.grads.slots = None;
        let g = &self.grads;
        let boxes = g.boxes.as_ref().expect("made above").range(0, 16 * items);
        let counts = g.counts.as_ref().expect("made above").range(0, 4 * items);
        let offsets = g.offsets.as_ref().expect("made above").range(0, 4 * items);
        let push = HardPush { grow, ..plan.push };
        rec.pass("hard visible tiles", |rec| {
            rec.fill(boxes, u32::MAX);
            rec.dispatch(
                &self.grad_boxes,
                &specs::HardGradBoxesBindings {
                    rast: rast.sub(0, 16 * pixels),
                    ranges,
                    boxes,
                }
                .for_kernel(&self.grad_boxes)?,
                &push,
                groups(pixels, 64)?,
            )?;
            rec.dispatch(
                &self.grad_count,
                &specs::HardGradCountBindings { boxes, counts }.for_kernel(&self.grad_count)?,
                &push,
                groups(items, 64)?,
            )?;
            self.scan.record(
                rec,
                g.scan.as_ref().expect("made above"),
                counts,
                offsets,
                items,
            )
        })
    }

    /// Reads the slot count back (after [`HardRasterizer::record_visible_tiles`]'s submission
    /// completed).
    pub fn read_slots(&mut self, ctx: &Context) -> Result<u64> {
        let scan = self.grads.scan.as_ref().ok_or_else(|| {
            Error::Misuse("hard backward: record_visible_tiles has not run".into())
        })?;
        let total = u64::from(ctx.read_buffer::<u32>(scan.total(), 0, 1)?[0]);
        self.grads.slots = Some(total);
        Ok(total)
    }

    /// Makes room for `dims` floats a slot and an item, and returns the push constants of the
    /// slot, reduce and gather kernels.
    fn grad_scratch(
        &mut self,
        ctx: &Context,
        plan: &HardPlan,
        dims: u32,
        grow: u32,
        what: &str,
    ) -> Result<HardPush> {
        let slots = self.grads.slots.ok_or_else(|| {
            Error::Misuse(format!(
                "{what}: the slot count is not read yet (read_slots)"
            ))
        })?;
        let bytes = 4 * u64::from(dims) * slots.max(1);
        let limit = u64::from(ctx.info().limits.max_storage_buffer_range);
        if bytes > limit {
            return Err(Error::DeviceLimit {
                kind: LimitKind::StorageBinding,
                what: format!("{what}: the per-tile partial gradients"),
                need: bytes,
                max: limit,
                device: ctx.info().name.clone(),
                hint: "differentiate fewer minibatch items at once or a smaller resolution",
            });
        }
        device_buffer(
            ctx,
            &mut self.grads.partials,
            "hard partial gradients",
            bytes,
        )?;
        let items = plan.job.item_count();
        device_buffer(
            ctx,
            &mut self.grads.item_grads,
            "hard item gradients",
            4 * u64::from(dims) * items,
        )?;
        Ok(HardPush {
            slots: u32::try_from(slots)
                .map_err(|_| Error::Input(format!("{what}: {slots} tiles of gradients")))?,
            dims,
            grow,
            ..plan.push
        })
    }

    /// Records the reduce and the gather of the slots' partials (after a slot kernel) into
    /// `out`, `rows × dims / 3` floats, over the CSR lists of [`vertex_lists`].
    fn record_reduce_gather(
        &self,
        rec: &mut Recorder<'_>,
        push: &HardPush,
        rows: u32,
        lists: (BufferRange<'_>, BufferRange<'_>),
        out: BufferRange<'_>,
    ) -> Result<()> {
        let g = &self.grads;
        let items = u64::from(push.items);
        let dims = u64::from(push.dims);
        let per = dims / 3;
        out.require(4 * u64::from(rows) * per, "gradient output")?;
        lists
            .0
            .require(4 * (u64::from(rows) + 1), "vertex list offsets")?;
        let item_grads = g
            .item_grads
            .as_ref()
            .expect("reserved")
            .range(0, 4 * dims * items);
        let partials = g.partials.as_ref().expect("reserved");
        let push = HardPush { rows, ..*push };
        rec.dispatch(
            &self.grad_reduce,
            &specs::HardGradReduceBindings {
                offsets: g.offsets.as_ref().expect("made").range(0, 4 * items),
                counts: g.counts.as_ref().expect("made").range(0, 4 * items),
                partials: partials.range(0, 4 * dims * u64::from(push.slots).max(1)),
                item_grads,
            }
            .for_kernel(&self.grad_reduce)?,
            &push,
            groups(items * dims, 64)?,
        )?;
        rec.dispatch(
            &self.grad_gather,
            &specs::HardGradGatherBindings {
                row_offsets: lists.0,
                row_entries: lists.1,
                item_grads,
                out: out.sub(0, 4 * u64::from(rows) * per),
            }
            .for_kernel(&self.grad_gather)?,
            &push,
            groups(u64::from(rows) * per, 64)?,
        )
    }

    /// The rasterizer's backward, after [`HardRasterizer::read_slots`] for the same `rast` with
    /// `grow` 0: into `grad_pos` (f32, [`Shape::pos_len`]), the gradient of
    /// `Σ dy·rast + ddb·rast_db` (channels 0 and 1 of `dy`; `ddb` optional), over the vertex
    /// lists of [`vertex_lists`] (`per_item` as the positions are instanced).
    #[allow(clippy::too_many_arguments)]
    pub fn record_rasterize_grad(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        inputs: HardInputs<'_>,
        rast: BufferRange<'_>,
        dy: BufferRange<'_>,
        ddb: Option<BufferRange<'_>>,
        lists: (BufferRange<'_>, BufferRange<'_>),
        grad_pos: BufferRange<'_>,
    ) -> Result<()> {
        let ctx = rec.context();
        Self::check_inputs(plan, &inputs)?;
        let pixels = plan.pixels();
        rast.require(16 * pixels, "rast")?;
        dy.require(16 * pixels, "the gradient of rast")?;
        if let Some(d) = &ddb {
            d.require(16 * pixels, "the gradient of rast_db")?;
        }
        let push = self.grad_scratch(ctx, plan, 12, 0, "rasterize backward")?;
        let push = HardPush {
            diff_count: u32::from(ddb.is_some()),
            ..push
        };
        let rows = plan.shape.pos_len() as u32 / 4;
        let g = &self.grads;
        rec.pass("hard rasterize backward", |rec| {
            if push.slots > 0 {
                rec.dispatch(
                    &self.raster_grad,
                    &specs::HardRasterGradBindings {
                        pos: inputs.pos,
                        tri: inputs.tri,
                        ranges: inputs.ranges,
                        rast: rast.sub(0, 16 * pixels),
                        dy: dy.sub(0, 16 * pixels),
                        ddb: ddb.unwrap_or(dy).sub(0, 16 * pixels),
                        boxes: g
                            .boxes
                            .as_ref()
                            .expect("made")
                            .range(0, 16 * u64::from(push.items)),
                        offsets: g
                            .offsets
                            .as_ref()
                            .expect("made")
                            .range(0, 4 * u64::from(push.items)),
                        partials: g
                            .partials
                            .as_ref()
                            .expect("reserved")
                            .range(0, 48 * u64::from(push.slots)),
                    }
                    .for_kernel(&self.raster_grad)?,
                    &push,
                    groups(u64::from(push.slots), 64)?,
                )?;
            }
            self.record_reduce_gather(rec, &push, rows, lists, grad_pos)
        })
    }

    /// The gradient of `pos` given the upstream gradients of `rast` (`dy`, `[B, H, W, 4]`) and
    /// of `rast_db` (`ddb`), for the visibility in `rast`. Waits for the device.
    #[allow(clippy::too_many_arguments)]
    pub fn rasterize_grad(
        &mut self,
        ctx: &Context,
        shape: &Shape,
        pos: &[f32],
        tri: &[[u32; 3]],
        rast: &[f32],
        dy: &[f32],
        ddb: Option<&[f32]>,
    ) -> Result<Vec<f32>> {
        shape.check(tri)?;
        shape.check_pos(pos)?;
        let plan = HardPlan::new(ctx, shape)?;
        let pixels = plan.pixels();
        for (what, len) in [("rast", rast.len()), ("the gradient of rast", dy.len())]
            .into_iter()
            .chain(ddb.map(|d| ("the gradient of rast_db", d.len())))
        {
            if len as u64 != 4 * pixels {
                return Err(Error::Input(format!(
                    "rasterize backward: {what} holds {len} floats, the shape needs {}",
                    4 * pixels
                )));
            }
        }
        let per_item = matches!(shape.topology, Topology::Instanced { .. });
        let (row_offsets, row_entries) = vertex_lists(&plan, tri, per_item);
        let at = layout_of(&[
            4 * pos.len() as u64,
            12 * tri.len() as u64,
            8 * plan.ranges.len() as u64,
            16 * pixels,
            16 * pixels,
            16 * pixels,
            4 * row_offsets.len() as u64,
            4 * row_entries.len() as u64,
        ]);
        let input = host_buffer(
            ctx,
            &mut self.host.inputs,
            "hard inputs",
            at[8],
            MemoryKind::Upload,
        )?;
        {
            let bytes = input
                .mapped_mut()
                .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
            put(bytes, at[0], pos);
            put(bytes, at[1], tri);
            put(bytes, at[2], &plan.ranges);
            put(bytes, at[3], rast);
            put(bytes, at[4], dy);
            if let Some(d) = ddb {
                put(bytes, at[5], d);
            }
            put(bytes, at[6], &row_offsets);
            put(bytes, at[7], &row_entries);
        }
        let out_bytes = 4 * pos.len() as u64;
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "hard outputs",
            out_bytes,
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made above");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            let inputs = HardInputs {
                pos: input.range(at[0], 4 * (pos.len() as u64).max(1)),
                tri: input.range(at[1], 12 * (tri.len() as u64).max(1)),
                ranges: input.range(at[2], 8 * plan.ranges.len() as u64),
            };
            let rast_r = input.range(at[3], 16 * pixels);
            self.submit(ctx, |s, rec| {
                s.record_visible_tiles(rec, &plan, rast_r, inputs.ranges, 0)
            })?;
            self.read_slots(ctx)?;
            let lists = (
                input.range(at[6], 4 * row_offsets.len() as u64),
                input.range(at[7], 4 * (row_entries.len() as u64).max(1)),
            );
            let out = output.range(0, out_bytes.max(4));
            self.submit(ctx, |s, rec| {
                s.record_rasterize_grad(
                    rec,
                    &plan,
                    inputs,
                    rast_r,
                    input.range(at[4], 16 * pixels),
                    ddb.map(|_| input.range(at[5], 16 * pixels)),
                    lists,
                    out,
                )
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut grad = vec![0.0f32; pos.len()];
            get(bytes, 0, &mut grad);
            Ok(grad)
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }

    /// The plan `interpolate` reduces over: `rast [B, H, W, 4]`'s ids are triangles of `tri`
    /// (global in range mode), so every minibatch item owns every triangle.
    fn interpolate_plan(
        ctx: &Context,
        layout: AttrLayout,
        rast_len: usize,
        tri: &[[u32; 3]],
        resolution: [u32; 2],
    ) -> Result<HardPlan> {
        let [height, width] = resolution;
        let pixels = u64::from(width) * u64::from(height);
        if pixels == 0 || rast_len as u64 % (4 * pixels) != 0 || rast_len == 0 {
            return Err(Error::Input(format!(
                "interpolate: rast holds {rast_len} floats, not [B, {height}, {width}, 4]"
            )));
        }
        let batch = (rast_len as u64 / (4 * pixels)) as u32;
        if let Some((t, _)) = tri
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v >= layout.vertex_count))
        {
            return Err(Error::Input(format!(
                "interpolate: triangle {t} has a vertex index outside the {} attribute rows",
                layout.vertex_count
            )));
        }
        let shape = Shape {
            width,
            height,
            vertex_count: layout.vertex_count,
            triangle_count: tri.len() as u32,
            topology: Topology::Instanced { batch },
        };
        let mut plan = HardPlan::new(ctx, &shape)?;
        plan.push.instanced = u32::from(layout.per_item);
        plan.push.attr_count = layout.attr_count;
        Ok(plan)
    }

    /// Records `interpolate` over caller buffers: `out` (A f32 a pixel) and, with `diff_count`
    /// differentiated attributes (`diff`: their indices, u32) and `rast_db`, `out_da` (2N f32 a
    /// pixel). `plan` as [`HardRasterizer::rasterize`] made it for `rast`, with `layout`'s
    /// attributes.
    #[allow(clippy::too_many_arguments)]
    pub fn record_interpolate(
        &self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        layout: AttrLayout,
        attr: BufferRange<'_>,
        tri: BufferRange<'_>,
        rast: BufferRange<'_>,
        rast_db: Option<BufferRange<'_>>,
        diff: (BufferRange<'_>, u32),
        out: BufferRange<'_>,
        out_da: Option<BufferRange<'_>>,
    ) -> Result<()> {
        let pixels = plan.pixels();
        let a = u64::from(layout.attr_count);
        let n = if rast_db.is_some() { diff.1 } else { 0 };
        rast.require(16 * pixels, "rast")?;
        out.require(4 * a * pixels, "interpolate output")?;
        if n > 0 {
            out_da
                .as_ref()
                .ok_or_else(|| Error::Misuse("interpolate: out_da is needed".into()))?
                .require(8 * u64::from(n) * pixels, "interpolate derivatives")?;
        }
        let push = HardPush {
            instanced: u32::from(layout.per_item),
            attr_count: layout.attr_count,
            diff_count: n,
            ..plan.push
        };
        rec.pass("hard interpolate", |rec| {
            rec.dispatch(
                &self.interp,
                &specs::HardInterpBindings {
                    attr,
                    tri,
                    rast: rast.sub(0, 16 * pixels),
                    rast_db: rast_db.unwrap_or(rast).sub(0, 16 * pixels),
                    diff: diff.0,
                    out: out.sub(0, (4 * a * pixels).max(4)),
                    out_da: out_da.unwrap_or(out),
                }
                .for_kernel(&self.interp)?,
                &push,
                groups(pixels, 64)?,
            )
        })
    }

    /// `interpolate` on host slices: `(out [B, H, W, A], out_da [B, H, W, 2N])` for `rast` at
    /// `resolution` `[H, W]`. Waits for the device.
    #[allow(clippy::too_many_arguments)]
    pub fn interpolate(
        &mut self,
        ctx: &Context,
        attr: &[f32],
        layout: AttrLayout,
        rast: &[f32],
        tri: &[[u32; 3]],
        resolution: [u32; 2],
        rast_db: Option<&[f32]>,
        diff: &[u32],
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        let plan = Self::interpolate_plan(ctx, layout, rast.len(), tri, resolution)?;
        check_attr(attr, layout, &plan, rast_db, diff)?;
        let pixels = plan.pixels();
        let a = u64::from(layout.attr_count);
        let n = if rast_db.is_some() {
            diff.len() as u64
        } else {
            0
        };
        let at = layout_of(&[
            4 * attr.len() as u64,
            12 * tri.len() as u64,
            16 * pixels,
            16 * pixels,
            4 * diff.len() as u64,
        ]);
        let input = host_buffer(
            ctx,
            &mut self.host.inputs,
            "hard inputs",
            at[5],
            MemoryKind::Upload,
        )?;
        {
            let bytes = input
                .mapped_mut()
                .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
            put(bytes, at[0], attr);
            put(bytes, at[1], tri);
            put(bytes, at[2], rast);
            if let Some(d) = rast_db {
                put(bytes, at[3], d);
            }
            put(bytes, at[4], diff);
        }
        let out_at = layout_of(&[4 * a * pixels, 8 * n * pixels]);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "hard outputs",
            out_at[2],
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made above");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            self.submit(ctx, |s, rec| {
                s.record_interpolate(
                    rec,
                    &plan,
                    layout,
                    input.range(at[0], (4 * attr.len() as u64).max(4)),
                    input.range(at[1], (12 * tri.len() as u64).max(4)),
                    input.range(at[2], 16 * pixels),
                    rast_db.map(|_| input.range(at[3], 16 * pixels)),
                    (
                        input.range(at[4], (4 * diff.len() as u64).max(4)),
                        diff.len() as u32,
                    ),
                    output.range(out_at[0], (4 * a * pixels).max(4)),
                    (n > 0).then(|| output.range(out_at[1], 8 * n * pixels)),
                )
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut out = vec![0.0f32; (a * pixels) as usize];
            let mut out_da = vec![0.0f32; (2 * n * pixels) as usize];
            get(bytes, out_at[0], &mut out);
            get(bytes, out_at[1], &mut out_da);
            Ok((out, out_da))
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }

    /// Records `interpolate`'s backward over caller buffers, after
    /// [`HardRasterizer::record_visible_tiles`] (grow 0) and [`HardRasterizer::read_slots`] for
    /// the same `rast` (with `ranges` `(0, T)` per minibatch item): the gradients of `attr` (its
    /// rows, over [`vertex_lists`] with `layout.per_item`), of `rast` and of `rast_db` (with
    /// `dda`, the upstream gradient of `out_da`).
    #[allow(clippy::too_many_arguments)]
    pub fn record_interpolate_grad(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        layout: AttrLayout,
        bufs: InterpolateGradBuffers<'_>,
        lists: (BufferRange<'_>, BufferRange<'_>),
        grad_attr: BufferRange<'_>,
        grad_rast: BufferRange<'_>,
        grad_rast_db: BufferRange<'_>,
    ) -> Result<()> {
        let ctx = rec.context();
        let pixels = plan.pixels();
        let a = layout.attr_count;
        let n = if bufs.rast_db.is_some() && bufs.dda.is_some() {
            bufs.diff.1
        } else {
            0
        };
        if u64::from(a) * 64 * (1 + u64::from(n))
            > ctx.info().shader_loop_limit().unwrap_or(u64::MAX)
        {
            return Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                what: "interpolate backward: the attributes of one tile".into(),
                need: u64::from(a) * 64 * (1 + u64::from(n)),
                max: ctx.info().shader_loop_limit().unwrap_or(u64::MAX),
                device: ctx.info().name.clone(),
                hint: "interpolate fewer attributes at once",
            });
        }
        let push = self.grad_scratch(ctx, plan, 3 * a, 0, "interpolate backward")?;
        let push = HardPush {
            instanced: u32::from(layout.per_item),
            attr_count: a,
            diff_count: n,
            ..push
        };
        let rows = if layout.per_item {
            plan.ranges.len() as u32
        } else {
            1
        } * layout.vertex_count;
        grad_rast.require(16 * pixels, "the gradient of rast")?;
        grad_rast_db.require(16 * pixels, "the gradient of rast_db")?;
        let g = &self.grads;
        let items = u64::from(push.items);
        rec.pass("hard interpolate backward", |rec| {
            rec.dispatch(
                &self.interp_pixel_grad,
                &specs::HardInterpPixelGradBindings {
                    attr: bufs.attr,
                    tri: bufs.tri,
                    rast: bufs.rast.sub(0, 16 * pixels),
                    diff: bufs.diff.0,
                    dy: bufs.dy,
                    dda: bufs.dda.unwrap_or(bufs.dy),
                    grad_rast: grad_rast.sub(0, 16 * pixels),
                    grad_rast_db: grad_rast_db.sub(0, 16 * pixels),
                }
                .for_kernel(&self.interp_pixel_grad)?,
                &push,
                groups(pixels, 64)?,
            )?;
            if push.slots > 0 {
                rec.dispatch(
                    &self.interp_grad,
                    &specs::HardInterpGradBindings {
                        ranges: bufs.ranges,
                        rast: bufs.rast.sub(0, 16 * pixels),
                        rast_db: bufs.rast_db.unwrap_or(bufs.rast).sub(0, 16 * pixels),
                        diff: bufs.diff.0,
                        dy: bufs.dy,
                        dda: bufs.dda.unwrap_or(bufs.dy),
                        boxes: g.boxes.as_ref().expect("made").range(0, 16 * items),
                        offsets: g.offsets.as_ref().expect("made").range(0, 4 * items),
                        partials: g
                            .partials
                            .as_ref()
                            .expect("reserved")
                            .range(0, 12 * u64::from(a) * u64::from(push.slots)),
                    }
                    .for_kernel(&self.interp_grad)?,
                    &push,
                    groups(u64::from(push.slots), 64)?,
                )?;
            }
            self.record_reduce_gather(rec, &push, rows, lists, grad_attr)
        })
    }

    /// The backward of [`HardRasterizer::interpolate`] on host slices (`dy [B, H, W, A]`, `dda
    /// [B, H, W, 2N]`). Waits for the device.
    #[allow(clippy::too_many_arguments)]
    pub fn interpolate_grad(
        &mut self,
        ctx: &Context,
        attr: &[f32],
        layout: AttrLayout,
        rast: &[f32],
        tri: &[[u32; 3]],
        resolution: [u32; 2],
        rast_db: Option<&[f32]>,
        diff: &[u32],
        dy: &[f32],
        dda: Option<&[f32]>,
    ) -> Result<InterpolateGrads32> {
        let plan = Self::interpolate_plan(ctx, layout, rast.len(), tri, resolution)?;
        check_attr(attr, layout, &plan, rast_db, diff)?;
        let pixels = plan.pixels();
        let a = u64::from(layout.attr_count);
        let n = diff.len() as u64;
        if dy.len() as u64 != a * pixels {
            return Err(Error::Input(format!(
                "interpolate backward: the output's gradient holds {} floats, not {}",
                dy.len(),
                a * pixels
            )));
        }
        let dda = dda.filter(|_| rast_db.is_some() && n > 0);
        if let Some(d) = dda {
            if d.len() as u64 != 2 * n * pixels {
                return Err(Error::Input(format!(
                    "interpolate backward: the derivatives' gradient holds {} floats, not {}",
                    d.len(),
                    2 * n * pixels
                )));
            }
        }
        let (row_offsets, row_entries) = vertex_lists(&plan, tri, layout.per_item);
        let at = layout_of(&[
            4 * attr.len() as u64,
            12 * tri.len() as u64,
            8 * plan.ranges.len() as u64,
            16 * pixels,
            16 * pixels,
            4 * n,
            4 * a * pixels,
            8 * n * pixels,
            4 * row_offsets.len() as u64,
            4 * row_entries.len() as u64,
        ]);
        let input = host_buffer(
            ctx,
            &mut self.host.inputs,
            "hard inputs",
            at[10],
            MemoryKind::Upload,
        )?;
        {
            let bytes = input
                .mapped_mut()
                .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
            put(bytes, at[0], attr);
            put(bytes, at[1], tri);
            put(bytes, at[2], &plan.ranges);
            put(bytes, at[3], rast);
            if let Some(d) = rast_db {
                put(bytes, at[4], d);
            }
            put(bytes, at[5], diff);
            put(bytes, at[6], dy);
            if let Some(d) = dda {
                put(bytes, at[7], d);
            }
            put(bytes, at[8], &row_offsets);
            put(bytes, at[9], &row_entries);
        }
        let out_at = layout_of(&[4 * attr.len() as u64, 16 * pixels, 16 * pixels]);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "hard outputs",
            out_at[3],
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made above");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            let rast_r = input.range(at[3], 16 * pixels);
            let ranges = input.range(at[2], 8 * plan.ranges.len() as u64);
            self.submit(ctx, |s, rec| {
                s.record_visible_tiles(rec, &plan, rast_r, ranges, 0)
            })?;
            self.read_slots(ctx)?;
            let bufs = InterpolateGradBuffers {
                attr: input.range(at[0], (4 * attr.len() as u64).max(4)),
                tri: input.range(at[1], (12 * tri.len() as u64).max(4)),
                ranges,
                rast: rast_r,
                rast_db: rast_db.map(|_| input.range(at[4], 16 * pixels)),
                diff: (input.range(at[5], (4 * n).max(4)), n as u32),
                dy: input.range(at[6], (4 * a * pixels).max(4)),
                dda: dda.map(|_| input.range(at[7], 8 * n * pixels)),
            };
            let lists = (
                input.range(at[8], 4 * row_offsets.len() as u64),
                input.range(at[9], (4 * row_entries.len() as u64).max(4)),
            );
            self.submit(ctx, |s, rec| {
                s.record_interpolate_grad(
                    rec,
                    &plan,
                    layout,
                    bufs,
                    lists,
                    output.range(out_at[0], (4 * attr.len() as u64).max(4)),
                    output.range(out_at[1], 16 * pixels),
                    output.range(out_at[2], 16 * pixels),
                )
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut g = InterpolateGrads32 {
                attr: vec![0.0; attr.len()],
                rast: vec![0.0; (4 * pixels) as usize],
                rast_db: vec![0.0; (4 * pixels) as usize],
            };
            get(bytes, out_at[0], &mut g.attr);
            get(bytes, out_at[1], &mut g.rast);
            get(bytes, out_at[2], &mut g.rast_db);
            Ok(g)
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }
}

/// The caller buffers `interpolate`'s backward reads.
#[derive(Clone, Copy)]
pub struct InterpolateGradBuffers<'a> {
    /// f32 attributes.
    pub attr: BufferRange<'a>,
    /// u32 triangles.
    pub tri: BufferRange<'a>,
    /// `(0, T)` per minibatch item.
    pub ranges: BufferRange<'a>,
    /// `[B, H, W, 4]`.
    pub rast: BufferRange<'a>,
    /// `[B, H, W, 4]`, when derivatives were asked for.
    pub rast_db: Option<BufferRange<'a>>,
    /// The differentiated attributes' indices (u32) and their count.
    pub diff: (BufferRange<'a>, u32),
    /// The output's gradient, A f32 a pixel.
    pub dy: BufferRange<'a>,
    /// The derivatives' gradient, 2N f32 a pixel.
    pub dda: Option<BufferRange<'a>>,
}

/// Checks `interpolate`'s arrays against its layout and plan.
fn check_attr(
    attr: &[f32],
    layout: AttrLayout,
    plan: &HardPlan,
    rast_db: Option<&[f32]>,
    diff: &[u32],
) -> Result<()> {
    let sets = if layout.per_item {
        plan.ranges.len()
    } else {
        1
    };
    let need = sets * layout.vertex_count as usize * layout.attr_count as usize;
    if attr.len() != need || layout.attr_count == 0 {
        return Err(Error::Input(format!(
            "interpolate: attr holds {} floats, the layout needs {need} ({sets} × {} × {})",
            attr.len(),
            layout.vertex_count,
            layout.attr_count
        )));
    }
    if let Some(i) = attr.iter().position(|v| !v.is_finite()) {
        return Err(Error::Input(format!(
            "interpolate: attribute {} of vertex row {} is not finite",
            i % layout.attr_count as usize,
            i / layout.attr_count as usize
        )));
    }
    if let Some(d) = rast_db {
        if d.len() as u64 != 4 * plan.pixels() {
            return Err(Error::Input(format!(
                "interpolate: rast_db holds {} floats, rast {}",
                d.len(),
                4 * plan.pixels()
            )));
        }
    }
    if let Some(&j) = diff.iter().find(|&&j| j >= layout.attr_count) {
        return Err(Error::Input(format!(
            "interpolate: diff_attrs names attribute {j} of {}",
            layout.attr_count
        )));
    }
    Ok(())
}
