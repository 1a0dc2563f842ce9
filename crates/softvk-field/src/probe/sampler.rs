//! Sampling, fresh every iteration and reproducible from (seed, iteration): the probing rays,
//! the anchors and the geometric regularizer's surface candidates, written by
//! [`Sampler::record`] into buffers the sampler owns.
//!
//! - **Rays** (`probe_sample_rays.comp`), [`ProbeSettings::rays_per_view`] per view, view-major:
//!   the first `round(N_r · ray_uniform_fraction)` of a view pick a pixel uniformly, the rest
//!   from the view's contour density: `|G_σc * ΔS|` (the 5-point Laplacian of the silhouette,
//!   replicated at the border, smoothed by a separable Gaussian of σ_c pixels truncated at 3σ_c),
//!   quantized to integers per view (its maximum → [`Sampler::quantum`]) once on the host, and
//!   turned into a CDF by the GPU's exclusive [`Scan`] once at construction. A pixel is drawn by
//!   binary search in the CDF; a view without contour falls back to uniform. Both kinds jitter
//!   uniformly within the pixel: a [`Ray`] holds a continuous pixel position and the
//!   silhouette's value at its pixel, its label S ∈ {0, 1}.
//! - **Anchors** (`probe_sample_points.comp`), [`ProbeSettings::anchors`] of them: the first
//!   `round(N_a · anchor_uniform_fraction)` uniform in the cube, the rest a visual-hull boundary
//!   point ([`super::hull`]) picked uniformly plus N(0, σ_a²) noise per axis (Box–Muller),
//!   clamped to the cube. Written as `(x, y, z, 1)`.
//! - **Surface candidates**, [`ProbeSettings::geo_candidates`] of them, drawn the same way
//!   (with `geo_uniform_fraction`) in the cube shrunk by `δ + δ_n`, so that every point of
//!   their stencils ([`super::geo`]) stays in the cube.
//!
//! Every random word is `pcg_hash(key ^ pcg_hash(8 · index + draw))` with one key per (seed,
//! iteration, stream) ([`super::rng`]). Integer decisions and the uniform coordinates are exact
//! f32 operations, so the twin ([`cpu`]) reproduces rays and uniform points bit for bit; the
//! Gaussian points go through the GPU's `log`, `sqrt`, `cos` and `sin` and agree to about 1e-7.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::rng::{STREAM_RAYS, stream_key};
use super::targets::{GpuTargets, Targets};
use super::{ProbeSettings, hull};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, Kernel, MemoryKind, Recorder};
use crate::gpu::{check_binding, groups};
use crate::primitives::{Scan, ScanScratch};
use crate::specs;

/// One probing ray. Twin of `Ray` in `kernels/softvk/include/probe.glsl`; 16 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Ray {
    /// Continuous column position: pixel `c` spans `[c, c + 1)`.
    pub px: f32,
    /// Continuous row position from the top: pixel row `r` spans `[r, r + 1)`.
    pub py: f32,
    /// The view.
    pub view: u32,
    /// The silhouette at the ray's pixel, 0 or 1.
    pub label: f32,
}

/// Push constants of `probe_sample_rays.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct RaysPush {
    views: u32,
    rays_per_view: u32,
    uniform_per_view: u32,
    width: u32,
    height: u32,
    key: u32,
    pad: [u32; 2],
}

/// What `probe_sample_points.comp` draws: its push constants. Also the twin's input.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct PointsPush {
    /// Points drawn.
    pub count: u32,
    /// The first `uniform_count` are uniform in the box.
    pub uniform_count: u32,
    /// Boundary points to draw around (0: all uniform).
    pub boundary_count: u32,
    /// The stream's key.
    pub key: u32,
    /// The box's lower corner.
    pub lo: [f32; 3],
    /// σ of the Gaussian around boundary points.
    pub sigma: f32,
    /// The box's edge per axis.
    pub size: [f32; 3],
    pad0: f32,
    /// The box's upper corner (clamp bound).
    pub hi: [f32; 3],
    pad1: f32,
}

