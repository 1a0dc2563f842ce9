//! The forward rasterization's steps on [`HardRasterizer`]: setup and the binning's count,
//! the binning's lists, the depth passes, the shade, and [`HardRasterizer::rasterize`] over
//! host slices.

use super::{
    HardInputs, HardLayer, HardPlan, HardPush, HardRasterizer, get, host_buffer, layout_of, put,
};
use crate::error::{Error, Result};
use crate::gpu::{BufferRange, Context, MemoryKind, Recorder, groups};
use crate::raster::hard::Shape;
use crate::raster::specs;

impl HardRasterizer {
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

    pub(super) fn check_inputs(plan: &HardPlan, inputs: &HardInputs<'_>) -> Result<()> {
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
}
