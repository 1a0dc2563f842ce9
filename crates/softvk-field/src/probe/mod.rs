//! Implicit-field sphere probing (SPEC §5; Liu et al., "Learning to Infer Implicit Surfaces
//! without 3D Supervision", NeurIPS 2019): sampling, probing and the losses, as kernels with CPU
//! twins. The field itself (grid or MLP, its evaluation and backward) lives elsewhere; the two
//! meet only through **points and φ**:
//!
//! - points: a buffer of `vec4` per point (`x, y, z, 1`; only xyz is read), written here;
//! - φ: one `f32` per point, in (0, 1), written by the field's evaluation;
//! - dL/dφ: one `f32` per point, written here, read by the field's backward.
//!
//! The stages, each a module:
//! - [`targets`]: the silhouettes and cameras ([`Targets`] on the host, [`GpuTargets`] uploaded);
//!   every camera becomes a [`ProbeView`]: its projective map and the line of each screen point.
//! - [`hull`]: the visual hull's boundary points (CPU, once), which anchor sampling uses.
//! - [`sampler`]: fresh every iteration, reproducible from (seed, iteration): the probing rays
//!   (part uniform, part importance-sampled from the silhouette contour), the anchors (part
//!   uniform in the cube, part Gaussian around visual-hull boundary points) and the
//!   regularizer's surface candidates ([`Sampler`]).
//! - [`prober`]: anchors → per-view screen boxes → the generic tile binning
//!   ([`crate::primitives::binning`]) → ψ per ray → `L_sil` → dL_sil/dφ per anchor ([`Prober`]).
//! - [`geo`]: the geometric regularizer `L_geo` and its dL/dφ ([`GeoRegularizer`]).
//! - [`rng`]: the counter-based hash the sampler draws from.
//! - [`dense`]: the dense-marching baseline (every ray sampled at voxel steps), for the
//!   throughput comparison.
//!
//! **One iteration** of a field fit, as the glue (`fit-field`) records it: one command buffer,
//! no read-back (the binning's entry count stays on the GPU, checked by an
//! [`IterationGate`](crate::gpu::gate::IterationGate) against the capacity of
//! [`Prober::reserve_guarded`]), `log_every` iterations per submission:
//!
//! ```text
//! sampler.record(rec, &gpu_targets, iteration)          → rays, anchors, candidates
//! geo.record_points(rec, sampler.candidates().whole())  → geo.points() (49 per candidate)
//! prober.record_guarded(rec, &mut gate, iteration, &gpu_targets, anchors, |rec| {
//!                                                       (anchor items, count, gate; then gated:)
//!   field: φ_a = φ(anchors), φ_g = φ(geo.points())
//!   prober.record_forward(rec, &gpu_targets, anchors, φ_a, rays)     → ψ, L_sil
//!   prober.record_backward(rec, &gpu_targets, anchors, φ_a, rays,
//!                          GradOut::write(d_φ_a))                    → dL_sil/dφ_a
//!   geo.record_loss(rec, φ_g, Some(GradOut::write(d_φ_g).weighted(λ))) → L_geo, λ dL_geo/dφ_g
//!   field backward of (anchors, d_φ_a) and (geo points, d_φ_g); optimizer step
//! })
//! ```
//!
//! ([`Prober::run`] is the exact two-submission path, with the count read back: tests, tools.)
//!
//! `L = L_sil + λ L_geo` ([`ProbeSettings::total_loss`]); the losses stay on the GPU in one-float
//! buffers ([`Prober::loss_buffer`], [`GeoRegularizer::loss_buffer`]) until read.
//!
//! **Conventions.** Every kernel has an f64 CPU twin (`cpu` submodules). Discrete decisions
//! (pixels, hits, tiles) are made in f32 with `precise` arithmetic on the GPU and the same f32
//! operations in the twins, so they agree exactly; values are compared within tolerances. The
//! backward uses no float atomics: per (anchor, tile) partial sums over the tile's rays in ray
//! order, then a per-anchor sum in a fixed order, so repeated runs are bit-identical. Every loop
//! whose length depends on the input is bounded on the host against the driver's loop cap
//! ([`crate::gpu::DeviceInfo::shader_loop_limit`]), never a silently truncated loop: a tile's
//! (or brute force's) anchor list too long for one invocation is folded in passes, each ray's
//! aggregate carried between them (the same bits as one pass); more rays per view than the
//! backward may loop over, or over two million anchors (a tile mask's words), is an
//! [`Error::DeviceLimit`].

