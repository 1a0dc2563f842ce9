//! PyTorch3D's mesh rasterizer on the GPU: [`FragmentRasterizer`].
//!
//! A rasterization is four steps, over buffers the caller owns (face vertices, meshes,
//! neighbours in; the fragments out) and scratch the rasterizer owns (the binning items and
//! bins, the backward's partials):
//!
//! 1. **Setup** (`kernels/fragments/frag_setup.comp`): per (mesh, face slot) a binning item,
//!    the face's box grown by √`blur_radius`, or none where PyTorch3D skips the face.
//! 2. **Binning** ([`crate::primitives::binning`], 8-pixel tiles): exact, so nothing overflows
//!    and `bin_size` and `max_faces_per_bin` have nothing to say; its count is read back
//!    between two submissions ([`FragmentRasterizer::record_setup`] and
//!    [`FragmentRasterizer::bin`]).
//! 3. **Forward** (`frag_forward.comp`): per pixel, the faces binned to its tile in index
//!    order into its K-list of `(face, z)` (sorted by `(z, face)`), in passes over crowded
//!    tiles where the driver caps loops; then `frag_finish.comp` writes PyTorch3D's outputs from
//!    the lists ([`FragmentRasterizer::record_forward`]).
//! 4. **Backward** (`frag_backward.comp`, `frag_reduce.comp`): per binned (face, tile) entry a
//!    partial gradient over the tile's pixels, then per face the sum of its partials in slot
//!    order ([`FragmentRasterizer::record_backward`]); it needs only the binning's count pass.
//!
//! [`FragmentRasterizer::rasterize_to`] (into a host-visible buffer: what the Python package
//! calls, its arrays then view that memory), [`FragmentRasterizer::rasterize_into`],
//! [`FragmentRasterizer::rasterize`] and [`FragmentRasterizer::rasterize_grad_into`] do all of it
//! from host slices, through host-visible buffers.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::FragmentSettings;
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{
    Buffer, BufferRange, Context, Kernel, MemoryKind, PassTime, Recorder, Timer, groups, specs,
};
use crate::primitives::binning::{BinJob, Binner, Bins, ItemLayout, TileGrid};

/// Words of one binning item (`ITEM_WORDS` in `kernels/include/fragments.glsl`): the box, the
/// flag word, padding.
const ITEM_WORDS: u32 = 8;

/// Push constants of every fragment kernel (`Push` in `kernels/include/fragments.glsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct FragmentPush {
    width: u32,
    height: u32,
    k: u32,
    flags: u32,
    blur_radius: f32,
    grow: f32,
    views: u32,
    items_per_view: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    pass_begin: u32,
    pass_end: u32,
    entries: u32,
    face_count: u32,
    pad: u32,
}

const FLAG_PERSPECTIVE: u32 = 1;
const FLAG_CLIP: u32 = 2;
const FLAG_CULL: u32 = 4;

/// What one rasterization is over, planned on the host: the batch's shape, the settings and the
/// binning job. Made by [`FragmentPlan::new`], which checks everything the kernels rely on.
#[derive(Clone, Debug)]
pub struct FragmentPlan {
    settings: FragmentSettings,
    /// Faces in the face-vertex buffer.
    face_count: u32,
    /// `(first, count)` per mesh.
    meshes: Vec<[u32; 2]>,
    job: BinJob,
    push: FragmentPush,
    /// Faces of a tile's run one forward pass visits at most.
    pass_faces: u64,
}

