//! The baseline sphere probing is measured against: **dense marching**, the conventional way to
//! get a ray's occupancy from a field: sample every ray at a fixed step (one voxel of the field's
//! grid) through the cube, evaluate φ at every sample, take the max (ψ = max φ, the same G as
//! probing's default), and for the backward send dL/dψ to the maximizing sample and run the
//! field's backward over all samples.
//!
//! - [`DenseMarch::new`] takes the rays (read back from the sampler) and computes, on the host,
//!   each ray's sample count `ceil(chord / step)` (the chord of its line through the cube) and
//!   their exclusive prefix sum: only samples inside the cube are evaluated, at the centres of
//!   `count` equal parts of the chord (at most `step` apart).
//! - [`DenseMarch::record_points`] (`probe_dense_points.comp`) writes the samples,
//!   [`DenseMarch::record_max`] (`probe_dense_max.comp`) ψ per ray and, optionally, dL_sil/dφ
//!   per sample. Between them the caller evaluates the field at [`DenseMarch::points`].
//!
//! Twins in [`cpu`]. Deterministic: one writer per output, no float atomics.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use super::ProbeSettings;
use super::prober::{self, Constants};
use super::sampler::Ray;
use super::targets::{GpuTargets, Targets};
use crate::error::{Error, LimitKind, Result};
use crate::field::Cube;
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::gpu::{check_binding, groups};
use crate::specs;

/// Push constants of `probe_dense_points.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DensePointsPush {
    rays: u32,
    width: u32,
    height: u32,
    pad0: u32,
    inv_s: f32,
    step: f32,
    pad1: f32,
    pad2: f32,
    cube: [f32; 4],
}

/// Push constants of `probe_dense_max.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DenseMaxPush {
    rays: u32,
    write_grad: u32,
    coef: f32,
    pad: u32,
}

/// Dense marching of a fixed set of rays through a cube: kernels and buffers.
pub struct DenseMarch {
    points_kernel: Arc<Kernel>,
    max_kernel: Arc<Kernel>,
    rays: u32,
    total: u32,
    width: u32,
    height: u32,
    inv_s: f32,
    step: f32,
    cube: Cube,
    offsets: Buffer,
    points: Buffer,
    phi: Buffer,
    psi: Buffer,
    d_phi: Buffer,
}

impl DenseMarch {
    /// Dense marching of `rays` (views and image of `targets`) through `cube` at `step` (world
    /// units, > 0). [`Error::Limit`] when a ray's samples would pass the device's loop cap or
    /// all samples one binding.
    pub fn new(
        ctx: &Context,
        targets: &Targets,
        rays: &[Ray],
        cube: &Cube,
        step: f64,
    ) -> Result<Self> {
        cube.validate()?;
        if !(step.is_finite() && step > 0.0) || rays.is_empty() {
            return Err(Error::Input(format!(
                "dense marching: step {step} and {} rays; need a step > 0 and some rays",
                rays.len()
            )));
        }
        let counts = cpu::counts(targets, rays, cube, step);
        let most = counts.iter().copied().max().unwrap_or(0);
        if let Some(limit) = ctx.info().shader_loop_limit() {
            if u64::from(most) > limit {
                return Err(Error::DeviceLimit {
                    kind: LimitKind::LoopIterations,
                    what: format!("dense marching: {most} samples on one ray"),
                    need: u64::from(most),
                    max: limit,
                    device: ctx.info().name.clone(),
                    hint: "use a larger step",
                });
            }
        }
        let offsets = cpu::offsets(&counts);
        let total = *offsets.last().expect("n + 1 offsets");
        check_binding(ctx, "dense marching: samples", 16 * u64::from(total))?;
        let n = rays.len() as u32;
        Ok(Self {
            points_kernel: ctx.kernel(&specs::PROBE_DENSE_POINTS, &[])?,
            max_kernel: ctx.kernel(&specs::PROBE_DENSE_MAX, &[])?,
            rays: n,
            total,
            width: targets.width,
            height: targets.height,
            inv_s: (1.0 / f64::from(targets.width.min(targets.height))) as f32,
            step: step as f32,
            cube: *cube,
            offsets: ctx.upload_buffer("dense offsets", &offsets)?,
            points: ctx.create_buffer(
                "dense points",
                16 * u64::from(total.max(1)),
                MemoryKind::Device,
            )?,
            phi: ctx.create_buffer("dense phi", 4 * u64::from(total.max(1)), MemoryKind::Device)?,
            psi: ctx.create_buffer("dense psi", 4 * u64::from(n), MemoryKind::Device)?,
            d_phi: ctx.create_buffer(
                "dense d_phi",
                4 * u64::from(total.max(1)),
                MemoryKind::Device,
            )?,
        })
    }

    /// Samples over all rays.
    pub fn sample_count(&self) -> u32 {
        self.total
    }

    /// The samples (`vec4`, w = 1), ray after ray, once [`DenseMarch::record_points`] ran.
    pub fn points(&self) -> &Buffer {
        &self.points
    }

    /// A buffer for φ at the samples (the caller's field writes it).
    pub fn phi(&self) -> &Buffer {
        &self.phi
    }

    /// ψ per ray.
    pub fn psi(&self) -> &Buffer {
        &self.psi
    }

    /// dL_sil/dφ per sample.
    pub fn d_phi(&self) -> &Buffer {
        &self.d_phi
    }