impl PointsPush {
    /// Points drawn in the box `[lo, hi]`.
    pub fn new(
        count: u32,
        uniform_count: u32,
        boundary_count: u32,
        key: u32,
        lo: [f64; 3],
        hi: [f64; 3],
        sigma: f64,
    ) -> Self {
        let lo32 = lo.map(|c| c as f32);
        let hi32 = hi.map(|c| c as f32);
        Self {
            count,
            uniform_count,
            boundary_count,
            key,
            lo: lo32,
            sigma: sigma as f32,
            size: [0, 1, 2].map(|i| (hi[i] - lo[i]) as f32),
            pad0: 0.0,
            hi: hi32,
            pad1: 0.0,
        }
    }
}

/// The sampler: its kernels, the contour CDF, the boundary points and the output buffers.
pub struct Sampler {
    rays_kernel: Arc<Kernel>,
    points_kernel: Arc<Kernel>,
    settings: ProbeSettings,
    views: u32,
    width: u32,
    height: u32,
    quantum: u32,
    cdf: Buffer,
    boundary_host: Vec<[f32; 4]>,
    boundary: Buffer,
    rays: Buffer,
    anchors: Buffer,
    candidates: Buffer,
}

impl Sampler {
    /// The sampler of `targets` (uploaded as `gpu`): computes the visual hull's boundary and
    /// the contour densities on the host, and their CDF on the GPU (one submission, waited on).
    pub fn new(
        ctx: &Context,
        targets: &Targets,
        gpu: &GpuTargets,
        settings: &ProbeSettings,
    ) -> Result<Self> {
        settings.validate()?;
        let boundary = hull::boundary_points(targets, settings);
        Self::with_boundary(ctx, targets, gpu, settings, boundary)
    }

    /// As [`Sampler::new`], with the visual hull's boundary points given (`(x, y, z, ·)` each,
    /// e.g. from another visual hull); empty: every anchor uniform.
    pub fn with_boundary(
        ctx: &Context,
        targets: &Targets,
        gpu: &GpuTargets,
        settings: &ProbeSettings,
        boundary: Vec<[f32; 4]>,
    ) -> Result<Self> {
        settings.validate()?;
        if gpu.view_count() != targets.view_count()
            || gpu.width() != targets.width
            || gpu.height() != targets.height
        {
            return Err(Error::Input(
                "sampler: the GPU targets are not the uploaded host targets".into(),
            ));
        }
        if boundary.len() as u64 > u64::from(u32::MAX)
            || boundary.iter().flatten().any(|c| !c.is_finite())
        {
            return Err(Error::Input(
                "sampler: the boundary points are too many or not finite".into(),
            ));
        }
        let views = targets.view_count();
        let rays = u64::from(views) * u64::from(settings.rays_per_view);
        if rays > u64::from(super::MAX_SAMPLES) {
            return Err(Error::Limit(format!(
                "sampler: {views} views × {} rays is over {} rays per iteration",
                settings.rays_per_view,
                super::MAX_SAMPLES
            )));
        }
        check_binding(ctx, "sampler: rays", 16 * rays)?;
        check_binding(ctx, "sampler: anchors", 16 * u64::from(settings.anchors))?;
        check_binding(
            ctx,
            "sampler: candidates",
            16 * u64::from(settings.geo_candidates),
        )?;
        let (mut weights_host, quantum) = cpu::contour_weights(targets, settings.contour_sigma)?;
        // A zero after the last pixel puts the total at the CDF's end; the weights themselves
        // are needed only to scan them, so they do not stay on the device.
        weights_host.push(0);
        let n = weights_host.len() as u64;
        let weights = ctx.upload_buffer("probe contour weights", &weights_host)?;
        let cdf = ctx.create_buffer("probe contour CDF", 4 * n, MemoryKind::Device)?;
        let scan = Scan::new(ctx)?;
        let scratch = ScanScratch::new(ctx, n)?;
        ctx.submit_and_wait(|rec| scan.record(rec, &scratch, weights.whole(), cdf.whole(), n))?;
        drop((weights, scratch));
        let boundary_buffer = if boundary.is_empty() {
            ctx.upload_buffer("probe hull boundary", &[[0f32; 4]])?
        } else {
            ctx.upload_buffer("probe hull boundary", &boundary)?
        };
        Ok(Self {
            rays_kernel: ctx.kernel(&specs::PROBE_SAMPLE_RAYS, &[])?,
            points_kernel: ctx.kernel(&specs::PROBE_SAMPLE_POINTS, &[])?,
            settings: *settings,
            views,
            width: targets.width,
            height: targets.height,
            quantum,
            cdf,
            boundary_host: boundary,
            boundary: boundary_buffer,
            rays: ctx.create_buffer("probe rays", 16 * rays, MemoryKind::Device)?,
            anchors: ctx.create_buffer(
                "probe anchors",
                16 * u64::from(settings.anchors),
                MemoryKind::Device,
            )?,
            candidates: ctx.create_buffer(
                "probe surface candidates",
                16 * u64::from(settings.geo_candidates),
                MemoryKind::Device,
            )?,
        })
    }