impl FragmentPlan {
    /// Plans a rasterization of `face_count` packed faces, of which mesh `n` owns
    /// `meshes[n] = (first, count)` (ranges in increasing order, not overlapping, as PyTorch3D
    /// packs them).
    pub fn new(
        ctx: &Context,
        face_count: usize,
        meshes: &[(usize, usize)],
        settings: &FragmentSettings,
    ) -> Result<Self> {
        let s = settings;
        let bad = |m: String| Err(Error::Input(format!("fragment rasterizer: {m}")));
        if s.width == 0 || s.height == 0 {
            return bad(format!("image size {}×{} is empty", s.height, s.width));
        }
        if s.faces_per_pixel == 0 {
            return bad("faces_per_pixel must be at least 1".into());
        }
        if !(s.blur_radius >= 0.0 && s.blur_radius.is_finite()) {
            return bad(format!(
                "blur_radius {} is not a finite number >= 0",
                s.blur_radius
            ));
        }
        if meshes.is_empty() {
            return bad("no meshes".into());
        }
        let face_count = u32::try_from(face_count)
            .ok()
            .filter(|&f| f < i32::MAX as u32)
            .ok_or_else(|| Error::Input(format!("{face_count} faces is too many")))?;
        super::check_meshes(face_count as usize, meshes)?;
        let items_per_view = meshes.iter().map(|m| m.1).max().unwrap_or(0).max(1) as u32;
        let views =
            u32::try_from(meshes.len()).map_err(|_| Error::Input("too many meshes".into()))?;
        let k = u32::try_from(s.faces_per_pixel)
            .map_err(|_| Error::Input("faces_per_pixel is too large".into()))?;
        let slots = u64::from(views) * u64::from(s.width) * u64::from(s.height) * u64::from(k);
        let limit = u64::from(ctx.info().limits.max_storage_buffer_range);
        if 12 * slots > limit || slots > u64::from(u32::MAX) / 3 {
            return Err(Error::DeviceLimit {
                kind: LimitKind::StorageBinding,
                what: format!(
                    "fragment rasterizer: the barycentrics of {views} × {}×{} pixels × K {k}",
                    s.height, s.width
                ),
                need: 12 * slots,
                max: limit,
                device: ctx.info().name.clone(),
                hint: "rasterize fewer meshes at once, a smaller image or a smaller K",
            });
        }
        let grid = TileGrid::new(s.width, s.height, 8)?;
        let loop_cap = ctx.info().shader_loop_limit();
        let k64 = u64::from(k);
        // The backward's loops (frag_backward.comp): its search, then per pixel of the tile one
        // and at most K + 1 list reads; the reduce's: one per tile of a face.
        let backward = 128 + 64 * (k64 + 1);
        let reduce = grid.tiles_per_view() + 8;
        // The forward's: K to find a list's end, then per face of a pass at most 2K + 1, and per
        // batch of a subgroup's faces one and one per ballot word (at most 2: a face's share of
        // them at most 3).
        let pass_faces = match loop_cap {
            Some(cap) => {
                for (what, need) in [
                    ("the backward's per-tile sum", backward),
                    ("the backward's per-face sum over its tiles", reduce),
                    ("a forward pass of one face", 16 + 3 * k64 + 4),
                ] {
                    if need > cap {
                        return Err(Error::DeviceLimit {
                            kind: LimitKind::LoopIterations,
                            what: format!("fragment rasterizer: {what}"),
                            need,
                            max: cap,
                            device: ctx.info().name.clone(),
                            hint: "use a smaller faces_per_pixel or image",
                        });
                    }
                }
                (cap - 16 - k64) / (2 * k64 + 4)
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
            views,
            first_item: 0,
        };
        let blur = s.blur_radius as f32;
        let flags = [
            (s.perspective_correct, FLAG_PERSPECTIVE),
            (s.clip_barycentric_coords, FLAG_CLIP),
            (s.cull_backfaces, FLAG_CULL),
        ]
        .iter()
        .filter(|(on, _)| *on)
        .fold(0, |f, (_, bit)| f | bit);
        let push = FragmentPush {
            width: s.width,
            height: s.height,
            k,
            flags,
            blur_radius: blur,
            // PyTorch3D's std::sqrt of the f32 radius, correctly rounded here once.
            grow: blur.sqrt(),
            views,
            items_per_view,
            tile_size: grid.tile_size,
            tiles_x: grid.tiles_x,
            tiles_y: grid.tiles_y,
            pass_begin: 0,
            pass_end: 0,
            entries: 0,
            face_count,
            pad: 0,
        };
        Ok(Self {
            settings: *s,
            face_count,
            meshes: meshes.iter().map(|&(f, c)| [f as u32, c as u32]).collect(),
            job,
            push,
            pass_faces: pass_faces.max(1),
        })
    }

    /// Fragment slots of the output: meshes × H × W × K.
    pub fn slots(&self) -> u64 {
        u64::from(self.push.views)
            * u64::from(self.push.width)
            * u64::from(self.push.height)
            * u64::from(self.push.k)
    }

    /// Faces in the face-vertex buffer.
    pub fn face_count(&self) -> u32 {
        self.face_count
    }

    /// The settings planned for.
    pub fn settings(&self) -> &FragmentSettings {
        &self.settings
    }

    /// `(first, count)` per mesh, as the kernels read them (one `[u32; 2]` each): what the
    /// caller's meshes buffer must hold.
    pub fn mesh_table(&self) -> &[[u32; 2]] {
        &self.meshes
    }

    /// The binning items' bytes.
    fn items_bytes(&self) -> u64 {
        self.job.item_count() * u64::from(ITEM_WORDS) * 4
    }
}

/// The forward's outputs, in the caller's buffers, `[meshes, H, W, K]` (slot-major): PyTorch3D's
/// `pix_to_face` as i64, `zbuf`, `dists` and `bary_coords` (three f32 a slot).
pub struct FragmentOutputs<'a> {
    /// i64 per slot: the packed face, or −1.
    pub pix_to_face: BufferRange<'a>,
    /// f32 per slot.
    pub zbuf: BufferRange<'a>,
    /// f32 per slot.
    pub dists: BufferRange<'a>,
    /// Three f32 per slot.
    pub bary_coords: BufferRange<'a>,
}

