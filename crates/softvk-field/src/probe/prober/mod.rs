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
//!
//! The parts: the binning and its entry lists (`lists.rs`), the forward (`forward.rs`), the
//! backward (`backward.rs`) and the CPU twins ([`cpu`]); the prober, its buffers and the
//! readbacks are here.

mod backward;
pub mod cpu;
mod forward;
mod lists;

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use self::backward::backward_iterations;
use self::lists::list_iterations;
use super::ProbeSettings;
use super::targets::GpuTargets;
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{
    Buffer, BufferRange, Context, GradOut, Kernel, KernelVariants, MemoryKind, check_binding,
    check_floats, check_texels,
};
use crate::primitives::binning::{BinJob, Binner, ItemLayout, TileGrid};
use crate::primitives::scan::{Scan, ScanScratch};
use crate::primitives::sum::Sum;
use crate::primitives::{RadixSort, SortScratch};
use crate::specs;

#[cfg(doc)]
use crate::gpu::gate::IterationGate;

/// [`ProbeItem::flags`]: every corner of the anchor's τ-cube is in front of the camera.
pub const FLAG_VALID: u32 = 1;
/// [`ProbeItem::flags`]: the anchor's centre projects into the silhouette.
pub const FLAG_INSIDE: u32 = 2;
/// [`RayOut::aux`] of a ray without hits.
pub const NO_HIT: u32 = u32::MAX;

/// One anchor in one view, as the binning reads it. Twin of `ProbeItem` in
/// `kernels/softvk/include/probe.glsl`; 32 bytes.
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

/// What the forward leaves per ray. Twin of `RayOut` in `kernels/softvk/include/probe.glsl`; 16 bytes.
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
    items_kernel: Arc<Kernel>,
    /// The forward, brute-force forward and backward kernels are specialized on
    /// [`Prober::modes`] (the aggregation and the assignment).
    forward_kernel: KernelVariants,
    brute_kernel: KernelVariants,
    keys_kernel: Arc<Kernel>,
    backward_kernel: KernelVariants,
    reduce_kernel: Arc<Kernel>,
    mask_counts_kernel: Arc<Kernel>,
    /// Specialized by whether it writes each entry's tile (constant 0: not under G = max).
    mask_list_kernel: KernelVariants,
    aux_keys_kernel: Arc<Kernel>,
    max_grad_kernel: Arc<Kernel>,
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
            items_kernel: ctx.kernel(&specs::PROBE_ITEMS, &[])?,
            forward_kernel: KernelVariants::new(&specs::PROBE_FORWARD),
            brute_kernel: KernelVariants::new(&specs::PROBE_FORWARD_BRUTE),
            keys_kernel: ctx.kernel(&specs::PROBE_RAY_KEYS, &[])?,
            backward_kernel: KernelVariants::new(&specs::PROBE_BACKWARD),
            reduce_kernel: ctx.kernel(&specs::PROBE_REDUCE, &[])?,
            mask_counts_kernel: ctx.kernel(&crate::gpu::specs::BIN_MASK_COUNTS, &[])?,
            mask_list_kernel: KernelVariants::new(&specs::PROBE_MASK_LIST),
            aux_keys_kernel: ctx.kernel(&specs::PROBE_AUX_KEYS, &[])?,
            max_grad_kernel: ctx.kernel(&specs::PROBE_MAX_GRAD, &[])?,
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

    /// `W`: the words of a tile's anchor mask.
    fn words_per_tile(&self) -> u64 {
        words_per_tile(self.settings.anchors)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn struct_layouts_match_the_kernels() {
        assert_eq!(std::mem::size_of::<ProbeItem>(), 32);
        assert_eq!(std::mem::offset_of!(ProbeItem, flags), 16);
        assert_eq!(std::mem::size_of::<RayOut>(), 16);
        assert_eq!(std::mem::size_of::<super::super::ProbeView>(), 160);
    }
}
