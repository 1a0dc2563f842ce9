//! Sphere probing, forward and backward (SPEC §5), on screen tiles.
//!
//! **Forward.** Every anchor j is a sphere of radius τ. Per view k, `probe_items.comp` writes
//! the anchor as a binning item ([`ProbeItem`]): a screen box that holds the sphere's projection
//! (its exact extent on each screen axis, within the box of its τ-cube's projected corners), the
//! flag [`FLAG_VALID`] (the cube is wholly in front of the camera; otherwise the anchor is not
//! probed in that view) and [`FLAG_INSIDE`] (its centre projects into the silhouette). The
//! items are binned to screen tiles by the generic binning's tile rectangles
//! ([`crate::primitives::binning`]'s `tile_rect`), but without its scatter and sort: the items
//! kernel sets the anchor's bit in an anchor mask per tile (`⌈anchors / 32⌉` words, integer
//! `atomicOr`), `bin_mask_counts.comp` counts each tile's bits, a scan gives each tile's first
//! entry, the entry count is read back, and `probe_mask_list.comp` writes each tile's anchors in
//! index order: the entries the generic binning's stable sort gives, at a fraction of the cost
//! on llvmpipe. Then one invocation per ray, the rays taken in tile order (a stable
//! [`RadixSort`] of their tile keys and the binning's ranges pass), visits the anchors of its
//! tile in anchor order (`probe_forward.comp`: per subgroup, batches of anchors loaded one per
//! lane and broadcast with shuffles) and aggregates, with G of [`Aggregate`](super::Aggregate),
//! the φ of those whose centre lies within τ of the ray's line (within
//! [`ProbeSettings::tau_outside`] for a ray outside the silhouette, when set; the items' boxes
//! hold the larger radius), skipping under boundary-aware
//! assignment the anchors whose [`FLAG_INSIDE`] differs from the ray's label. No hit: ψ = 0. The
//! loss is `L_sil = mean_i (ψ_i − S_i)²` over every ray of every view, summed in a fixed order.
//! `probe_forward_brute.comp` visits every anchor instead: the baseline the tiled pass equals bit
//! for bit. The aggregation and the assignment are specialization constants of both (and of
//! the backward): a pipeline per combination, built on first use.
//!
//! **Backward.** `dL/dφ_j = (2 / N) Σ_i (ψ_i − S_i) dψ_i/dφ_j`, without float atomics. Under
//! G = max, dψ_i/dφ_j is 1 for the anchor ψ_i came from and 0 otherwise: the rays are sorted by
//! that anchor (a stable sort) and one invocation per anchor sums its rays in ray order
//! (`probe_aux_keys.comp`, `probe_max_grad.comp`; when all rays fit the driver's loop cap).
//! Otherwise one invocation per binned (anchor, tile) entry sums over the tile's rays in ray
//! order and writes the partial at the entry (`probe_backward.comp`: per subgroup, batches of
//! rays broadcast with shuffles); one invocation per anchor adds its entries, view by view and
//! tile by tile, finding them from the masks (`probe_reduce.comp`).
//!
//! **Recording.** Exact: the binning's entry count is read back between two submissions:
//! [`Prober::record_count`] (submission 1), [`Prober::finish_count`] (host), then
//! [`Prober::record_forward`] and [`Prober::record_backward`] (submission 2). The anchors, φ and
//! rays must stay unchanged in between. [`Prober::run`] does all of it and reads the results back.
//! Guarded, for loops that never wait (the field fit): [`Prober::reserve_guarded`] sizes the
//! entry buffers for a capacity, and [`Prober::record_guarded`] records the count, an
//! [`IterationGate`]'s check of it and, gated, the forward and backward (and the caller's
//! rest of the iteration) into one command buffer; they work over the capacity and the kernels
//! read the count themselves. The results are the exact path's, bit for bit.

use bytemuck::{Pod, Zeroable};

use super::ProbeSettings;
use super::targets::GpuTargets;
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{GradOut, check_binding, check_floats, check_texels, groups};
use crate::primitives::sum::{Sum, SumPush};
use std::sync::Arc;

use crate::gpu::gate::IterationGate;
use crate::gpu::pass_size;
use crate::gpu::{
    Buffer, BufferRange, Context, Kernel, KernelVariants, MemoryKind, Recorder, specs,
};
use crate::primitives::binning::{self, BinJob, Binner, ItemLayout, TileGrid};
use crate::primitives::scan::{Scan, ScanScratch};
use crate::primitives::{RadixSort, SortScratch};

/// [`ProbeItem::flags`]: every corner of the anchor's τ-cube is in front of the camera.
pub const FLAG_VALID: u32 = 1;
/// [`ProbeItem::flags`]: the anchor's centre projects into the silhouette.
pub const FLAG_INSIDE: u32 = 2;
/// [`RayOut::aux`] of a ray without hits.
pub const NO_HIT: u32 = u32::MAX;

/// One anchor in one view, as the binning reads it. Twin of `ProbeItem` in
/// `kernels/include/probe.glsl`; 32 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ProbeItem {
    /// Screen box `(x_min, y_min, x_max, y_max)` holding the projected τ-sphere: its extent
    /// on each axis ([`cpu::sphere_extent`]) within the box of the projected τ-cube's corners.
    pub screen_box: [f32; 4],
    /// [`FLAG_VALID`] | [`FLAG_INSIDE`].
    pub flags: u32,
    /// The centre's screen x.
    pub sx: f32,
    /// The centre's screen y.
    pub sy: f32,
    /// The centre's depth.
    pub depth: f32,
}

/// What the forward leaves per ray. Twin of `RayOut` in `kernels/include/probe.glsl`; 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RayOut {
    /// ψ.
    pub psi: f32,
    /// (ψ − S)².
    pub err2: f32,
    /// Max and log-sum-exp: the anchor of the largest φ (the first on a tie); union: how many
    /// hits have 1 − φ = 0; [`NO_HIT`] without hits.
    pub aux: u32,
    /// Union: the product of the nonzero 1 − φ.
    pub aux_f: f32,
}

/// Push constants of `probe_items.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ItemsPush {
    anchors: u32,
    views: u32,
    width: u32,
    height: u32,
    tau: f32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
}

/// Push constants of `probe_forward.comp` and `probe_forward_brute.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ForwardPush {
    rays: u32,
    anchors: u32,
    width: u32,
    height: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    mode: u32,
    inv_s: f32,
    tau2: f32,
    temperature: f32,
    inv_t: f32,
    boundary_aware: u32,
    tau2_outside: f32,
    /// The pass's anchors of each ray's list (`CARRY` in `probe_forward.glsl`).
    pass_begin: u32,
    pass_end: u32,
}

/// Push constants of `probe_mask_list.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ListPush {
    tiles: u32,
    words_per_tile: u32,
    /// The pass's words of each tile's mask (`PARTS` in the kernel).
    word_begin: u32,
    word_end: u32,
}

/// Push constants of `bin_mask_counts.comp` and `probe_mask_list.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct WordsPush {
    tiles: u32,
    words_per_tile: u32,
    pad: u32,
    /// `bin_mask_counts.comp`: the first summary word (0: none).
    summary_offset: u32,
}

/// Push constants of `probe_aux_keys.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct AuxKeysPush {
    rays: u32,
    anchors: u32,
    views: u32,
    pad: u32,
}

/// Push constants of `probe_max_grad.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct MaxGradPush {
    anchors: u32,
    views: u32,
    accumulate: u32,
    coef: f32,
}

/// Push constants of `probe_ray_keys.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct KeysPush {
    rays: u32,
    width: u32,
    height: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    pad: [u32; 2],
}

/// Push constants of `probe_backward.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct BackwardPush {
    entries: u32,
    anchors: u32,
    width: u32,
    height: u32,
    tiles_x: u32,
    tiles_y: u32,
    mode: u32,
    boundary_aware: u32,
    inv_s: f32,
    tau2: f32,
    inv_t: f32,
    /// Where `offsets` holds the entry count (the tile count).
    total_index: u32,
    tau2_outside: f32,
    pad: [u32; 3],
}

