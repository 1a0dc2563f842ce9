//! The forward of sphere probing: the rays sorted by tile (`probe_ray_keys.comp`, the stable
//! radix sort, the ranges pass), then per ray the aggregate over its tile's anchors
//! (`probe_forward.comp`) or over every anchor (`probe_forward_brute.comp`, the baseline),
//! folded in passes under a driver's loop cap; and L_sil, summed in a fixed order.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::{Prober, lanes};
use crate::error::Result;
use crate::gpu::{BufferRange, Context, Kernel, KernelVariants, Recorder, groups, pass_size};
use crate::primitives::sum::SumPush;
use crate::probe::targets::GpuTargets;
use crate::specs;

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

impl Prober {
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
    /// the rays ([`Ray`](crate::probe::sampler::Ray) each, view-major, `rays_per_view` per view).
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
        rec.pass("bin list", |rec| self.record_list(rec))?;
        let rays = rays.sub(0, 16 * self.rays());
        rec.pass("ray sort", |rec| self.record_ray_sort(rec, rays))?;
        if self.rays() > 0 {
            rec.pass("forward rays", |rec| {
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

    pub(super) fn variant(
        &self,
        rec: &Recorder<'_>,
        variants: &KernelVariants,
    ) -> Result<Arc<Kernel>> {
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
        rec.pass("bin list", |rec| self.record_list(rec))?;
        rec.pass("ray sort", |rec| {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        let size = |s: &crate::gpu::KernelSpec| s.push_constant_size as usize;
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
        assert_eq!(specs::PROBE_FORWARD.bindings.len(), 10);
        assert_eq!(specs::PROBE_FORWARD_BRUTE.bindings.len(), 7);
    }
}