    /// Records the samples of `iteration`: [`Sampler::rays`], [`Sampler::anchors`] and
    /// [`Sampler::candidates`].
    pub fn record(&self, rec: &mut Recorder<'_>, gpu: &GpuTargets, iteration: u32) -> Result<()> {
        if gpu.view_count() != self.views
            || gpu.width() != self.width
            || gpu.height() != self.height
        {
            return Err(Error::Input(
                "sampler: recorded with other targets than it was made for".into(),
            ));
        }
        let s = &self.settings;
        let push = RaysPush {
            views: self.views,
            rays_per_view: s.rays_per_view,
            uniform_per_view: ProbeSettings::uniform_count(s.rays_per_view, s.ray_uniform_fraction),
            width: self.width,
            height: self.height,
            key: stream_key(s.seed, iteration, STREAM_RAYS),
            pad: [0; 2],
        };
        let rays = self.ray_count();
        rec.dispatch(
            &self.rays_kernel,
            &specs::ProbeSampleRaysBindings {
                masks: gpu.masks().whole(),
                cdf: self.cdf.whole(),
                rays: self.rays.whole(),
            }
            .for_kernel(&self.rays_kernel)?,
            &push,
            groups(rays, 64)?,
        )?;
        for (push, out) in [
            (self.anchor_push(iteration), &self.anchors),
            (self.candidate_push(iteration), &self.candidates),
        ] {
            rec.dispatch(
                &self.points_kernel,
                &specs::ProbeSamplePointsBindings {
                    boundary: self.boundary.whole(),
                    points: out.whole(),
                }
                .for_kernel(&self.points_kernel)?,
                &push,
                groups(u64::from(push.count), 64)?,
            )?;
        }
        Ok(())
    }

    /// What the anchors of `iteration` are drawn from.
    pub fn anchor_push(&self, iteration: u32) -> PointsPush {
        cpu::anchor_push(&self.settings, self.boundary_host.len() as u32, iteration)
    }

    /// What the surface candidates of `iteration` are drawn from.
    pub fn candidate_push(&self, iteration: u32) -> PointsPush {
        cpu::candidate_push(&self.settings, self.boundary_host.len() as u32, iteration)
    }

    /// The rays of the last recorded iteration ([`Ray`] each, view-major).
    pub fn rays(&self) -> &Buffer {
        &self.rays
    }

    /// The anchors of the last recorded iteration (`vec4` each, w = 1).
    pub fn anchors(&self) -> &Buffer {
        &self.anchors
    }

    /// The surface candidates of the last recorded iteration (`vec4` each, w = 1).
    pub fn candidates(&self) -> &Buffer {
        &self.candidates
    }

    /// Rays per iteration (all views).
    pub fn ray_count(&self) -> u64 {
        u64::from(self.views) * u64::from(self.settings.rays_per_view)
    }

    /// The exclusive prefix sum of the quantized contour weights over all views (view-major),
    /// computed by the GPU scan, and after the last pixel their total
    /// ([`cpu::exclusive_prefix`] of [`cpu::contour_weights`]).
    pub fn cdf(&self) -> &Buffer {
        &self.cdf
    }

    /// The integer a view's largest contour density is quantized to.
    pub fn quantum(&self) -> u32 {
        self.quantum
    }

    /// The visual hull's boundary points the anchors are drawn around.
    pub fn boundary_points(&self) -> &[[f32; 4]] {
        &self.boundary_host
    }

    /// The settings the sampler was made with.
    pub fn settings(&self) -> &ProbeSettings {
        &self.settings
    }
}

