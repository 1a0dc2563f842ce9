//! The rasterizer's backward on [`HardRasterizer`]: the items' visible boxes and slots, the
//! fixed-order reduction's scratch, reduce and gather over the [`vertex_lists`], and the
//! position gradient of `rast` and `rast_db`.

use super::{
    HardInputs, HardPlan, HardPush, HardRasterizer, device_buffer, get, host_buffer, layout_of, put,
};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{BufferRange, Context, MemoryKind, Recorder, groups};
use crate::primitives::scan::ScanScratch;
use crate::raster::hard::{Shape, Topology};
use crate::raster::specs;
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

impl HardRasterizer {
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
    pub(super) fn grad_scratch(
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
    pub(super) fn record_reduce_gather(
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
}