/// Push constants of `probe_reduce.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ReducePush {
    anchors: u32,
    views: u32,
    entries: u32,
    accumulate: u32,
    coef: f32,
    words_per_tile: u32,
    tiles_x: u32,
    tiles_y: u32,
}

/// The f32 constants the kernels and the twin share.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Constants {
    pub inv_s: f32,
    /// The larger radius: the items' screen boxes hold it.
    pub tau: f32,
    /// τ² of the rays inside the silhouettes.
    pub tau2: f32,
    /// τ² of the rays outside.
    pub tau2_outside: f32,
    pub temperature: f32,
    pub inv_t: f32,
}

impl Constants {
    /// τ² of a ray with `label` (`ray_tau2` of `probe.glsl`).
    pub fn ray_tau2(&self, label: f32) -> f32 {
        if label >= 0.5 {
            self.tau2
        } else {
            self.tau2_outside
        }
    }

    pub fn new(settings: &ProbeSettings, width: u32, height: u32) -> Self {
        let tau_outside = settings.tau_outside.unwrap_or(settings.tau);
        Self {
            inv_s: (1.0 / f64::from(width.min(height))) as f32,
            tau: settings.tau.max(tau_outside) as f32,
            tau2: (settings.tau * settings.tau) as f32,
            tau2_outside: (tau_outside * tau_outside) as f32,
            temperature: settings.temperature as f32,
            inv_t: (1.0 / settings.temperature) as f32,
        }
    }
}

/// What [`Prober::run`] reads back.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeRun {
    /// Per ray.
    pub outs: Vec<RayOut>,
    /// L_sil.
    pub loss: f32,
    /// dL_sil/dφ per anchor.
    pub d_phi: Vec<f32>,
    /// Binned (anchor, tile) entries.
    pub entries: u64,
}

/// The probing pipelines and their buffers, for one set of targets and settings.
pub struct Prober {
    items_kernel: Kernel,
    /// The forward, brute-force forward and backward kernels are specialized on
    /// [`Prober::modes`] (the aggregation and the assignment).
    forward_kernel: KernelVariants,
    brute_kernel: KernelVariants,
    keys_kernel: Kernel,
    backward_kernel: KernelVariants,
    reduce_kernel: Kernel,
    mask_counts_kernel: Kernel,
    /// Specialized by whether it writes each entry's tile (constant 0: not under G = max).
    mask_list_kernel: KernelVariants,
    aux_keys_kernel: Kernel,
    max_grad_kernel: Kernel,
    binner: Binner,
    scan: Scan,
    scan_scratch: ScanScratch,
    sort: RadixSort,
    sort_scratch: SortScratch,
    sum: Sum,
    job: BinJob,
    settings: ProbeSettings,
    constants: Constants,
    items: Buffer,
    outs: Buffer,
    /// Every ray's running aggregate between the passes of a list too long for one
    /// (`CARRY` in `probe_forward.glsl`).
    carry: Buffer,
    ray_keys: Buffer,
    ray_order: Buffer,
    ray_ranges: Buffer,
    /// G = max: the rays' anchor keys, the rays sorted by them, each anchor's range.
    aux_keys: Buffer,
    aux_order: Buffer,
    item_ranges: Buffer,
    /// Per tile, a bit per anchor (`W` words): the anchors binned to it.
    masks: Buffer,
    /// Per item, its packed tile rectangle.
    rects: Buffer,
    /// Each tile's first entry (the exclusive scan of their entry counts), then the entry
    /// count: `tiles + 1`.
    offsets: Buffer,
    /// Each mask word's first entry within its tile.
    word_prefix: Buffer,
    /// The anchor and the tile of every entry, sorted by tile, and its partial gradient.
    list: Buffer,
    list_tiles: Buffer,
    partials: Buffer,
    entry_capacity: u64,
    /// The entry count [`Prober::finish_count`] read, or for a guarded binning
    /// ([`Prober::reserve_guarded`]) the capacity, an upper bound of it.
    entries: Option<u64>,
    /// The entry buffers were sized by [`Prober::reserve_guarded`]: the count stays on the GPU.
    guarded: bool,
    loss: Buffer,
}

/// Fails with [`Error::Limit`] when a kernel loop of `iterations` would pass the driver's cap.
fn check_loop(ctx: &Context, what: &str, iterations: u64) -> Result<()> {
    if let Some(limit) = ctx.info().shader_loop_limit() {
        if iterations > limit {
            return Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                what: format!("sphere probing: {what}"),
                need: iterations,
                max: limit,
                device: ctx.info().name.clone(),
                hint: "use fewer anchors, rays or views per tile, or smaller tiles",
            });
        }
    }
    Ok(())
}

/// `W`: the words of a tile's anchor mask.
fn words_per_tile(anchors: u32) -> u64 {
    u64::from(anchors).div_ceil(32)
}

/// Lanes of a subgroup the tiled kernels use (`min(gl_SubgroupSize, 64)`) and the words of its
/// ballot.
fn lanes(ctx: &Context) -> (u64, u64) {
    let lanes = u64::from(ctx.info().subgroup_size.clamp(1, 64));
    (lanes, lanes.div_ceil(32))
}

/// Loop iterations of one invocation of `probe_mask_list.comp` at most, for masks of `words`
/// words listed `per_pass` words a pass: the bit counts of the words before the pass, then per
/// word of the pass one iteration and one per set bit (at most 32).
fn list_iterations(words: u64, per_pass: u64) -> u64 {
    words + 32 * per_pass.min(words) + 2
}

/// Loop iterations of one invocation of `probe_forward.comp` at most, when the tiles hold
/// `total` entries with at most `run` in one tile: a subgroup's rays lie in at most `lanes`
/// distinct tiles (one pass of the outer loop each); per tile, a batch per `lanes` entries, the
/// ballot's words per batch and a pass per kept entry.
fn forward_iterations(ctx: &Context, total: u64, run: u64) -> u64 {
    let (lanes, words) = lanes(ctx);
    let entries = total.min(lanes * run);
    let batches = entries.div_ceil(lanes) + lanes;
    lanes + batches * (1 + words) + entries
}

/// Loop iterations of one invocation of `probe_backward.comp` at most, for `rays` rays of which
/// at most `per_view` in one view (a tile holds one view's rays): a subgroup's entries lie in
/// at most `lanes` distinct tiles; per tile, a batch per `lanes` rays and a pass per ray.
fn backward_iterations(ctx: &Context, rays: u64, per_view: u64) -> u64 {
    let (lanes, _) = lanes(ctx);
    let visited = rays.min(lanes * per_view);
    lanes + visited.div_ceil(lanes) + lanes + visited
}