/// The inputs every step reads, in the caller's buffers.
#[derive(Clone, Copy)]
pub struct FragmentInputs<'a> {
    /// Nine f32 per face: its three vertices' `(x, y, z)` in PyTorch3D's NDC.
    pub face_verts: BufferRange<'a>,
    /// [`FragmentPlan::mesh_table`].
    pub meshes: BufferRange<'a>,
}

/// The backward's upstream gradients and the forward's `pix_to_face`, in the caller's buffers.
pub struct FragmentGrads<'a> {
    /// i64 per slot, as the forward wrote it.
    pub pix_to_face: BufferRange<'a>,
    /// f32 per slot.
    pub grad_zbuf: BufferRange<'a>,
    /// Three f32 per slot.
    pub grad_bary: BufferRange<'a>,
    /// f32 per slot.
    pub grad_dists: BufferRange<'a>,
}

/// Host-visible buffers the slice entry points reuse (grown, never shrunk).
#[derive(Default)]
struct HostBuffers {
    inputs: Option<Buffer>,
    outputs: Option<Buffer>,
}

fn host_buffer(
    ctx: &Context,
    slot: &mut Option<Buffer>,
    name: &str,
    bytes: u64,
    kind: MemoryKind,
) -> Result<()> {
    if slot.as_ref().is_none_or(|b| b.size() < bytes) {
        *slot = None; // free the old one first
        *slot = Some(ctx.create_buffer(name, bytes.max(16), kind)?);
    }
    Ok(())
}

/// PyTorch3D's rasterizer on the GPU: its pipelines, its binning and its scratch.
pub struct FragmentRasterizer {
    setup: Arc<Kernel>,
    forward: Arc<Kernel>,
    finish: Arc<Kernel>,
    backward: Arc<Kernel>,
    reduce: Arc<Kernel>,
    binner: Binner,
    bins: Bins,
    items: Option<Buffer>,
    partials: Option<Buffer>,
    /// Read back by [`FragmentRasterizer::bin`]: the entries of the last binning.
    entries: Option<u64>,
    host: HostBuffers,
    /// GPU timestamps of the slice entry points' passes ([`FragmentRasterizer::time_passes`]).
    timer: Option<Timer>,
    timings: Vec<PassTime>,
}