pub mod dense;
pub mod geo;
pub mod hull;
pub mod prober;
pub mod rng;
pub mod sampler;
pub mod targets;

pub use geo::GeoRegularizer;
pub use prober::Prober;
pub use sampler::Sampler;
pub use targets::{GpuTargets, ProbeView, Targets};

use crate::error::{Error, Result};

/// How a ray's value ψ combines the φ of the anchors it hits (SPEC §5). No hit: ψ = 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Aggregate {
    /// `ψ = max φ` (the paper). Its gradient goes to the maximizing anchor alone (the first in
    /// anchor order on a tie).
    #[default]
    Max,
    /// `ψ = T log Σ exp(φ / T)` with temperature T ([`ProbeSettings::temperature`]), computed
    /// with a running maximum. Not normalised by the hit count: `max φ ≤ ψ ≤ max φ + T ln n` for
    /// n hits, so ψ can exceed 1 by up to `T ln n` (small T keeps it near the max; normalising by
    /// n would let empty anchors dilute a ray that hits the surface). dψ/dφ_j is the softmax
    /// weight `exp((φ_j − ψ) / T)`.
    LogSumExp,
    /// `ψ = 1 − Π (1 − φ)`: the probability that some hit anchor is occupied, for independent
    /// anchors. dψ/dφ_j = Π over the other hits of (1 − φ).
    Union,
}

impl Aggregate {
    /// The `AGG_*` code of the kernels.
    pub(crate) fn code(self) -> u32 {
        match self {
            Aggregate::Max => 0,
            Aggregate::LogSumExp => 1,
            Aggregate::Union => 2,
        }
    }
}