/// CPU twins.
pub mod cpu {
    use super::{PointsPush, Ray};
    use crate::error::{Error, Result};
    use crate::probe::ProbeSettings;
    use crate::probe::rng::{
        STREAM_ANCHORS, STREAM_CANDIDATES, STREAM_RAYS, rand_u32, scale_u32, stream_key,
        unit_float, unit_float_open0,
    };
    use crate::probe::targets::Targets;

    /// The contour density `|G_σ * ΔS|` of every view (f64, view-major, row-major).
    pub fn contour_density(targets: &Targets, sigma: f64) -> Vec<f64> {
        let (w, h) = (targets.width as usize, targets.height as usize);
        let clamp = |v: isize, n: usize| v.clamp(0, n as isize - 1) as usize;
        let radius = (3.0 * sigma).ceil() as isize;
        let kernel: Vec<f64> = if sigma > 0.0 {
            let k: Vec<f64> = (-radius..=radius)
                .map(|i| (-((i * i) as f64) / (2.0 * sigma * sigma)).exp())
                .collect();
            let total: f64 = k.iter().sum();
            k.iter().map(|x| x / total).collect()
        } else {
            vec![1.0]
        };
        let radius = if sigma > 0.0 { radius } else { 0 };
        let mut out = Vec::with_capacity(targets.masks.len());
        for view in 0..targets.views.len() {
            let m = targets.mask(view);
            let at = |c: isize, r: isize| f64::from(m[clamp(r, h) * w + clamp(c, w)]);
            let mut lap = vec![0.0; w * h];
            for r in 0..h as isize {
                for c in 0..w as isize {
                    lap[r as usize * w + c as usize] =
                        at(c - 1, r) + at(c + 1, r) + at(c, r - 1) + at(c, r + 1) - 4.0 * at(c, r);
                }
            }
            let mut tmp = vec![0.0; w * h];
            for r in 0..h {
                for c in 0..w as isize {
                    tmp[r * w + c as usize] = (-radius..=radius)
                        .map(|i| kernel[(i + radius) as usize] * lap[r * w + clamp(c + i, w)])
                        .sum();
                }
            }
            for r in 0..h as isize {
                for c in 0..w {
                    let v: f64 = (-radius..=radius)
                        .map(|i| kernel[(i + radius) as usize] * tmp[clamp(r + i, h) * w + c])
                        .sum();
                    out.push(v.abs());
                }
            }
        }
        out
    }

    /// The contour densities quantized for the GPU's u32 CDF: per view, `round(d / max · Q)`
    /// with `Q = min(65535, ⌊(2^32 − 1) / all pixels⌋)`, so that the sum over all views fits in
    /// a `u32`. Returns the weights and Q.
    pub fn contour_weights(targets: &Targets, sigma: f64) -> Result<(Vec<u32>, u32)> {
        let density = contour_density(targets, sigma);
        let q = (u64::from(u32::MAX) / (density.len() as u64).max(1)).min(65_535) as u32;
        if q < 16 {
            return Err(Error::Limit(format!(
                "sampler: {} pixels over all views leave too little room in a u32 CDF",
                density.len()
            )));
        }
        let pixels = targets.pixels();
        let mut weights = Vec::with_capacity(density.len());
        for view in density.chunks(pixels) {
            let max = view.iter().fold(0.0f64, |m, &d| m.max(d));
            // Densities below 1e-9 of the maximum are the Gaussian's round-off, not contour.
            weights.extend(view.iter().map(|&d| {
                if max > 0.0 && d > 1e-9 * max {
                    (d / max * f64::from(q)).round() as u32
                } else {
                    0
                }
            }));
        }
        Ok((weights, q))
    }

    /// The exclusive prefix sum, and the total after it: `weights.len() + 1` entries (wrapping,
    /// as the GPU's).
    pub fn exclusive_prefix(weights: &[u32]) -> Vec<u32> {
        let mut acc = 0u32;
        let mut cdf: Vec<u32> = weights
            .iter()
            .map(|&w| {
                let r = acc;
                acc = acc.wrapping_add(w);
                r
            })
            .collect();
        cdf.push(acc);
        cdf
    }