impl Prober {
    /// Pipelines and buffers for probing `gpu`'s views with `settings`' counts: `anchors`
    /// anchors and `rays_per_view` rays per view.
    pub fn new(ctx: &Context, gpu: &GpuTargets, settings: &ProbeSettings) -> Result<Self> {
        settings.validate()?;
        let views = gpu.view_count();
        let anchors = u64::from(settings.anchors);
        let rays = u64::from(views) * u64::from(settings.rays_per_view);
        let grid = TileGrid::new(gpu.width(), gpu.height(), settings.tile_size)?;
        let job = BinJob {
            grid,
            layout: ItemLayout {
                stride_words: 8,
                box_offset: 0,
                flag_offset: 4,
                flag_mask: FLAG_VALID,
            },
            items_per_view: settings.anchors,
            views,
            first_item: 0,
        };
        if job.max_entries() > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "sphere probing: {} anchors over {} tiles in {views} views could bin more than \
                 2^32 entries; use fewer anchors or views, or larger tiles",
                settings.anchors,
                grid.tiles_per_view()
            )));
        }
        // A tile belongs to one view: the backward visits at most one view's rays per tile.
        check_loop(
            ctx,
            &format!("{} rays per view (backward)", settings.rays_per_view),
            backward_iterations(ctx, rays, u64::from(settings.rays_per_view)),
        )?;
        let items = anchors * u64::from(views);
        check_binding(ctx, "sphere probing: anchor items", 32 * items)?;
        check_binding(ctx, "sphere probing: rays", 16 * rays)?;
        // The items and forward kernels fetch these as texels.
        check_texels(ctx, "sphere probing: anchor items", 32 * items)?;
        check_texels(ctx, "sphere probing: rays", 16 * rays)?;
        check_texels(ctx, "sphere probing: anchors", 16 * anchors)?;
        check_texels(ctx, "sphere probing: views", 160 * u64::from(views))?;
        let tiles = job.tile_count();
        if grid.tiles_x > 0xFFFF || grid.tiles_y > 0xFFFF {
            return Err(Error::Limit(format!(
                "sphere probing: {} x {} tiles per view (at most 65535 each way)",
                grid.tiles_x, grid.tiles_y
            )));
        }
        let words = tiles * words_per_tile(settings.anchors);
        check_binding(ctx, "sphere probing: tile anchor masks", 4 * words)?;
        // A tile's bit count loops over its mask's words, and each pass of its list over them
        // and one word's bits.
        check_loop(
            ctx,
            &format!("{} anchors (a tile's mask words)", settings.anchors),
            list_iterations(words_per_tile(settings.anchors), 1),
        )?;
        check_binding(ctx, "sphere probing: anchor tile rectangles", 8 * items)?;
        Ok(Self {
            items_kernel: Kernel::new(ctx, &specs::PROBE_ITEMS)?,
            forward_kernel: KernelVariants::new(&specs::PROBE_FORWARD),
            brute_kernel: KernelVariants::new(&specs::PROBE_FORWARD_BRUTE),
            keys_kernel: Kernel::new(ctx, &specs::PROBE_RAY_KEYS)?,
            backward_kernel: KernelVariants::new(&specs::PROBE_BACKWARD),
            reduce_kernel: Kernel::new(ctx, &specs::PROBE_REDUCE)?,
            mask_counts_kernel: Kernel::new(ctx, &specs::BIN_MASK_COUNTS)?,
            mask_list_kernel: KernelVariants::new(&specs::PROBE_MASK_LIST),
            aux_keys_kernel: Kernel::new(ctx, &specs::PROBE_AUX_KEYS)?,
            max_grad_kernel: Kernel::new(ctx, &specs::PROBE_MAX_GRAD)?,
            binner: Binner::new(ctx)?,
            scan: Scan::new(ctx)?,
            scan_scratch: ScanScratch::new(ctx, tiles)?,
            sort: RadixSort::new(ctx)?,
            sort_scratch: SortScratch::new(ctx, rays)?,
            sum: Sum::new(ctx)?,
            job,
            settings: *settings,
            constants: Constants::new(settings, gpu.width(), gpu.height()),
            items: ctx.create_buffer("probe anchor items", 32 * items, MemoryKind::Device)?,
            outs: ctx.create_buffer("probe ray outputs", 16 * rays, MemoryKind::Device)?,
            carry: ctx.create_buffer("probe ray carry", 16 * rays, MemoryKind::Device)?,
            ray_keys: ctx.create_buffer("probe ray tile keys", 8 * rays, MemoryKind::Device)?,
            ray_order: ctx.create_buffer("probe rays by tile", 4 * rays, MemoryKind::Device)?,
            ray_ranges: ctx.create_buffer(
                "probe ray tile ranges",
                8 * tiles,
                MemoryKind::Device,
            )?,
            aux_keys: ctx.create_buffer("probe ray item keys", 8 * rays, MemoryKind::Device)?,
            aux_order: ctx.create_buffer("probe rays by item", 4 * rays, MemoryKind::Device)?,
            item_ranges: ctx.create_buffer(
                "probe ray anchor ranges",
                8 * (anchors + 1),
                MemoryKind::Device,
            )?,
            masks: ctx.create_buffer("probe tile anchor masks", 4 * words, MemoryKind::Device)?,
            rects: ctx.create_buffer("probe anchor tile rects", 8 * items, MemoryKind::Device)?,
            offsets: ctx.create_buffer(
                "probe tile entry offsets",
                4 * (tiles + 1),
                MemoryKind::Device,
            )?,
            word_prefix: ctx.create_buffer(
                "probe mask word prefixes",
                4 * words,
                MemoryKind::Device,
            )?,
            list: ctx.create_buffer("probe entry anchors", 4, MemoryKind::Device)?,
            list_tiles: ctx.create_buffer("probe entry tiles", 4, MemoryKind::Device)?,
            partials: ctx.create_buffer("probe partials", 4, MemoryKind::Device)?,
            entry_capacity: 1,
            entries: None,
            guarded: false,
            loss: ctx.create_buffer("probe silhouette loss", 4, MemoryKind::Device)?,
        })
    }

    fn rays(&self) -> u64 {
        u64::from(self.job.views) * u64::from(self.settings.rays_per_view)
    }

    fn anchors(&self) -> u64 {
        u64::from(self.settings.anchors)
    }

    fn check_inputs(
        &self,
        gpu: &GpuTargets,
        anchors: &BufferRange<'_>,
        phi: Option<&BufferRange<'_>>,
        rays: Option<&BufferRange<'_>>,
    ) -> Result<()> {
        if gpu.view_count() != self.job.views
            || gpu.width() != self.job.grid.width
            || gpu.height() != self.job.grid.height
        {
            return Err(Error::Input(
                "sphere probing: recorded with other targets than the prober was made for".into(),
            ));
        }
        check_floats("sphere probing: anchors", anchors, 4 * self.anchors())?;
        if let Some(phi) = phi {
            check_floats("sphere probing: φ at the anchors", phi, self.anchors())?;
        }
        if let Some(rays) = rays {
            check_floats("sphere probing: rays", rays, 4 * self.rays())?;
        }
        Ok(())
    }

    /// Records the anchor items of every view ([`Prober::items`]) and their tiles' anchor masks
    /// (the anchors fetched as texels, as [`Prober::record_forward`] says);
    /// [`Prober::record_count`] includes it.
    pub fn record_items(
        &self,
        rec: &mut Recorder<'_>,
        gpu: &GpuTargets,
        anchors: BufferRange<'_>,
    ) -> Result<()> {
        self.check_inputs(gpu, &anchors, None, None)?;
        let push = ItemsPush {
            anchors: self.settings.anchors,
            views: self.job.views,
            width: self.job.grid.width,
            height: self.job.grid.height,
            tau: self.constants.tau,
            tile_size: self.job.grid.tile_size,
            tiles_x: self.job.grid.tiles_x,
            tiles_y: self.job.grid.tiles_y,
        };
        rec.fill(self.masks.whole(), 0);
        rec.dispatch(
            &self.items_kernel,
            &specs::ProbeItemsBindings {
                views: gpu.views().whole(),
                anchors: anchors.sub(0, 16 * self.anchors()),
                masks: gpu.masks().whole(),
                items: self.items.whole(),
                tile_masks: self.masks.whole(),
                rects: self.rects.whole(),
            }
            .for_kernel(&self.items_kernel)?,
            &push,
            groups(self.job.item_count(), 64)?,
        )
    }

    /// `W`: the words of a tile's anchor mask.
    fn words_per_tile(&self) -> u64 {
        words_per_tile(self.settings.anchors)
    }

    /// Submission 1: records the anchor items with every tile's anchor mask (`probe_items.comp`,
    /// by the generic binning's tile rectangles), each tile's entry count
    /// (`bin_mask_counts.comp`) and their exclusive scan (each tile's first entry), and the
    /// entry count after them.
    pub fn record_count(
        &self,
        rec: &mut Recorder<'_>,
        gpu: &GpuTargets,
        anchors: BufferRange<'_>,
    ) -> Result<()> {
        rec.pass("  items", |rec| self.record_items(rec, gpu, anchors))?;
        rec.pass("  mask scan", |rec| self.record_mask_scan(rec))
    }

    fn record_mask_scan(&self, rec: &mut Recorder<'_>) -> Result<()> {
        let tiles = self.job.tile_count();
        let counts = self.offsets.range(0, 4 * tiles);
        rec.dispatch(
            &self.mask_counts_kernel,
            &specs::BinMaskCountsBindings {
                masks: self.masks.whole(),
                counts,
            }
            .for_kernel(&self.mask_counts_kernel)?,
            &WordsPush {
                tiles: tiles as u32,
                words_per_tile: self.words_per_tile() as u32,
                pad: 0,
                summary_offset: 0,
            },
            groups(tiles, 64)?,
        )?;
        self.scan
            .record(rec, &self.scan_scratch, counts, counts, tiles)?;
        // offsets[tiles] = the entry count: the end of the last tile's run.
        rec.copy(self.scan_scratch.total(), 0, &self.offsets, 4 * tiles, 4);
        Ok(())
    }

    /// Submission 2: the anchor and the tile of every entry (the tile only where the backward
    /// reads it: not under G = max), in tile order, from the masks and their offsets
    /// (`probe_mask_list.comp`). The forwards record it.
    fn record_list(&self, rec: &mut Recorder<'_>) -> Result<()> {
        let total = self.entry_count()?;
        let tiles = self.job.tile_count();
        if total == 0 {
            return Ok(());
        }
        let ctx = rec.context();
        let write_tiles = u32::from(!self.max_by_rays(ctx));
        // One pass over every word where a tile's words and anchors stay under the loop cap,
        // else passes of as many words as the cap allows.
        let words = self.words_per_tile();
        let run = total.min(self.anchors());
        let limit = ctx.info().shader_loop_limit();
        let per_pass = if limit.is_none_or(|l| words + run + 2 <= l) {
            words
        } else {
            pass_size(words, limit, |k| list_iterations(words, k))
        };
        let passes = words.max(1).div_ceil(per_pass.max(1));
        let kernel = self
            .mask_list_kernel
            .get(ctx, &[write_tiles, u32::from(passes > 1)])?;
        let bindings = specs::ProbeMaskListBindings {
            masks: self.masks.whole(),
            offsets: self.offsets.whole(),
            word_prefix: self.word_prefix.whole(),
            list: self.list.range(0, 4 * total),
            list_tiles: self.list_tiles.range(0, 4 * total),
        };
        for pass in 0..passes {
            if pass > 0 {
                rec.barrier();
            }
            rec.dispatch(
                &kernel,
                &bindings.for_kernel(&kernel)?,
                &ListPush {
                    tiles: tiles as u32,
                    words_per_tile: words as u32,
                    word_begin: (pass * per_pass) as u32,
                    word_end: ((pass + 1) * per_pass).min(words) as u32,
                },
                groups(tiles, 64)?,
            )?;
        }
        Ok(())
    }

    /// The entry count [`Prober::finish_count`] read, once it fits the entry buffers; guarded,
    /// the capacity (the kernels read the count).
    fn entry_count(&self) -> Result<u64> {
        let total = self.entries.ok_or_else(|| {
            Error::Misuse("sphere probing: the entry count is not known yet (finish_count)".into())
        })?;
        if total > self.entry_capacity {
            return Err(Error::Limit(
                "sphere probing: the entry buffers do not hold the entries (finish_count)".into(),
            ));
        }
        Ok(total)
    }

    /// After submission 1 finished: reads the entry count, sizes the entry buffers, and checks
    /// the tiled loops against the driver's cap. Returns the entry count.
    pub fn finish_count(&mut self, ctx: &Context) -> Result<u64> {
        let total = u64::from(ctx.read_buffer::<u32>(self.scan_scratch.total(), 0, 1)?[0]);
        self.size_entries(ctx, total)?;
        if total > self.entry_capacity {
            let cap = (total + total / 4)
                .min(binning::max_entries(ctx))
                .max(total);
            self.allocate_entries(ctx, cap)?;
        }
        self.entries = Some(total);
        self.guarded = false;
        Ok(total)
    }

    /// For loops that never wait for the count (a field fit's iterations): sizes the entry
    /// buffers for exactly `capacity` entries and checks the tiled loops against the driver's
    /// cap for any count up to it. Record each iteration's probing with
    /// [`Prober::record_guarded`]; the forward and backward then work over the capacity, each
    /// kernel reading the count itself.
    pub fn reserve_guarded(&mut self, ctx: &Context, capacity: u64) -> Result<()> {
        let capacity = capacity.max(1);
        if self.job.max_entries() > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "sphere probing: {} anchors over {} tiles in {} view(s) could count past 2^32 \
                 entries; use fewer anchors or views, or larger tiles",
                self.anchors(),
                self.job.grid.tiles_per_view(),
                self.job.views
            )));
        }
        self.size_entries(ctx, capacity)?;
        if capacity != self.entry_capacity {
            self.allocate_entries(ctx, capacity)?;
        }
        self.entries = Some(capacity);
        self.guarded = true;
        Ok(())
    }

    /// Entries the entry buffers hold.
    pub fn entry_capacity(&self) -> u64 {
        self.entry_capacity
    }

    /// The count's total (one `u32`, after [`Prober::record_count`]): what a gate checks.
    pub fn total_buffer(&self) -> BufferRange<'_> {
        self.scan_scratch.total().range(0, 4)
    }

    /// Records a guarded iteration's probing into any command buffer, with no read-back: the
    /// anchor items and the count ([`Prober::record_count`]), `gate`'s check of the count
    /// against the capacity of [`Prober::reserve_guarded`] for `iteration`, then — gated: they
    /// run only when the entries fit — whatever `then` records ([`Prober::record_forward`],
    /// [`Prober::record_backward`], and the rest of the caller's iteration). When the entries
    /// do not fit, none of the gated work runs and the gate's status says so
    /// ([`IterationGate::read`]): reserve more and record again.
    pub fn record_guarded(
        &self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        iteration: u32,
        gpu: &GpuTargets,
        anchors: BufferRange<'_>,
        then: impl FnOnce(&mut Recorder<'_>) -> Result<()>,
    ) -> Result<()> {
        if !self.guarded {
            return Err(Error::Misuse(
                "sphere probing: a guarded iteration needs Prober::reserve_guarded first".into(),
            ));
        }
        rec.pass("probe count", |rec| self.record_count(rec, gpu, anchors))?;
        gate.record_check(rec, self.total_buffer(), iteration, self.entry_capacity)?;
        gate.record_gated(rec, then)
    }

    /// Checks `total` entries (a count, or a guarded capacity) against the device: the
    /// binning's limit and the tiled loops' cap.
    fn size_entries(&self, ctx: &Context, total: u64) -> Result<()> {
        let max = binning::max_entries(ctx);
        if total > max {
            return Err(Error::DeviceLimit {
                kind: LimitKind::BinEntries,
                what: "sphere probing".into(),
                need: total,
                max,
                device: ctx.info().name.clone(),
                hint: "use fewer anchors or views, larger tiles or a smaller τ",
            });
        }
        // (A tile's list and the forward over it are folded in passes where the driver's loop
        // cap asks: `record_list`, `dispatch_forward`.)
        let views = u64::from(self.job.views);
        let per_anchor = total.min(views * self.job.grid.tiles_per_view());
        // Per view, a pass of the row loop per tile row and of the column loop per tile.
        check_loop(
            ctx,
            &format!("an anchor binned to {per_anchor} tiles (gradient sum)"),
            views + 2 * per_anchor,
        )
    }

    /// Replaces the entry buffers with ones of `cap` entries.
    fn allocate_entries(&mut self, ctx: &Context, cap: u64) -> Result<()> {
        let bytes = 4 * cap;
        check_binding(ctx, "sphere probing: entries", bytes)?;
        // Drop the old buffers before making the new ones.
        // Whole texels: the forward fetches the anchors of the entries as texels.
        check_texels(ctx, "sphere probing: entries", bytes)?;
        self.list = ctx.create_buffer(
            "probe entry anchors",
            bytes.next_multiple_of(crate::gpu::TEXEL_BYTES),
            MemoryKind::Device,
        )?;
        self.list_tiles = ctx.create_buffer("probe entry tiles", bytes, MemoryKind::Device)?;
        self.partials = ctx.create_buffer("probe partials", bytes, MemoryKind::Device)?;
        self.entry_capacity = cap;
        Ok(())
    }

    fn forward_push(&self) -> ForwardPush {
        let c = &self.constants;
        let g = &self.job.grid;
        ForwardPush {
            rays: self.rays() as u32,
            anchors: self.settings.anchors,
            width: g.width,
            height: g.height,
            tile_size: g.tile_size,
            tiles_x: g.tiles_x,
            tiles_y: g.tiles_y,
            mode: self.settings.aggregate.code(),
            inv_s: c.inv_s,
            tau2: c.tau2,
            temperature: c.temperature,
            inv_t: c.inv_t,
            boundary_aware: u32::from(self.settings.boundary_aware),
            tau2_outside: c.tau2_outside,
            pass_begin: 0,
            pass_end: u32::MAX,
        }
    }

    fn record_loss(&self, rec: &mut Recorder<'_>) -> Result<()> {
        self.sum.record(
            rec,
            self.outs.whole(),
            self.loss.whole(),
            SumPush {
                n: self.rays() as u32,
                stride: 4,
                offset: 1,
                out_index: 0,
                scale: (1.0 / self.rays() as f64) as f32,
                bias: 0.0,
            },
            1,
        )
    }

    /// Submission 2: records the rest of the binning, ψ per ray ([`Prober::outputs`]) and
    /// L_sil ([`Prober::loss_buffer`]). `phi` holds φ at the anchors (one `f32` each), `rays`
    /// the rays ([`Ray`](super::sampler::Ray) each, view-major, `rays_per_view` per view).
    /// The kernels fetch the anchors and the rays as texels (see [`crate::gpu::TEXEL_FORMAT`]):
    /// their ranges start at offsets aligned to `minTexelBufferOffsetAlignment`, as every
    /// softvk buffer's whole range does.
    pub fn record_forward(
        &self,
        rec: &mut Recorder<'_>,
        gpu: &GpuTargets,
        anchors: BufferRange<'_>,
        phi: BufferRange<'_>,
        rays: BufferRange<'_>,
    ) -> Result<()> {
        self.check_inputs(gpu, &anchors, Some(&phi), Some(&rays))?;
        rec.pass("  bin list", |rec| self.record_list(rec))?;
        let rays = rays.sub(0, 16 * self.rays());
        rec.pass("  ray sort", |rec| self.record_ray_sort(rec, rays))?;
        if self.rays() > 0 {
            rec.pass("  forward rays", |rec| {
                self.dispatch_forward(rec, gpu, &anchors, &phi, &rays)
            })?;
        }
        self.record_loss(rec)
    }

    /// The specialization constants of the forward, brute-force forward and backward kernels:
    /// `[MODE, BOUNDARY_AWARE]`.
    fn modes(&self) -> [u32; 2] {
        [
            self.settings.aggregate.code(),
            u32::from(self.settings.boundary_aware),
        ]
    }

    fn variant(&self, rec: &Recorder<'_>, variants: &KernelVariants) -> Result<Arc<Kernel>> {
        variants.get(rec.context(), &self.modes())
    }

    fn dispatch_forward(
        &self,
        rec: &mut Recorder<'_>,
        gpu: &GpuTargets,
        anchors: &BufferRange<'_>,
        phi: &BufferRange<'_>,
        rays: &BufferRange<'_>,
    ) -> Result<()> {
        let n = self.rays();
        // A tile holds each anchor at most once: its run is at most min(entries, anchors).
        let total = self.entry_count()?;
        let ctx = rec.context();
        let per_pass = pass_size(
            total.min(self.anchors()),
            ctx.info().shader_loop_limit(),
            |run| forward_iterations(ctx, total, run),
        );
        let passes = total.min(self.anchors()).max(1).div_ceil(per_pass);
        let kernel = self.forward_variant(rec, &self.forward_kernel, passes > 1)?;
        let bindings = specs::ProbeForwardBindings {
            rays: rays.sub(0, 16 * n),
            views: gpu.views().whole(),
            anchors: anchors.sub(0, 16 * self.anchors()),
            phi: phi.sub(0, 4 * self.anchors()),
            items: self.items.whole(),
            offsets: self.offsets.whole(),
            list: self.list.whole(),
            outs: self.outs.whole(),
            ray_order: self.ray_order.whole(),
            carry: self.carry.whole(),
        };
        self.dispatch_passes(
            rec,
            &kernel,
            &bindings.for_kernel(&kernel)?,
            (passes, per_pass),
        )
    }

    /// The forward kernel of the modes, with the carry between passes or without.
    fn forward_variant(
        &self,
        rec: &Recorder<'_>,
        variants: &KernelVariants,
        carry: bool,
    ) -> Result<Arc<Kernel>> {
        let [mode, aware] = self.modes();
        variants.get(rec.context(), &[mode, aware, u32::from(carry)])
    }

    /// `passes` dispatches of a forward kernel over every ray, each over its part of the
    /// anchor lists (`per_pass` anchors), with a barrier between.
    fn dispatch_passes(
        &self,
        rec: &mut Recorder<'_>,
        kernel: &Kernel,
        bindings: &[BufferRange<'_>],
        (passes, per_pass): (u64, u64),
    ) -> Result<()> {
        for pass in 0..passes {
            if pass > 0 {
                rec.barrier();
            }
            let bound = |k: u64| u32::try_from(k * per_pass).unwrap_or(u32::MAX);
            let push = ForwardPush {
                pass_begin: bound(pass),
                pass_end: bound(pass + 1),
                ..self.forward_push()
            };
            rec.dispatch(kernel, bindings, &push, groups(self.rays(), 64)?)?;
        }
        Ok(())
    }

    /// The brute-force forward (every anchor for every ray), after [`Prober::record_items`]:
    /// the same [`Prober::outputs`] and loss as [`Prober::record_forward`], bit for bit.
    pub fn record_forward_brute(
        &self,
        rec: &mut Recorder<'_>,
        gpu: &GpuTargets,
        anchors: BufferRange<'_>,
        phi: BufferRange<'_>,
        rays: BufferRange<'_>,
    ) -> Result<()> {
        self.check_inputs(gpu, &anchors, Some(&phi), Some(&rays))?;
        let n = self.rays();
        // The backward reads the entries and the rays by tile, which the tiled forward lists
        // and sorts.
        rec.pass("  bin list", |rec| self.record_list(rec))?;
        rec.pass("  ray sort", |rec| {
            self.record_ray_sort(rec, rays.sub(0, 16 * n))
        })?;
        // More anchors than one invocation may loop over are folded in passes.
        let per_pass = pass_size(
            self.anchors(),
            rec.context().info().shader_loop_limit(),
            |anchors| anchors + 2,
        );
        let passes = self.anchors().max(1).div_ceil(per_pass);
        let kernel = self.forward_variant(rec, &self.brute_kernel, passes > 1)?;
        let bindings = specs::ProbeForwardBruteBindings {
            rays: rays.sub(0, 16 * n),
            views: gpu.views().whole(),
            anchors: anchors.sub(0, 16 * self.anchors()),
            phi: phi.sub(0, 4 * self.anchors()),
            items: self.items.whole(),
            outs: self.outs.whole(),
            carry: self.carry.whole(),
        };
        self.dispatch_passes(
            rec,
            &kernel,
            &bindings.for_kernel(&kernel)?,
            (passes, per_pass),
        )?;
        self.record_loss(rec)
    }

    /// Records dL_sil/dφ at the anchors into `d_phi` (one `f32` per anchor, `weight ·` the
    /// gradient, overwritten or accumulated), after [`Prober::record_forward`] (or the brute
    /// forward) in this or an earlier submission, with the same inputs.
    pub fn record_backward(
        &self,
        rec: &mut Recorder<'_>,
        gpu: &GpuTargets,
        anchors: BufferRange<'_>,
        phi: BufferRange<'_>,
        rays: BufferRange<'_>,
        d_phi: GradOut<'_>,
    ) -> Result<()> {
        self.check_inputs(gpu, &anchors, Some(&phi), Some(&rays))?;
        check_floats("sphere probing: d_phi", &d_phi.range, self.anchors())?;
        let total = self.entry_count()?;
        let n = self.rays();
        let rays = rays.sub(0, 16 * n);
        let coef = (2.0 * f64::from(d_phi.weight) / n as f64) as f32;
        if self.max_by_rays(rec.context()) {
            return self.record_max_backward(rec, rays, d_phi, coef);
        }
        let tiles = self.job.tile_count();
        let ranges = self.ray_ranges.range(0, 8 * tiles);
        let anchors = anchors.sub(0, 16 * self.anchors());
        let phi = phi.sub(0, 4 * self.anchors());
        if total > 0 {
            rec.pass("  backward entries", |rec| {
                self.dispatch_backward(rec, gpu, total, anchors, phi, rays, ranges)
            })?;
        }
        rec.pass("  reduce", |rec| {
            rec.dispatch(
                &self.reduce_kernel,
                &specs::ProbeReduceBindings {
                    rects: self.rects.whole(),
                    masks: self.masks.whole(),
                    offsets: self.offsets.whole(),
                    word_prefix: self.word_prefix.whole(),
                    partials: self.partials.whole(),
                    d_phi: d_phi.range.sub(0, 4 * self.anchors()),
                }
                .for_kernel(&self.reduce_kernel)?,
                &ReducePush {
                    anchors: self.settings.anchors,
                    views: self.job.views,
                    entries: total as u32,
                    accumulate: u32::from(d_phi.accumulate),
                    coef,
                    words_per_tile: self.words_per_tile() as u32,
                    tiles_x: self.job.grid.tiles_x,
                    tiles_y: self.job.grid.tiles_y,
                },
                groups(self.anchors(), 64)?,
            )
        })
    }

    /// Whether the backward takes the path of G = max that needs no entries
    /// ([`Prober::record_max_backward`]): under max, when its gradient sum fits the driver's
    /// loop cap (an anchor's rays over all views, at most every ray).
    fn max_by_rays(&self, ctx: &Context) -> bool {
        self.settings.aggregate == super::Aggregate::Max
            && ctx
                .info()
                .shader_loop_limit()
                .is_none_or(|limit| self.rays() <= limit)
    }

    /// The backward under G = max: each ray's ψ − S goes to the one anchor its ψ came from. The
    /// rays are sorted by that anchor (`probe_aux_keys.comp`, the stable sort, the ranges pass);
    /// `probe_max_grad.comp` sums each anchor's in ray order.
    fn record_max_backward(
        &self,
        rec: &mut Recorder<'_>,
        rays: BufferRange<'_>,
        d_phi: GradOut<'_>,
        coef: f32,
    ) -> Result<()> {
        let n = self.rays();
        // One bucket per anchor; the rays without a hit join the last one's and are skipped
        // there.
        let buckets = self.anchors();
        let key_bits = (u64::BITS - (buckets.max(2) - 1).leading_zeros()).max(1);
        let ranges = self.item_ranges.range(0, 8 * buckets);
        rec.pass("  ray sort by anchor", |rec| {
            rec.dispatch(
                &self.aux_keys_kernel,
                &specs::ProbeAuxKeysBindings {
                    rays,
                    outs: self.outs.whole(),
                    keys: self.aux_keys.whole(),
                    values: self.aux_order.whole(),
                }
                .for_kernel(&self.aux_keys_kernel)?,
                &AuxKeysPush {
                    rays: n as u32,
                    anchors: self.settings.anchors,
                    views: self.job.views,
                    pad: 0,
                },
                groups(n, 64)?,
            )?;
            self.sort.record(
                rec,
                &self.sort_scratch,
                &self.aux_keys,
                &self.aux_order,
                n,
                key_bits,
            )?;
            rec.fill(ranges, 0);
            self.binner
                .record_ranges(rec, self.aux_keys.range(0, 8 * n), ranges, n, buckets)
        })?;
        rec.pass("  max gradient", |rec| {
            rec.dispatch(
                &self.max_grad_kernel,
                &specs::ProbeMaxGradBindings {
                    rays,
                    outs: self.outs.whole(),
                    order: self.aux_order.whole(),
                    anchor_ranges: ranges,
                    d_phi: d_phi.range.sub(0, 4 * self.anchors()),
                }
                .for_kernel(&self.max_grad_kernel)?,
                &MaxGradPush {
                    anchors: self.settings.anchors,
                    views: self.job.views,
                    accumulate: u32::from(d_phi.accumulate),
                    coef,
                },
                groups(self.anchors(), 64)?,
            )
        })
    }

    /// The rays' tile keys, their stable sort by tile, and each tile's range in the order.
    fn record_ray_sort(&self, rec: &mut Recorder<'_>, rays: BufferRange<'_>) -> Result<()> {
        let g = &self.job.grid;
        let n = self.rays();
        let tiles = self.job.tile_count();
        rec.dispatch(
            &self.keys_kernel,
            &specs::ProbeRayKeysBindings {
                rays,
                keys: self.ray_keys.whole(),
                values: self.ray_order.whole(),
            }
            .for_kernel(&self.keys_kernel)?,
            &KeysPush {
                rays: n as u32,
                width: g.width,
                height: g.height,
                tile_size: g.tile_size,
                tiles_x: g.tiles_x,
                tiles_y: g.tiles_y,
                pad: [0; 2],
            },
            groups(n, 64)?,
        )?;
        self.sort.record(
            rec,
            &self.sort_scratch,
            &self.ray_keys,
            &self.ray_order,
            n,
            self.job.key_bits(),
        )?;
        let ranges = self.ray_ranges.range(0, 8 * tiles);
        rec.fill(ranges, 0);
        self.binner
            .record_ranges(rec, self.ray_keys.range(0, 8 * n), ranges, n, tiles)
    }

    /// Step 2 of the backward: one invocation per binned (anchor, tile) entry.
    #[allow(clippy::too_many_arguments)]
    fn dispatch_backward(
        &self,
        rec: &mut Recorder<'_>,
        gpu: &GpuTargets,
        total: u64,
        anchors: BufferRange<'_>,
        phi: BufferRange<'_>,
        rays: BufferRange<'_>,
        ranges: BufferRange<'_>,
    ) -> Result<()> {
        let g = &self.job.grid;
        {
            let c = &self.constants;
            let kernel = self.variant(rec, &self.backward_kernel)?;
            rec.dispatch(
                &kernel,
                &specs::ProbeBackwardBindings {
                    list_tiles: self.list_tiles.whole(),
                    list: self.list.whole(),
                    items: self.items.whole(),
                    anchors,
                    phi,
                    rays,
                    views: gpu.views().whole(),
                    outs: self.outs.whole(),
                    ray_order: self.ray_order.whole(),
                    ray_ranges: ranges,
                    partials: self.partials.whole(),
                    offsets: self.offsets.whole(),
                }
                .for_kernel(&kernel)?,
                &BackwardPush {
                    entries: total as u32,
                    anchors: self.settings.anchors,
                    width: g.width,
                    height: g.height,
                    tiles_x: g.tiles_x,
                    tiles_y: g.tiles_y,
                    mode: self.settings.aggregate.code(),
                    boundary_aware: u32::from(self.settings.boundary_aware),
                    inv_s: c.inv_s,
                    tau2: c.tau2,
                    inv_t: c.inv_t,
                    total_index: self.job.tile_count() as u32,
                    tau2_outside: c.tau2_outside,
                    pad: [0; 3],
                },
                groups(total, 64)?,
            )
        }
    }

    /// Convenience (tests, tools): the whole forward (tiled, or brute force with `brute`) and
    /// backward of `anchors`, `phi` and `rays`, in two submissions, read back.
    pub fn run(
        &mut self,
        ctx: &Context,
        gpu: &GpuTargets,
        anchors: &Buffer,
        phi: &Buffer,
        rays: &Buffer,
        brute: bool,
    ) -> Result<ProbeRun> {
        ctx.submit_and_wait(|rec| self.record_count(rec, gpu, anchors.whole()))?;
        let entries = self.finish_count(ctx)?;
        let d_phi = ctx.create_buffer("probe d_phi", 4 * self.anchors(), MemoryKind::Device)?;
        ctx.submit_and_wait(|rec| {
            if brute {
                self.record_forward_brute(rec, gpu, anchors.whole(), phi.whole(), rays.whole())?;
            } else {
                self.record_forward(rec, gpu, anchors.whole(), phi.whole(), rays.whole())?;
            }
            self.record_backward(
                rec,
                gpu,
                anchors.whole(),
                phi.whole(),
                rays.whole(),
                GradOut::write(d_phi.whole()),
            )
        })?;
        Ok(ProbeRun {
            outs: self.read_outputs(ctx)?,
            loss: self.read_loss(ctx)?,
            d_phi: ctx.read_buffer(&d_phi, 0, self.anchors() as usize)?,
            entries,
        })
    }

    /// [`RayOut`] per ray of the last forward.
    pub fn outputs(&self) -> &Buffer {
        &self.outs
    }

    /// Reads [`Prober::outputs`] back.
    pub fn read_outputs(&self, ctx: &Context) -> Result<Vec<RayOut>> {
        ctx.read_buffer(&self.outs, 0, self.rays() as usize)
    }

    /// One `f32`: L_sil of the last forward.
    pub fn loss_buffer(&self) -> &Buffer {
        &self.loss
    }

    /// Reads L_sil back.
    pub fn read_loss(&self, ctx: &Context) -> Result<f32> {
        Ok(ctx.read_buffer::<f32>(&self.loss, 0, 1)?[0])
    }

    /// The anchor items ([`ProbeItem`], view-major) of the last [`Prober::record_items`].
    pub fn items(&self) -> &Buffer {
        &self.items
    }

    /// The binning job (grid, layout, counts).
    pub fn job(&self) -> &BinJob {
        &self.job
    }

    /// The settings the prober was made with.
    pub fn settings(&self) -> &ProbeSettings {
        &self.settings
    }
}

/// CPU twins: the discrete decisions in the kernels' f32 operations, the values in f64.
pub mod cpu {
    use super::{Constants, FLAG_INSIDE, FLAG_VALID, ProbeItem};
    use crate::primitives::binning::TileGrid;
    use crate::probe::sampler::Ray;
    use crate::probe::targets::{ProbeView, Targets};
    use crate::probe::{Aggregate, ProbeSettings};

    type V3 = [f32; 3];

    fn affine(a: &[f32; 4], p: V3) -> f32 {
        a[0] * p[0] + a[1] * p[1] + a[2] * p[2] + a[3]
    }

    /// `sphere_extent` of `probe_items.comp`, rounding for rounding: the extent `[lo, hi]` of the
    /// screen coordinate `affine(a, p) / affine(a2, p)` over the sphere of radius `tau` around
    /// `c`; `None` where the sphere reaches the plane `affine(a2, p) = 0` (or rounding leaves no
    /// real roots).
    pub fn sphere_extent(a: &[f32; 4], a2: &[f32; 4], c: V3, tau: f32) -> Option<(f32, f32)> {
        let big_a = affine(a, c);
        let big_b = affine(a2, c);
        let (u, w) = ([a[0], a[1], a[2]], [a2[0], a2[1], a2[2]]);
        let tau2 = tau * tau;
        let qa = big_b * big_b - tau2 * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
        let qb = big_a * big_b - tau2 * (u[0] * w[0] + u[1] * w[1] + u[2] * w[2]);
        let v = [0, 1, 2].map(|i| big_a * w[i] - big_b * u[i]);
        let x = [
            u[1] * w[2] - u[2] * w[1],
            u[2] * w[0] - u[0] * w[2],
            u[0] * w[1] - u[1] * w[0],
        ];
        let disc = tau2
            * ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
                - tau2 * (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]));
        if !(qa > 0.0 && disc >= 0.0) {
            return None;
        }
        let r = disc.sqrt();
        Some(((qb - r) / qa, (qb + r) / qa))
    }

    /// `probe_items.comp`.
    pub fn items(targets: &Targets, tau: f64, anchors: &[[f32; 4]]) -> Vec<ProbeItem> {
        let tau = tau as f32;
        let (w, h) = (targets.width as f32, targets.height as f32);
        let smin = w.min(h);
        let mut out = Vec::with_capacity(anchors.len() * targets.views.len());
        for (k, v) in targets.views.iter().enumerate() {
            for a in anchors {
                let p = [a[0], a[1], a[2]];
                let mut valid = true;
                let mut b = [1e30f32, 1e30, -1e30, -1e30];
                for c in 0..8u32 {
                    let sign = |bit: u32| if c & bit != 0 { 1.0f32 } else { -1.0 };
                    let corner = [
                        p[0] + tau * sign(1),
                        p[1] + tau * sign(2),
                        p[2] + tau * sign(4),
                    ];
                    let den = affine(&v.a2, corner);
                    valid = valid && affine(&v.depth, corner) > 0.0 && den > 0.0;
                    let (sx, sy) = (affine(&v.a0, corner) / den, affine(&v.a1, corner) / den);
                    b = [b[0].min(sx), b[1].min(sy), b[2].max(sx), b[3].max(sy)];
                }
                if let (Some(ex), Some(ey)) = (
                    sphere_extent(&v.a0, &v.a2, p, tau),
                    sphere_extent(&v.a1, &v.a2, p, tau),
                ) {
                    b = [
                        b[0].max(ex.0),
                        b[1].max(ey.0),
                        b[2].min(ex.1),
                        b[3].min(ey.1),
                    ];
                }
                let den = affine(&v.a2, p);
                let sx = affine(&v.a0, p) / den;
                let sy = affine(&v.a1, p) / den;
                let fc = ((sx * smin + w) * 0.5).floor();
                let fr = ((h - sy * smin) * 0.5).floor();
                let inside = den > 0.0
                    && fc >= 0.0
                    && fc < w
                    && fr >= 0.0
                    && fr < h
                    && targets.inside(k, fc as i64, fr as i64);
                out.push(ProbeItem {
                    screen_box: b,
                    flags: (u32::from(valid) * FLAG_VALID) | (u32::from(inside) * FLAG_INSIDE),
                    sx,
                    sy,
                    depth: affine(&v.depth, p),
                });
            }
        }
        out
    }

    /// The line of a ray: `pixel_to_screen` and `view_ray` of `probe.glsl`.
    pub fn ray_line(view: &ProbeView, ray: &Ray, width: u32, height: u32, inv_s: f32) -> (V3, V3) {
        let sx = (2.0 * ray.px - width as f32) * inv_s;
        let sy = (height as f32 - 2.0 * ray.py) * inv_s;
        let f = |a: &[f32; 4], b: &[f32; 4], c: &[f32; 4]| {
            [0, 1, 2].map(|i| a[i] + sx * b[i] + sy * c[i])
        };
        (
            f(&view.o0, &view.ox, &view.oy),
            f(&view.d0, &view.dx, &view.dy),
        )
    }

    /// `hit_bound` of `probe.glsl`: τ² |d|².
    pub fn hit_bound(d: V3, tau2: f32) -> f32 {
        tau2 * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    }

    /// `ray_hits` of `probe.glsl`: |(p − o) × d|² < τ² |d|².
    pub fn ray_hits(o: V3, d: V3, bound: f32, p: V3) -> bool {
        let v = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        let cx = v[1] * d[2] - v[2] * d[1];
        let cy = v[2] * d[0] - v[0] * d[2];
        let cz = v[0] * d[1] - v[1] * d[0];
        cx * cx + cy * cy + cz * cz < bound
    }

    /// `ray_tile` of `probe.glsl`.
    pub fn ray_tile(ray: &Ray, grid: &TileGrid) -> u32 {
        let col = (ray.px as u32).min(grid.width - 1);
        let row = (ray.py as u32).min(grid.height - 1);
        ray.view * grid.tiles_x * grid.tiles_y
            + (row / grid.tile_size) * grid.tiles_x
            + col / grid.tile_size
    }

    /// The anchors each ray uses, in anchor order: valid in its view, assigned to it (when
    /// boundary-aware) and within τ of its line.
    pub fn hits(
        targets: &Targets,
        settings: &ProbeSettings,
        anchors: &[[f32; 4]],
        rays: &[Ray],
    ) -> Vec<Vec<u32>> {
        let c = Constants::new(settings, targets.width, targets.height);
        let items = items(targets, f64::from(c.tau), anchors);
        let n = anchors.len();
        rays.iter()
            .map(|r| {
                let view = &targets.views[r.view as usize];
                let (o, d) = ray_line(view, r, targets.width, targets.height, c.inv_s);
                let bound = hit_bound(d, c.ray_tau2(r.label));
                (0..n)
                    .filter(|&j| {
                        let flags = items[r.view as usize * n + j].flags;
                        let assigned = !settings.boundary_aware
                            || (r.label >= 0.5) == (flags & FLAG_INSIDE != 0);
                        flags & FLAG_VALID != 0
                            && assigned
                            && ray_hits(o, d, bound, [anchors[j][0], anchors[j][1], anchors[j][2]])
                    })
                    .map(|j| j as u32)
                    .collect()
            })
            .collect()
    }

    /// ψ of a ray with `hits` and dψ/dφ of each hit (zero without hits).
    pub fn aggregate(settings: &ProbeSettings, hits: &[u32], phi: &[f64]) -> (f64, Vec<f64>) {
        if hits.is_empty() {
            return (0.0, Vec::new());
        }
        let values: Vec<f64> = hits.iter().map(|&j| phi[j as usize]).collect();
        match settings.aggregate {
            Aggregate::Max => {
                let mut best = 0;
                for (i, &v) in values.iter().enumerate() {
                    if v > values[best] {
                        best = i;
                    }
                }
                let mut g = vec![0.0; values.len()];
                g[best] = 1.0;
                (values[best], g)
            }
            Aggregate::LogSumExp => {
                let t = settings.temperature;
                let m = values.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(v));
                let s: f64 = values.iter().map(|&v| ((v - m) / t).exp()).sum();
                let psi = m + t * s.ln();
                (psi, values.iter().map(|&v| ((v - psi) / t).exp()).collect())
            }
            Aggregate::Union => {
                let prod: f64 = values.iter().map(|&v| 1.0 - v).product();
                let g = (0..values.len())
                    .map(|i| {
                        values
                            .iter()
                            .enumerate()
                            .filter(|&(k, _)| k != i)
                            .map(|(_, &v)| 1.0 - v)
                            .product()
                    })
                    .collect();
                (1.0 - prod, g)
            }
        }
    }

    /// The forward's result.
    #[derive(Clone, Debug, PartialEq)]
    pub struct Forward {
        /// The anchors each ray used, in order.
        pub hits: Vec<Vec<u32>>,
        /// ψ per ray.
        pub psi: Vec<f64>,
        /// L_sil.
        pub loss: f64,
    }

    /// L_sil of fixed hits: `mean (ψ − S)²`.
    pub fn loss(settings: &ProbeSettings, hits: &[Vec<u32>], phi: &[f64], rays: &[Ray]) -> f64 {
        let sum: f64 = hits
            .iter()
            .zip(rays)
            .map(|(h, r)| {
                let e = aggregate(settings, h, phi).0 - f64::from(r.label);
                e * e
            })
            .sum();
        sum / rays.len() as f64
    }

    /// The forward: hits, ψ, L_sil.
    pub fn forward(
        targets: &Targets,
        settings: &ProbeSettings,
        anchors: &[[f32; 4]],
        phi: &[f64],
        rays: &[Ray],
    ) -> Forward {
        let hits = hits(targets, settings, anchors, rays);
        let psi = hits.iter().map(|h| aggregate(settings, h, phi).0).collect();
        let loss = loss(settings, &hits, phi, rays);
        Forward { hits, psi, loss }
    }

    /// dL_sil/dφ per anchor: `(2 / N) Σ_i (ψ_i − S_i) dψ_i/dφ_j`.
    pub fn backward(
        settings: &ProbeSettings,
        forward: &Forward,
        phi: &[f64],
        rays: &[Ray],
    ) -> Vec<f64> {
        let mut d = vec![0.0; phi.len()];
        let n = rays.len() as f64;
        for ((h, &psi), r) in forward.hits.iter().zip(&forward.psi).zip(rays) {
            let (_, g) = aggregate(settings, h, phi);
            let e = 2.0 * (psi - f64::from(r.label)) / n;
            for (&j, gj) in h.iter().zip(g) {
                d[j as usize] += e * gj;
            }
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::probe::Aggregate;

    #[test]
    fn push_and_struct_layouts_match_the_kernels() {
        let size = |s: &crate::gpu::KernelSpec| s.push_constant_size as usize;
        assert_eq!(std::mem::size_of::<ItemsPush>(), size(&specs::PROBE_ITEMS));
        assert_eq!(
            std::mem::size_of::<ForwardPush>(),
            size(&specs::PROBE_FORWARD)
        );
        assert_eq!(
            std::mem::size_of::<ForwardPush>(),
            size(&specs::PROBE_FORWARD_BRUTE)
        );
        assert_eq!(
            std::mem::size_of::<KeysPush>(),
            size(&specs::PROBE_RAY_KEYS)
        );
        assert_eq!(
            std::mem::size_of::<BackwardPush>(),
            size(&specs::PROBE_BACKWARD)
        );
        assert_eq!(
            std::mem::size_of::<ReducePush>(),
            size(&specs::PROBE_REDUCE)
        );
        assert_eq!(
            std::mem::size_of::<WordsPush>(),
            size(&specs::BIN_MASK_COUNTS)
        );
        assert_eq!(
            std::mem::size_of::<ListPush>(),
            size(&specs::PROBE_MASK_LIST)
        );
        assert_eq!(
            std::mem::size_of::<AuxKeysPush>(),
            size(&specs::PROBE_AUX_KEYS)
        );
        assert_eq!(
            std::mem::size_of::<MaxGradPush>(),
            size(&specs::PROBE_MAX_GRAD)
        );
        assert_eq!(std::mem::size_of::<ProbeItem>(), 32);
        assert_eq!(std::mem::offset_of!(ProbeItem, flags), 16);
        assert_eq!(std::mem::size_of::<RayOut>(), 16);
        assert_eq!(std::mem::size_of::<super::super::ProbeView>(), 160);
        assert_eq!(specs::PROBE_FORWARD.bindings.len(), 10);
        assert_eq!(specs::PROBE_FORWARD_BRUTE.bindings.len(), 7);
        assert_eq!(specs::PROBE_BACKWARD.bindings.len(), 12);
    }

    #[test]
    fn aggregates_match_their_definitions() {
        let phi = [0.2, 0.9, 0.5, 0.7];
        let hits = [0, 2, 3];
        let s = |aggregate| ProbeSettings {
            aggregate,
            temperature: 0.1,
            ..ProbeSettings::default()
        };
        let (psi, g) = cpu::aggregate(&s(Aggregate::Max), &hits, &phi);
        assert_eq!((psi, g), (0.7, vec![0.0, 0.0, 1.0]));
        let (psi, g) = cpu::aggregate(&s(Aggregate::LogSumExp), &hits, &phi);
        let want = 0.1 * (2f64.exp() + 5f64.exp() + 7f64.exp()).ln();
        assert!((psi - want).abs() < 1e-12);
        assert!((g.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let (psi, g) = cpu::aggregate(&s(Aggregate::Union), &hits, &phi);
        assert!((psi - (1.0 - 0.8 * 0.5 * 0.3)).abs() < 1e-12);
        assert!((g[1] - 0.8 * 0.3).abs() < 1e-12);
        assert_eq!(cpu::aggregate(&s(Aggregate::Union), &[], &phi).0, 0.0);
    }
}