impl FragmentRasterizer {
    /// Builds the pipelines (from the context's cache) and empty scratch.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            setup: ctx.kernel(&specs::FRAG_SETUP, &[])?,
            forward: ctx.kernel(&specs::FRAG_FORWARD, &[])?,
            finish: ctx.kernel(&specs::FRAG_FINISH, &[])?,
            backward: ctx.kernel(&specs::FRAG_BACKWARD, &[])?,
            reduce: ctx.kernel(&specs::FRAG_REDUCE, &[])?,
            binner: Binner::new(ctx)?,
            bins: Bins::new(ctx)?,
            items: None,
            partials: None,
            entries: None,
            host: HostBuffers::default(),
            timer: None,
            timings: Vec::new(),
        })
    }

    /// Times every pass of the slice entry points ([`FragmentRasterizer::rasterize_into`],
    /// [`FragmentRasterizer::rasterize_grad_into`]) with GPU timestamps, from now on: what
    /// benchmarks read with [`FragmentRasterizer::take_timings`].
    pub fn time_passes(&mut self, ctx: &Context) -> Result<()> {
        self.timer = Some(Timer::new(ctx, 16)?);
        Ok(())
    }

    /// The pass times recorded since the last call, in order.
    pub fn take_timings(&mut self) -> Vec<PassTime> {
        std::mem::take(&mut self.timings)
    }

    /// Submits what `f` records and waits, timed when [`FragmentRasterizer::time_passes`] asked.
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

    /// Step 1 and the binning's count: records the setup of `plan`'s items and the count pass
    /// into `rec`. Submit it, then call [`FragmentRasterizer::bin`].
    pub fn record_setup(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &FragmentPlan,
        inputs: FragmentInputs<'_>,
    ) -> Result<()> {
        let ctx = rec.context();
        let bytes = plan.items_bytes();
        if self.items.as_ref().is_none_or(|b| b.size() < bytes) {
            self.items = None;
            self.items =
                Some(ctx.create_buffer("fragment binning items", bytes, MemoryKind::Device)?);
        }
        self.bins.reserve(ctx, &plan.job)?;
        self.entries = None;
        inputs
            .face_verts
            .require(36 * u64::from(plan.face_count), "fragment face vertices")?;
        inputs
            .meshes
            .require(8 * plan.meshes.len() as u64, "fragment mesh table")?;
        let items = self.items.as_ref().expect("reserved above").range(0, bytes);
        let n = plan.job.item_count();
        rec.pass("fragment setup", |rec| {
            rec.dispatch(
                &self.setup,
                &specs::FragSetupBindings {
                    face_verts: inputs.face_verts,
                    meshes: inputs.meshes,
                    items,
                }
                .for_kernel(&self.setup)?,
                &plan.push,
                groups(n, 64)?,
            )
        })?;
        rec.pass("fragment binning count", |rec| {
            self.binner.record_count(rec, &self.bins, items, &plan.job)
        })
    }

    /// Reads the binning's entry count back (after [`FragmentRasterizer::record_setup`]'s
    /// submission completed) and sizes the entry buffers for it.
    pub fn bin(&mut self, ctx: &Context) -> Result<u64> {
        let total = self.bins.read_total(ctx)?;
        self.bins.reserve_entries(ctx, total)?;
        self.entries = Some(total);
        Ok(total)
    }

    fn entry_count(&self) -> Result<u64> {
        self.entries.ok_or_else(|| {
            Error::Misuse("fragment rasterizer: the binning's count is not read yet (bin)".into())
        })
    }

    /// The forward passes `plan` needs when no tile's run is longer than `longest`.
    pub fn forward_passes(plan: &FragmentPlan, longest: u64) -> u64 {
        longest.div_ceil(plan.pass_faces).max(1)
    }

    /// The longest tile run the forward can meet without reading the ranges: the largest
    /// mesh's face count, or the entries.
    pub fn longest_run_bound(&self, plan: &FragmentPlan) -> Result<u64> {
        Ok(u64::from(plan.job.items_per_view).min(self.entry_count()?))
    }

    /// Reads the binning's tile ranges back (after a submission of
    /// [`FragmentRasterizer::record_sort`]) and returns the longest run.
    pub fn longest_run(&self, ctx: &Context, plan: &FragmentPlan) -> Result<u64> {
        let ranges: Vec<[u32; 2]> =
            ctx.read_buffer(self.bins.ranges(), 0, plan.job.tile_count() as usize)?;
        Ok(ranges
            .iter()
            .map(|r| u64::from(r[1].saturating_sub(r[0])))
            .max()
            .unwrap_or(0))
    }

    /// Step 2's second half: records the binning's lists (after [`FragmentRasterizer::bin`]).
    pub fn record_sort(&self, rec: &mut Recorder<'_>, plan: &FragmentPlan) -> Result<()> {
        self.entry_count()?;
        let items = self.items_range(plan)?;
        rec.pass("fragment binning lists", |rec| {
            self.binner.record_sort(rec, &self.bins, items, &plan.job)
        })
    }

    fn items_range(&self, plan: &FragmentPlan) -> Result<BufferRange<'_>> {
        self.items
            .as_ref()
            .map(|b| b.range(0, plan.items_bytes()))
            .ok_or_else(|| Error::Misuse("fragment rasterizer: record_setup has not run".into()))
    }

    /// Step 3: records `passes` forward passes ([`FragmentRasterizer::forward_passes`]) into
    /// `out`, after [`FragmentRasterizer::record_sort`] in this or an earlier submission.
    /// `neighbors`: one i32 per face (the other half of a face cut by the near plane, or −1).
    pub fn record_forward(
        &self,
        rec: &mut Recorder<'_>,
        plan: &FragmentPlan,
        inputs: FragmentInputs<'_>,
        neighbors: BufferRange<'_>,
        out: &FragmentOutputs<'_>,
        passes: u64,
    ) -> Result<()> {
        let total = self.entry_count()?;
        let slots = plan.slots();
        neighbors.require(4 * u64::from(plan.face_count), "fragment neighbours")?;
        out.pix_to_face.require(8 * slots, "pix_to_face")?;
        out.zbuf.require(4 * slots, "zbuf")?;
        out.dists.require(4 * slots, "dists")?;
        out.bary_coords.require(12 * slots, "bary_coords")?;
        let tiles = plan.job.tile_count();
        let entries = total.max(1);
        let blocks = u64::from(plan.push.width.div_ceil(8))
            * u64::from(plan.push.height.div_ceil(8))
            * u64::from(plan.push.views);
        rec.pass("fragment forward", |rec| {
            // Every list empty: all ones in each slot's (face, z) words.
            rec.fill(out.pix_to_face.sub(0, 8 * slots), u32::MAX);
            for pass in 0..passes {
                let begin = pass * plan.pass_faces;
                let end = (begin + plan.pass_faces).min(u64::from(u32::MAX));
                let push = FragmentPush {
                    pass_begin: begin as u32,
                    pass_end: end as u32,
                    ..plan.push
                };
                rec.dispatch(
                    &self.forward,
                    &specs::FragForwardBindings {
                        face_verts: inputs.face_verts,
                        meshes: inputs.meshes,
                        neighbors,
                        pairs: self.bins.entries().range(0, 4 * entries),
                        pair_items: self.bins.entry_items().range(0, 4 * entries),
                        ranges: self.bins.ranges().range(0, 8 * tiles),
                        lists: out.pix_to_face.sub(0, 8 * slots),
                    }
                    .for_kernel(&self.forward)?,
                    &push,
                    u32::try_from(blocks)
                        .map_err(|_| Error::Input("fragment rasterizer: image too large".into()))?,
                )?;
            }
            Ok(())
        })?;
        rec.pass("fragment outputs", |rec| {
            let minus_one = (-1.0f32).to_bits();
            rec.fill(out.zbuf.sub(0, 4 * slots), minus_one);
            rec.fill(out.dists.sub(0, 4 * slots), minus_one);
            rec.fill(out.bary_coords.sub(0, 12 * slots), minus_one);
            rec.dispatch(
                &self.finish,
                &specs::FragFinishBindings {
                    face_verts: inputs.face_verts,
                    lists: out.pix_to_face.sub(0, 8 * slots),
                    zbuf: out.zbuf.sub(0, 4 * slots),
                    dists: out.dists.sub(0, 4 * slots),
                    bary: out.bary_coords.sub(0, 12 * slots),
                }
                .for_kernel(&self.finish)?,
                &plan.push,
                groups(slots / u64::from(plan.push.k), 64)?,
            )
        })
    }

    /// Step 4: records the backward into `grad_face_verts` (nine f32 per face; faces of no
    /// mesh are left as they are), after [`FragmentRasterizer::bin`] for the same faces (the
    /// lists are not needed).
    pub fn record_backward(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &FragmentPlan,
        inputs: FragmentInputs<'_>,
        grads: &FragmentGrads<'_>,
        grad_face_verts: BufferRange<'_>,
    ) -> Result<()> {
        let total = self.entry_count()?;
        let ctx = rec.context();
        let slots = plan.slots();
        grads.pix_to_face.require(8 * slots, "pix_to_face")?;
        grads.grad_zbuf.require(4 * slots, "grad_zbuf")?;
        grads.grad_bary.require(12 * slots, "grad_bary")?;
        grads.grad_dists.require(4 * slots, "grad_dists")?;
        grad_face_verts.require(36 * u64::from(plan.face_count), "grad_face_verts")?;
        let partial_bytes = 36 * total.max(1);
        if partial_bytes > u64::from(ctx.info().limits.max_storage_buffer_range) {
            return Err(Error::DeviceLimit {
                kind: LimitKind::BinEntries,
                what: "fragment rasterizer: the backward's (face, tile) partials".into(),
                need: partial_bytes,
                max: u64::from(ctx.info().limits.max_storage_buffer_range),
                device: ctx.info().name.clone(),
                hint: "rasterize fewer meshes at once or a smaller blur_radius",
            });
        }
        if self
            .partials
            .as_ref()
            .is_none_or(|b| b.size() < partial_bytes)
        {
            self.partials = None;
            self.partials = Some(ctx.create_buffer(
                "fragment backward partials",
                partial_bytes + partial_bytes / 4,
                MemoryKind::Device,
            )?);
        }
        let items = self.items_range(plan)?;
        let partials = self
            .partials
            .as_ref()
            .expect("reserved above")
            .range(0, partial_bytes);
        let n = plan.job.item_count();
        let offsets = self.bins.offsets().range(0, 4 * (n + 1));
        let push = FragmentPush {
            entries: total as u32,
            ..plan.push
        };
        rec.pass("fragment backward", |rec| {
            if total > 0 {
                rec.dispatch(
                    &self.backward,
                    &specs::FragBackwardBindings {
                        face_verts: inputs.face_verts,
                        meshes: inputs.meshes,
                        items,
                        offsets,
                        pix_to_face: grads.pix_to_face.sub(0, 8 * slots),
                        grad_zbuf: grads.grad_zbuf.sub(0, 4 * slots),
                        grad_bary: grads.grad_bary.sub(0, 12 * slots),
                        grad_dists: grads.grad_dists.sub(0, 4 * slots),
                        partials,
                    }
                    .for_kernel(&self.backward)?,
                    &push,
                    groups(total, 64)?,
                )?;
            }
            rec.dispatch(
                &self.reduce,
                &specs::FragReduceBindings {
                    meshes: inputs.meshes,
                    offsets,
                    partials,
                    grad_face_verts,
                }
                .for_kernel(&self.reduce)?,
                &push,
                groups(n, 64)?,
            )
        })
    }

    /// Uploads the faces and mesh table (and neighbours) into the host-visible input buffer:
    /// face vertices at 0, the mesh table, the neighbours, then `extra` bytes for the caller.
    fn upload_inputs(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
        extra: u64,
    ) -> Result<InputLayout> {
        let faces = u64::from(plan.face_count);
        let layout = InputLayout::new(faces, plan.meshes.len() as u64, extra);
        host_buffer(
            ctx,
            &mut self.host.inputs,
            "fragment inputs",
            layout.total,
            MemoryKind::Upload,
        )?;
        let buffer = self.host.inputs.as_mut().expect("made above");
        let bytes = buffer
            .mapped_mut()
            .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
        let put = |bytes: &mut [u8], at: u64, data: &[u8]| {
            bytes[at as usize..at as usize + data.len()].copy_from_slice(data);
        };
        put(bytes, 0, bytemuck::cast_slice(face_verts));
        put(bytes, layout.meshes, bytemuck::cast_slice(&plan.meshes));
        let nb = &mut bytes[layout.neighbors as usize..(layout.neighbors + 4 * faces) as usize];
        match neighbors {
            Some(list) => {
                for (dst, &n) in nb.chunks_exact_mut(4).zip(list) {
                    let n = if (0..i64::from(plan.face_count)).contains(&n) {
                        n as i32
                    } else {
                        -1
                    };
                    dst.copy_from_slice(&n.to_ne_bytes());
                }
            }
            None => nb.fill(0xFF),
        }
        Ok(layout)
    }

    fn check_host_inputs(
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
    ) -> Result<()> {
        let faces = plan.face_count as usize;
        if face_verts.len() != 9 * faces {
            return Err(Error::Input(format!(
                "fragment rasterizer: {} face-vertex floats for {faces} faces (9 each)",
                face_verts.len()
            )));
        }
        if let Some(nb) = neighbors {
            if nb.len() != faces {
                return Err(Error::Input(format!(
                    "fragment rasterizer: {} neighbours for {faces} faces",
                    nb.len()
                )));
            }
        }
        super::check_finite(face_verts)
    }

    /// The forward on host slices: `face_verts` (nine f32 per face), written into `out`, a
    /// host-visible buffer of at least `SlotParts::new(plan.slots()).total` bytes, at that
    /// layout's offsets. Waits for the device.
    pub fn rasterize_to(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
        out: &Buffer,
    ) -> Result<()> {
        Self::check_host_inputs(plan, face_verts, neighbors)?;
        let slots = plan.slots();
        let parts = SlotParts::new(slots);
        out.whole().require(parts.total, "fragment outputs")?;
        let layout = self.upload_inputs(ctx, plan, face_verts, neighbors, 0)?;
        let inputs_buffer = self.host.inputs.take().expect("uploaded");
        let result = (|| {
            let inputs = layout.inputs(&inputs_buffer);
            self.submit(ctx, |s, rec| s.record_setup(rec, plan, inputs))?;
            self.bin(ctx)?;
            let bound = self.longest_run_bound(plan)?;
            // Crowded tiles: the lists first, then the real longest run decides.
            let sorted_first = Self::forward_passes(plan, bound) > 1;
            let mut passes = 1;
            if sorted_first {
                self.submit(ctx, |s, rec| s.record_sort(rec, plan))?;
                passes = Self::forward_passes(plan, self.longest_run(ctx, plan)?);
            }
            let [p, z, d, b] = parts.at;
            let outputs = FragmentOutputs {
                pix_to_face: out.range(p, 8 * slots),
                zbuf: out.range(z, 4 * slots),
                dists: out.range(d, 4 * slots),
                bary_coords: out.range(b, 12 * slots),
            };
            let neighbors =
                inputs_buffer.range(layout.neighbors, 4 * u64::from(plan.face_count).max(1));
            self.submit(ctx, |s, rec| {
                if !sorted_first {
                    s.record_sort(rec, plan)?;
                }
                s.record_forward(rec, plan, inputs, neighbors, &outputs, passes)
            })
        })();
        self.host.inputs = Some(inputs_buffer);
        result
    }

    /// The forward on host slices: `face_verts` (nine f32 per face), written into `out`'s
    /// slices (each `plan.slots()` long; three f32 a slot for the barycentrics).
    pub fn rasterize_into(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
        out: HostFragments<'_>,
    ) -> Result<()> {
        let slots = plan.slots();
        let n = slots as usize;
        if out.pix_to_face.len() != n
            || out.zbuf.len() != n
            || out.dists.len() != n
            || out.bary_coords.len() != 3 * n
        {
            return Err(Error::Input(
                "fragment rasterizer: output slices of the wrong length".into(),
            ));
        }
        let parts = SlotParts::new(slots);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "fragments",
            parts.total,
            MemoryKind::Readback,
        )?;
        let outputs_buffer = self.host.outputs.take().expect("made above");
        let result = self.rasterize_to(ctx, plan, face_verts, neighbors, &outputs_buffer);
        if result.is_ok() {
            let bytes = outputs_buffer
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let [p, z, d, b] = parts.at;
            let part = |at: u64, len: u64| &bytes[at as usize..(at + len) as usize];
            bytemuck::cast_slice_mut::<i64, u8>(out.pix_to_face)
                .copy_from_slice(part(p, 8 * slots));
            bytemuck::cast_slice_mut::<f32, u8>(out.zbuf).copy_from_slice(part(z, 4 * slots));
            bytemuck::cast_slice_mut::<f32, u8>(out.dists).copy_from_slice(part(d, 4 * slots));
            bytemuck::cast_slice_mut::<f32, u8>(out.bary_coords)
                .copy_from_slice(part(b, 12 * slots));
        }
        self.host.outputs = Some(outputs_buffer);
        result
    }

    /// The forward on host slices, into new vectors.
    pub fn rasterize(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        neighbors: Option<&[i64]>,
    ) -> Result<GpuFragments> {
        let n = plan.slots() as usize;
        let mut f = GpuFragments {
            pix_to_face: vec![0; n],
            zbuf: vec![0.0; n],
            dists: vec![0.0; n],
            bary_coords: vec![0.0; 3 * n],
        };
        self.rasterize_into(
            ctx,
            plan,
            face_verts,
            neighbors,
            HostFragments {
                pix_to_face: &mut f.pix_to_face,
                zbuf: &mut f.zbuf,
                dists: &mut f.dists,
                bary_coords: &mut f.bary_coords,
            },
        )?;
        Ok(f)
    }

    /// The backward on host slices: the gradient of
    /// `Σ grad_zbuf·zbuf + grad_bary·bary_coords + grad_dists·dists` to `face_verts`, given
    /// the forward's `pix_to_face`, into `grad_face_verts` (nine f32 per face).
    #[allow(clippy::too_many_arguments)]
    pub fn rasterize_grad_into(
        &mut self,
        ctx: &Context,
        plan: &FragmentPlan,
        face_verts: &[f32],
        pix_to_face: &[i64],
        grad_zbuf: &[f32],
        grad_bary: &[f32],
        grad_dists: &[f32],
        grad_face_verts: &mut [f32],
    ) -> Result<()> {
        Self::check_host_inputs(plan, face_verts, None)?;
        let slots = plan.slots();
        let n = slots as usize;
        if pix_to_face.len() != n
            || grad_zbuf.len() != n
            || grad_dists.len() != n
            || grad_bary.len() != 3 * n
            || grad_face_verts.len() != face_verts.len()
        {
            return Err(Error::Input(
                "fragment rasterizer backward: slices of the wrong length".into(),
            ));
        }
        super::check_pix_to_face(pix_to_face, plan.face_count as usize)?;
        let parts = SlotParts::new(slots);
        let layout = self.upload_inputs(ctx, plan, face_verts, None, parts.total)?;
        {
            let buffer = self.host.inputs.as_mut().expect("uploaded");
            let bytes = buffer.mapped_mut().expect("host-mapped");
            for (at, part) in parts.at.iter().zip([
                bytemuck::cast_slice::<i64, u8>(pix_to_face),
                bytemuck::cast_slice(grad_zbuf),
                bytemuck::cast_slice(grad_dists),
                bytemuck::cast_slice(grad_bary),
            ]) {
                let at = (layout.extra + at) as usize;
                bytes[at..at + part.len()].copy_from_slice(part);
            }
        }
        let faces = u64::from(plan.face_count);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "fragments",
            (36 * faces).max(36),
            MemoryKind::Readback,
        )?;
        let inputs_buffer = self.host.inputs.take().expect("uploaded");
        let outputs_buffer = self.host.outputs.take().expect("made above");
        let result = (|| {
            let inputs = layout.inputs(&inputs_buffer);
            self.submit(ctx, |s, rec| s.record_setup(rec, plan, inputs))?;
            self.bin(ctx)?;
            let e = layout.extra;
            let [p, z, d, b] = parts.at.map(|at| e + at);
            let grads = FragmentGrads {
                pix_to_face: inputs_buffer.range(p, 8 * slots),
                grad_zbuf: inputs_buffer.range(z, 4 * slots),
                grad_dists: inputs_buffer.range(d, 4 * slots),
                grad_bary: inputs_buffer.range(b, 12 * slots),
            };
            let out = outputs_buffer.range(0, (36 * faces).max(4));
            self.submit(ctx, |s, rec| {
                // Faces of no mesh get 0.
                rec.fill(out, 0);
                s.record_backward(rec, plan, inputs, &grads, out)
            })?;
            let bytes = outputs_buffer.mapped().expect("host-mapped");
            bytemuck::cast_slice_mut::<f32, u8>(grad_face_verts)
                .copy_from_slice(&bytes[..36 * faces as usize]);
            Ok(())
        })();
        self.host.inputs = Some(inputs_buffer);
        self.host.outputs = Some(outputs_buffer);
        result
    }
}