/// Every parameter of sphere probing. Lengths are in world units and the defaults are for the
/// default cube [-1, 1]³ (scale them with the cube); they are sensible starting points, to be
/// tuned by measurement once the field fit exists.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeSettings {
    /// Centre of the bounding cube the field lives in (default the origin).
    pub cube_center: [f64; 3],
    /// Half the cube's edge (default 1: the cube [-1, 1]³).
    pub cube_half: f64,

    /// N_r, probing rays per view per iteration (default 1024).
    pub rays_per_view: u32,
    /// Fraction of each view's rays sampled uniformly over the image; the rest follow the
    /// contour density (default 0.25).
    pub ray_uniform_fraction: f64,
    /// σ_c, in pixels, of the Gaussian that smooths the silhouette's Laplacian into the contour
    /// density (default 2; 0 for the raw Laplacian).
    pub contour_sigma: f64,

    /// N_a, anchors per iteration (default 8192).
    pub anchors: u32,
    /// Fraction of the anchors uniform in the cube; the rest are near the visual hull's boundary
    /// (default 0.25).
    pub anchor_uniform_fraction: f64,
    /// σ_a, the standard deviation of the Gaussian around a visual-hull boundary point (default
    /// 0.04, a little over one hull voxel at the default resolution).
    pub anchor_sigma: f64,
    /// V, lattice points per cube edge of the visual hull whose boundary anchors are drawn
    /// around (default 64).
    pub hull_resolution: u32,

    /// τ, the anchor spheres' radius (default 0.03: a bit over 0.027, the half-diagonal of a
    /// voxel of a 64³ grid over the default cube).
    pub tau: f64,
    /// The radius for the rays outside the silhouettes, when it differs from τ (default `None`:
    /// τ for every ray). Under boundary-aware assignment the two kinds of rays use disjoint
    /// anchors, so each kind may have its own radius: a larger one outside lets each outside ray
    /// carve more next to the contour without widening an inside ray's tube. Measured on thin
    /// shapes (`RESULTS.md`, "Thin structures", "Where the fit loses to the hull"), it thins the
    /// rim a fit leaves around flat parts but also erodes sub-pixel ones; no default uses it.
    pub tau_outside: Option<f64>,
    /// G, how a ray combines its hits (default [`Aggregate::Max`]).
    pub aggregate: Aggregate,
    /// T, the log-sum-exp temperature (default 0.05; only for [`Aggregate::LogSumExp`]).
    pub temperature: f64,
    /// Boundary-aware assignment: a ray inside (outside) its silhouette ignores anchors whose
    /// centre projects outside (inside) it in that view (default on).
    pub boundary_aware: bool,
    /// Screen tile edge, in pixels, of the anchor binning (default 16).
    pub tile_size: u32,

    /// N, surface candidates s_j of the geometric regularizer per iteration (default 2048).
    pub geo_candidates: u32,
    /// Fraction of the candidates uniform in the cube (the rest like the near-hull anchors, with
    /// σ_a; default 0.25).
    pub geo_uniform_fraction: f64,
    /// δ, the offset of a candidate's six neighbours q_j^l (default 0.0625, two voxels of 64³).
    pub geo_delta: f64,
    /// δ_n, the central-difference step of the normals (default 0.03125, one voxel of 64³).
    pub geo_normal_delta: f64,
    /// ε, the half-width of the surface window `W(x) = 1[|x − 0.5| < ε]` (default 0.2).
    pub geo_epsilon: f64,
    /// p, the exponent of the normal-difference norm ‖·‖_p^p, ≥ 1 (default 2).
    pub geo_p: f64,
    /// λ, the weight of L_geo in `L = L_sil + λ L_geo` (default 0.1).
    pub geo_lambda: f64,

    /// The seed of every random stream (default 0).
    pub seed: u64,
}

impl Default for ProbeSettings {
    fn default() -> Self {
        Self {
            cube_center: [0.0; 3],
            cube_half: 1.0,
            rays_per_view: 1024,
            ray_uniform_fraction: 0.25,
            contour_sigma: 2.0,
            anchors: 8192,
            anchor_uniform_fraction: 0.25,
            anchor_sigma: 0.04,
            hull_resolution: 64,
            tau: 0.03,
            tau_outside: None,
            aggregate: Aggregate::Max,
            temperature: 0.05,
            boundary_aware: true,
            tile_size: 16,
            geo_candidates: 2048,
            geo_uniform_fraction: 0.25,
            geo_delta: 0.0625,
            geo_normal_delta: 0.03125,
            geo_epsilon: 0.2,
            geo_p: 2.0,
            geo_lambda: 0.1,
            seed: 0,
        }
    }
}

/// Counts above this would overflow the samplers' `index · 8 + draw` counters.
pub const MAX_SAMPLES: u32 = 1 << 28;

