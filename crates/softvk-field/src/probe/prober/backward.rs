//! The backward of sphere probing: dL_sil/dφ per anchor, without float atomics. Under G = max,
//! the rays sorted by the anchor their ψ came from and summed per anchor in ray order
//! (`probe_aux_keys.comp`, `probe_max_grad.comp`); otherwise a partial per binned (anchor, tile)
//! entry (`probe_backward.comp`), added per anchor view by view and tile by tile
//! (`probe_reduce.comp`).

use bytemuck::{Pod, Zeroable};

use super::{Prober, lanes};
use crate::error::Result;
use crate::gpu::{BufferRange, Context, GradOut, Recorder, check_floats, groups};
use crate::probe::Aggregate;
use crate::probe::targets::GpuTargets;
use crate::specs;

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

/// Loop iterations of one invocation of `probe_backward.comp` at most, for `rays` rays of which
/// at most `per_view` in one view (a tile holds one view's rays): a subgroup's entries lie in
/// at most `lanes` distinct tiles; per tile, a batch per `lanes` rays and a pass per ray.
pub(super) fn backward_iterations(ctx: &Context, rays: u64, per_view: u64) -> u64 {
    let (lanes, _) = lanes(ctx);
    let visited = rays.min(lanes * per_view);
    lanes + visited.div_ceil(lanes) + lanes + visited
}

impl Prober {
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
            rec.pass("backward entries", |rec| {
                self.dispatch_backward(rec, gpu, total, anchors, phi, rays, ranges)
            })?;
        }
        rec.pass("reduce", |rec| {
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
    pub(super) fn max_by_rays(&self, ctx: &Context) -> bool {
        self.settings.aggregate == Aggregate::Max
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
        rec.pass("ray sort by anchor", |rec| {
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
        rec.pass("max gradient", |rec| {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        let size = |s: &crate::gpu::KernelSpec| s.push_constant_size as usize;
        assert_eq!(
            std::mem::size_of::<BackwardPush>(),
            size(&specs::PROBE_BACKWARD)
        );
        assert_eq!(
            std::mem::size_of::<ReducePush>(),
            size(&specs::PROBE_REDUCE)
        );
        assert_eq!(
            std::mem::size_of::<AuxKeysPush>(),
            size(&specs::PROBE_AUX_KEYS)
        );
        assert_eq!(
            std::mem::size_of::<MaxGradPush>(),
            size(&specs::PROBE_MAX_GRAD)
        );
        assert_eq!(specs::PROBE_BACKWARD.bindings.len(), 12);
    }
}