/// Every part of a host-visible buffer starts 256-byte aligned: a storage binding's offset
/// alignment on any device.
fn align(x: u64) -> u64 {
    x.next_multiple_of(256)
}

/// Where the per-slot arrays lie in one buffer ([`FragmentRasterizer::rasterize_to`]):
/// `pix_to_face` (or its i64 upstream twin), `zbuf`, `dists`, `bary_coords`, in that order, each
/// at a byte offset 256-byte aligned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlotParts {
    /// Byte offsets of `pix_to_face`, `zbuf`, `dists` and `bary_coords`.
    pub at: [u64; 4],
    /// Bytes in all.
    pub total: u64,
}

impl SlotParts {
    /// The layout of `slots` slots.
    pub fn new(slots: u64) -> Self {
        let z = align(8 * slots);
        let d = z + align(4 * slots);
        let b = d + align(4 * slots);
        Self {
            at: [0, z, d, b],
            total: b + 12 * slots,
        }
    }
}

/// Where [`FragmentRasterizer`]'s host-visible input buffer holds each part.
struct InputLayout {
    meshes: u64,
    neighbors: u64,
    extra: u64,
    total: u64,
}

impl InputLayout {
    fn new(faces: u64, meshes: u64, extra: u64) -> Self {
        let m = align(36 * faces.max(1));
        let nb = m + align(8 * meshes);
        let e = nb + align(4 * faces.max(1));
        Self {
            meshes: m,
            neighbors: nb,
            extra: e,
            total: e + extra,
        }
    }