impl ProbeSettings {
    /// [`Error::Input`] naming the first parameter out of range.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str, value: String, need: &str| {
            Err(Error::Input(format!(
                "sphere probing: {what} = {value}; it must be {need}"
            )))
        };
        let pos = |x: f64| x.is_finite() && x > 0.0;
        let frac = |x: f64| (0.0..=1.0).contains(&x);
        if !self.cube_center.iter().all(|c| c.is_finite()) {
            return bad("cube_center", format!("{:?}", self.cube_center), "finite");
        }
        if !pos(self.cube_half) {
            return bad("cube_half", self.cube_half.to_string(), "positive");
        }
        for (what, n) in [
            ("rays_per_view", self.rays_per_view),
            ("anchors", self.anchors),
            ("geo_candidates", self.geo_candidates),
        ] {
            if n == 0 || n > MAX_SAMPLES {
                return bad(what, n.to_string(), &format!("between 1 and {MAX_SAMPLES}"));
            }
        }
        for (what, x) in [
            ("ray_uniform_fraction", self.ray_uniform_fraction),
            ("anchor_uniform_fraction", self.anchor_uniform_fraction),
            ("geo_uniform_fraction", self.geo_uniform_fraction),
        ] {
            if !frac(x) {
                return bad(what, x.to_string(), "in [0, 1]");
            }
        }
        for (what, x) in [
            ("contour_sigma", self.contour_sigma),
            ("anchor_sigma", self.anchor_sigma),
            ("geo_lambda", self.geo_lambda),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return bad(what, x.to_string(), "finite and >= 0");
            }
        }
        if self.contour_sigma > 64.0 {
            return bad(
                "contour_sigma",
                self.contour_sigma.to_string(),
                "at most 64 pixels",
            );
        }
        for (what, x) in [
            ("tau", self.tau),
            ("tau_outside", self.tau_outside.unwrap_or(self.tau)),
            ("temperature", self.temperature),
            ("geo_delta", self.geo_delta),
            ("geo_normal_delta", self.geo_normal_delta),
        ] {
            if !pos(x) {
                return bad(what, x.to_string(), "positive");
            }
        }
        if !(2..=1024).contains(&self.hull_resolution) {
            return bad(
                "hull_resolution",
                self.hull_resolution.to_string(),
                "between 2 and 1024",
            );
        }
        if !(1..=1024).contains(&self.tile_size) {
            return bad(
                "tile_size",
                self.tile_size.to_string(),
                "between 1 and 1024",
            );
        }
        if !(self.geo_epsilon > 0.0 && self.geo_epsilon <= 0.5) {
            return bad("geo_epsilon", self.geo_epsilon.to_string(), "in (0, 0.5]");
        }
        if !(self.geo_p.is_finite() && self.geo_p >= 1.0) {
            return bad("geo_p", self.geo_p.to_string(), "finite and >= 1");
        }
        let margin = self.geo_delta + self.geo_normal_delta;
        if margin >= self.cube_half {
            return bad(
                "geo_delta + geo_normal_delta",
                margin.to_string(),
                "less than cube_half (the stencils must fit in the cube)",
            );
        }
        Ok(())
    }

    /// The cube's lower corner.
    pub fn cube_min(&self) -> [f64; 3] {
        self.cube_center.map(|c| c - self.cube_half)
    }

    /// The cube's upper corner.
    pub fn cube_max(&self) -> [f64; 3] {
        self.cube_center.map(|c| c + self.cube_half)
    }

    /// `L = L_sil + λ L_geo`.
    pub fn total_loss(&self, l_sil: f64, l_geo: f64) -> f64 {
        l_sil + self.geo_lambda * l_geo
    }

    /// `round(n · fraction)`: how many of n samples are uniform.
    pub(crate) fn uniform_count(n: u32, fraction: f64) -> u32 {
        ((f64::from(n) * fraction).round() as u32).min(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_settings_are_valid_and_tau_covers_a_64_voxel() {
        let s = ProbeSettings::default();
        s.validate().unwrap();
        let voxel = 2.0 * s.cube_half / 64.0;
        assert!(s.tau > voxel * 3f64.sqrt() / 2.0 && s.tau < voxel);
    }

    #[test]
    fn out_of_range_settings_are_input_errors() {
        let d = ProbeSettings::default();
        let cases = [
            ProbeSettings { tau: 0.0, ..d },
            ProbeSettings { anchors: 0, ..d },
            ProbeSettings {
                ray_uniform_fraction: 1.5,
                ..d
            },
            ProbeSettings { geo_p: 0.5, ..d },
            ProbeSettings {
                geo_epsilon: 0.0,
                ..d
            },
            ProbeSettings {
                temperature: f64::NAN,
                ..d
            },
            ProbeSettings {
                geo_delta: 1.0,
                ..d
            },
            ProbeSettings {
                hull_resolution: 1,
                ..d
            },
        ];
        for s in cases {
            let e = s.validate();
            assert!(matches!(e, Err(Error::Input(_))), "{s:?}");
        }
    }
}
