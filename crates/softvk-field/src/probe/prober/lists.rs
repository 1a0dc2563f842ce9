//! The binning of sphere probing: per view the anchor items and their tiles' anchor masks
//! (`probe_items.comp`), each tile's entry count and first entry (`bin_mask_counts.comp` and a
//! scan), the count read back (exact) or left on the GPU for a gate (guarded), and each tile's
//! anchors in index order (`probe_mask_list.comp`, folded in passes under a driver's loop cap);
//! the entry buffers sized for the count or a capacity.

use bytemuck::{Pod, Zeroable};

use super::{Prober, check_loop};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::gate::IterationGate;
use crate::gpu::{
    BufferRange, Context, MemoryKind, Recorder, check_binding, check_texels, groups, pass_size,
};
use crate::primitives::binning;
use crate::probe::targets::GpuTargets;
use crate::specs;

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

/// Loop iterations of one invocation of `probe_mask_list.comp` at most, for masks of `words`
/// words listed `per_pass` words a pass: the bit counts of the words before the pass, then per
/// word of the pass one iteration and one per set bit (at most 32).
pub(super) fn list_iterations(words: u64, per_pass: u64) -> u64 {
    words + 32 * per_pass.min(words) + 2
}

impl Prober {
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
        rec.pass("items", |rec| self.record_items(rec, gpu, anchors))?;
        rec.pass("mask scan", |rec| self.record_mask_scan(rec))
    }

    fn record_mask_scan(&self, rec: &mut Recorder<'_>) -> Result<()> {
        let tiles = self.job.tile_count();
        let counts = self.offsets.range(0, 4 * tiles);
        rec.dispatch(
            &self.mask_counts_kernel,
            &crate::gpu::specs::BinMaskCountsBindings {
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
    pub(super) fn record_list(&self, rec: &mut Recorder<'_>) -> Result<()> {
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
    pub(super) fn entry_count(&self) -> Result<u64> {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        let size = |s: &crate::gpu::KernelSpec| s.push_constant_size as usize;
        assert_eq!(std::mem::size_of::<ItemsPush>(), size(&specs::PROBE_ITEMS));
        assert_eq!(
            std::mem::size_of::<WordsPush>(),
            size(&crate::gpu::specs::BIN_MASK_COUNTS)
        );
        assert_eq!(
            std::mem::size_of::<ListPush>(),
            size(&specs::PROBE_MASK_LIST)
        );
    }
}