    fn inputs<'a>(&self, buffer: &'a Buffer) -> FragmentInputs<'a> {
        FragmentInputs {
            face_verts: buffer.range(0, self.meshes),
            meshes: buffer.range(self.meshes, self.neighbors - self.meshes),
        }
    }
}

/// The forward's outputs on the host, `[meshes, H, W, K]` slot-major (PyTorch3D's layout).
pub struct HostFragments<'a> {
    /// The packed face of each slot, −1 where empty.
    pub pix_to_face: &'a mut [i64],
    /// Depth per slot (−1 where empty).
    pub zbuf: &'a mut [f32],
    /// Signed squared distance per slot (−1 where empty).
    pub dists: &'a mut [f32],
    /// Three barycentrics per slot (−1 where empty).
    pub bary_coords: &'a mut [f32],
}

/// The forward's outputs in vectors ([`FragmentRasterizer::rasterize`]).
#[derive(Clone, Debug, PartialEq)]
pub struct GpuFragments {
    /// The packed face of each slot, −1 where empty.
    pub pix_to_face: Vec<i64>,
    /// Depth per slot.
    pub zbuf: Vec<f32>,
    /// Signed squared distance per slot.
    pub dists: Vec<f32>,
    /// Three barycentrics per slot.
    pub bary_coords: Vec<f32>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layout_matches_the_kernels() {
        for spec in [
            &specs::FRAG_SETUP,
            &specs::FRAG_FORWARD,
            &specs::FRAG_FINISH,
            &specs::FRAG_BACKWARD,
            &specs::FRAG_REDUCE,
        ] {
            assert_eq!(
                std::mem::size_of::<FragmentPush>() as u32,
                spec.push_constant_size,
                "{}",
                spec.name
            );
        }
    }
}