    /// `probe_sample_rays.comp`: the rays of one iteration.
    pub fn sample_rays(
        targets: &Targets,
        weights: &[u32],
        rays_per_view: u32,
        uniform_per_view: u32,
        key: u32,
    ) -> Vec<Ray> {
        let cdf = exclusive_prefix(weights);
        let pixels = (targets.width * targets.height) as usize;
        let mut rays = Vec::with_capacity(targets.views.len() * rays_per_view as usize);
        for view in 0..targets.views.len() {
            let first = view * pixels;
            let last = first + pixels - 1;
            let base = cdf[first];
            let total = cdf[last + 1].wrapping_sub(base);
            for i in 0..rays_per_view {
                let id = view as u32 * rays_per_view + i;
                let h = rand_u32(key, id, 0);
                let pixel = if i < uniform_per_view || total == 0 {
                    scale_u32(h, pixels as u32) as usize
                } else {
                    let target = base + scale_u32(h, total);
                    // The last pixel of the view with cdf <= target.
                    let within = &cdf[first..=last];
                    within.partition_point(|&c| c <= target) - 1
                };
                let (row, col) = (
                    pixel / targets.width as usize,
                    pixel % targets.width as usize,
                );
                let px = col as f32 + unit_float(rand_u32(key, id, 1));
                let py = row as f32 + unit_float(rand_u32(key, id, 2));
                let label = if targets.masks[first + pixel] >= 0.5 {
                    1.0
                } else {
                    0.0
                };
                rays.push(Ray {
                    px,
                    py,
                    view: view as u32,
                    label,
                });
            }
        }
        rays
    }

    /// `probe_sample_points.comp`: the points `push` describes, around `boundary`.
    pub fn sample_points(push: &PointsPush, boundary: &[[f32; 4]]) -> Vec<[f32; 4]> {
        let key = push.key;
        (0..push.count)
            .map(|id| {
                let mut p = [0f32; 3];
                if id < push.uniform_count || push.boundary_count == 0 {
                    for (a, pa) in p.iter_mut().enumerate() {
                        *pa = push.lo[a] + push.size[a] * unit_float(rand_u32(key, id, a as u32));
                    }
                } else {
                    let b = boundary[scale_u32(rand_u32(key, id, 0), push.boundary_count) as usize];
                    let u = |d: u32| f64::from(unit_float(rand_u32(key, id, d)));
                    let u0 = |d: u32| f64::from(unit_float_open0(rand_u32(key, id, d)));
                    let tau = std::f64::consts::TAU;
                    let (r1, t1) = ((-2.0 * u0(1).ln()).sqrt(), tau * u(2));
                    let (r2, t2) = ((-2.0 * u0(3).ln()).sqrt(), tau * u(4));
                    let g = [r1 * t1.cos(), r1 * t1.sin(), r2 * t2.cos()];
                    for a in 0..3 {
                        p[a] = (f64::from(b[a]) + f64::from(push.sigma) * g[a]) as f32;
                    }
                }
                [
                    p[0].clamp(push.lo[0], push.hi[0]),
                    p[1].clamp(push.lo[1], push.hi[1]),
                    p[2].clamp(push.lo[2], push.hi[2]),
                    1.0,
                ]
            })
            .collect()
    }

    /// The anchors' [`PointsPush`] of `iteration`.
    pub fn anchor_push(settings: &ProbeSettings, boundary: u32, iteration: u32) -> PointsPush {
        PointsPush::new(
            settings.anchors,
            ProbeSettings::uniform_count(settings.anchors, settings.anchor_uniform_fraction),
            boundary,
            stream_key(settings.seed, iteration, STREAM_ANCHORS),
            settings.cube_min(),
            settings.cube_max(),
            settings.anchor_sigma,
        )
    }

    /// The surface candidates' [`PointsPush`] of `iteration`: the cube shrunk by `δ + δ_n`.
    pub fn candidate_push(settings: &ProbeSettings, boundary: u32, iteration: u32) -> PointsPush {
        let margin = settings.geo_delta + settings.geo_normal_delta;
        PointsPush::new(
            settings.geo_candidates,
            ProbeSettings::uniform_count(settings.geo_candidates, settings.geo_uniform_fraction),
            boundary,
            stream_key(settings.seed, iteration, STREAM_CANDIDATES),
            settings.cube_min().map(|c| c + margin),
            settings.cube_max().map(|c| c - margin),
            settings.anchor_sigma,
        )
    }

