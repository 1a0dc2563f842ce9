//! The recorded steps of [`FragmentRasterizer`] over caller buffers: setup and the binning's
//! count, the binning's lists, the forward passes and the finish, and the backward.

use super::{
    FragmentGrads, FragmentInputs, FragmentOutputs, FragmentPlan, FragmentPush, FragmentRasterizer,
};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{BufferRange, Context, MemoryKind, Recorder, groups};
use crate::raster::specs;

impl FragmentRasterizer {
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
}