    /// Records the samples of `rays` (the rays given to [`DenseMarch::new`], on the GPU).
    pub fn record_points(
        &self,
        rec: &mut Recorder<'_>,
        gpu: &GpuTargets,
        rays: BufferRange<'_>,
    ) -> Result<()> {
        let c = self.cube.to_f32();
        rec.dispatch(
            &self.points_kernel,
            &specs::ProbeDensePointsBindings {
                rays: rays.sub(0, 16 * u64::from(self.rays)),
                views: gpu.views().whole(),
                offsets: self.offsets.whole(),
                points: self.points.whole(),
            }
            .for_kernel(&self.points_kernel)?,
            &DensePointsPush {
                rays: self.rays,
                width: self.width,
                height: self.height,
                pad0: 0,
                inv_s: self.inv_s,
                step: self.step,
                pad1: 0.0,
                pad2: 0.0,
                cube: c,
            },
            groups(u64::from(self.rays), 64)?,
        )
    }

    /// Records ψ per ray from [`DenseMarch::phi`] and, with `grad`, dL_sil/dφ per sample into
    /// [`DenseMarch::d_phi`].
    pub fn record_max(
        &self,
        rec: &mut Recorder<'_>,
        rays: BufferRange<'_>,
        grad: bool,
    ) -> Result<()> {
        rec.dispatch(
            &self.max_kernel,
            &specs::ProbeDenseMaxBindings {
                rays: rays.sub(0, 16 * u64::from(self.rays)),
                offsets: self.offsets.whole(),
                phi: self.phi.whole(),
                psi: self.psi.whole(),
                d_phi: self.d_phi.whole(),
            }
            .for_kernel(&self.max_kernel)?,
            &DenseMaxPush {
                rays: self.rays,
                write_grad: u32::from(grad),
                coef: (2.0 / f64::from(self.rays)) as f32,
                pad: 0,
            },
            groups(u64::from(self.rays), 64)?,
        )
    }
}

/// CPU twins.
pub mod cpu {
    use super::*;

    /// The chord `[t0, t1]` of a line through the cube (in units of `d`), as the kernel clips.
    fn chord(o: [f32; 3], d: [f32; 3], cube: &Cube) -> (f64, f64) {
        let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
        for a in 0..3 {
            let (lo, hi) = (cube.center[a] - cube.half, cube.center[a] + cube.half);
            let (oa, da) = (f64::from(o[a]), f64::from(d[a]));
            if da != 0.0 {
                let (ta, tb) = ((lo - oa) / da, (hi - oa) / da);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
        }
        (t0, t1)
    }

    fn line(targets: &Targets, ray: &Ray) -> ([f32; 3], [f32; 3]) {
        let c = Constants::new(&ProbeSettings::default(), targets.width, targets.height);
        prober::cpu::ray_line(
            &targets.views[ray.view as usize],
            ray,
            targets.width,
            targets.height,
            c.inv_s,
        )
    }

    /// Samples per ray: `ceil(chord length / step)`, 0 for a ray that misses the cube.
    pub fn counts(targets: &Targets, rays: &[Ray], cube: &Cube, step: f64) -> Vec<u32> {
        rays.iter()
            .map(|r| {
                let (o, d) = line(targets, r);
                let (t0, t1) = chord(o, d, cube);
                let len = DVec3::from(d.map(f64::from)).length();
                if t1 > t0 {
                    ((t1 - t0) * len / step).ceil() as u32
                } else {
                    0
                }
            })
            .collect()
    }

    /// The exclusive prefix sum of `counts`, with the total appended (n + 1 values).
    pub fn offsets(counts: &[u32]) -> Vec<u32> {
        let mut out = Vec::with_capacity(counts.len() + 1);
        let mut acc = 0u32;
        out.push(0);
        for &c in counts {
            acc += c;
            out.push(acc);
        }
        out
    }

    /// `probe_dense_points.comp`, in f64 (the step is carried by the offsets).
    pub fn points(targets: &Targets, rays: &[Ray], offsets: &[u32], cube: &Cube) -> Vec<[f64; 3]> {
        let mut out = Vec::new();
        for (i, r) in rays.iter().enumerate() {
            let (o, d) = line(targets, r);
            let (t0, t1) = chord(o, d, cube);
            let (o, d) = (DVec3::from(o.map(f64::from)), DVec3::from(d.map(f64::from)));
            let count = offsets[i + 1] - offsets[i];
            let dt = (t1 - t0) / f64::from(count.max(1));
            for k in 0..count {
                let p = o + (t0 + (f64::from(k) + 0.5) * dt) * d;
                out.push(p.to_array());
            }
        }
        out
    }

    /// `probe_dense_max.comp`: ψ per ray and dL_sil/dφ per sample.
    pub fn max(rays: &[Ray], offsets: &[u32], phi: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let mut psi = Vec::with_capacity(rays.len());
        let mut d = vec![0.0; phi.len()];
        let coef = 2.0 / rays.len() as f64;
        for (i, r) in rays.iter().enumerate() {
            let (a, b) = (offsets[i] as usize, offsets[i + 1] as usize);
            let mut arg = None;
            for k in a..b {
                if arg.is_none_or(|j: usize| phi[k] > phi[j]) {
                    arg = Some(k);
                }
            }
            let m = arg.map_or(0.0, |k| phi[k]);
            if let Some(k) = arg {
                d[k] = coef * (m - f64::from(r.label));
            }
            psi.push(m);
        }
        (psi, d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        assert_eq!(
            std::mem::size_of::<DensePointsPush>() as u32,
            specs::PROBE_DENSE_POINTS.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<DenseMaxPush>() as u32,
            specs::PROBE_DENSE_MAX.push_constant_size
        );
    }
}