    /// The samples of one iteration.
    #[derive(Clone, Debug, PartialEq)]
    pub struct Samples {
        /// The rays, view-major.
        pub rays: Vec<Ray>,
        /// The anchors.
        pub anchors: Vec<[f32; 4]>,
        /// The surface candidates.
        pub candidates: Vec<[f32; 4]>,
    }

    /// Everything [`super::Sampler::record`] writes for `iteration`.
    pub fn sample(
        targets: &Targets,
        settings: &ProbeSettings,
        boundary: &[[f32; 4]],
        iteration: u32,
    ) -> Result<Samples> {
        let (weights, _) = contour_weights(targets, settings.contour_sigma)?;
        let b = boundary.len() as u32;
        Ok(Samples {
            rays: sample_rays(
                targets,
                &weights,
                settings.rays_per_view,
                ProbeSettings::uniform_count(settings.rays_per_view, settings.ray_uniform_fraction),
                stream_key(settings.seed, iteration, STREAM_RAYS),
            ),
            anchors: sample_points(&anchor_push(settings, b, iteration), boundary),
            candidates: sample_points(&candidate_push(settings, b, iteration), boundary),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::probe::targets::sphere_silhouettes;

    #[test]
    fn push_layouts_match_the_kernels() {
        assert_eq!(
            std::mem::size_of::<RaysPush>() as u32,
            specs::PROBE_SAMPLE_RAYS.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<PointsPush>() as u32,
            specs::PROBE_SAMPLE_POINTS.push_constant_size
        );
        assert_eq!(std::mem::size_of::<Ray>(), 16);
        assert_eq!(std::mem::offset_of!(PointsPush, size), 32);
        assert_eq!(std::mem::offset_of!(PointsPush, hi), 48);
    }

    #[test]
    fn contour_weights_live_near_the_silhouette_edge() {
        let cams = [Camera::from_angles(2.732, 10.0, 20.0)];
        let t = sphere_silhouettes(&cams, 40, 30, 0.5).unwrap();
        let sigma = 1.5;
        let (w, q) = cpu::contour_weights(&t, sigma).unwrap();
        assert_eq!(w.iter().copied().max(), Some(q));
        let m = t.mask(0);
        let (width, height) = (40i64, 30i64);
        let near_edge = |c: i64, r: i64| {
            let me = m[(r * width + c) as usize];
            let reach = (3.0 * sigma).ceil() as i64 + 1;
            (-reach..=reach).any(|dr| {
                (-reach..=reach).any(|dc| {
                    let (cc, rr) = ((c + dc).clamp(0, width - 1), (r + dr).clamp(0, height - 1));
                    m[(rr * width + cc) as usize] != me
                })
            })
        };
        let mut nonzero = 0;
        for r in 0..height {
            for c in 0..width {
                if w[(r * width + c) as usize] > 0 {
                    nonzero += 1;
                    assert!(near_edge(c, r), "weight far from the edge at ({c}, {r})");
                }
            }
        }
        assert!(nonzero > 20);
    }

    #[test]
    fn contour_rays_land_on_weighted_pixels_and_uniform_ones_anywhere() {
        let cams = [
            Camera::from_angles(2.732, 0.0, 0.0),
            Camera::from_angles(2.732, 30.0, 90.0),
        ];
        let t = sphere_silhouettes(&cams, 24, 20, 0.4).unwrap();
        let (w, _) = cpu::contour_weights(&t, 1.0).unwrap();
        let rays = cpu::sample_rays(&t, &w, 200, 50, 1234);
        assert_eq!(rays.len(), 400);
        for (i, r) in rays.iter().enumerate() {
            let (col, row) = (r.px.floor() as usize, r.py.floor() as usize);
            assert!(col < 24 && row < 20);
            assert_eq!(r.view as usize, i / 200);
            let p = r.view as usize * 480 + row * 24 + col;
            assert_eq!(r.label, t.masks[p]);
            if i % 200 >= 50 {
                assert!(w[p] > 0, "contour ray {i} on a zero-weight pixel");
            }
        }
    }
}
