//! The geometric regularizer of SPEC §5, which favours smooth surfaces:
//!
//! ```text
//! L_geo = (1/N) Σ_j W(φ(s_j)) Σ_l W(φ(q_j^l)) ‖n(s_j) − n(q_j^l)‖_p^p / Σ_l W(φ(q_j^l))
//! ```
//!
//! over N surface candidates s_j ([`super::Sampler::candidates`]) and their six neighbours
//! `q_j^l = s_j ± δ e_axis`, with `W(x) = 1[|x − 0.5| < ε]` (a term is 0 when no neighbour is
//! in the window) and normals `n = g / max(|g|, NORMAL_EPS)`, g the central differences of φ
//! with step δ_n (their common factor 1/2δ_n cancels in the normalisation).
//!
//! 1. [`GeoRegularizer::record_points`] (`probe_geo_points.comp`) writes the points to evaluate:
//!    49 per candidate, [`POINTS_PER_CANDIDATE`]. Point `(7 j + c) 7 + k` is `q_c + δ_n e_k`
//!    with `q_0 = s_j`, `q_1..q_6 = s_j ± δ` on x, y, z and `e_0 = 0`, `e_1..e_6 = ±` x, y, z:
//!    k = 0 gives W, k = 1..6 the normal.
//! 2. The field evaluates φ at [`GeoRegularizer::points`].
//! 3. [`GeoRegularizer::record_loss`] (`probe_geo_loss.comp`, then a fixed-order sum) writes
//!    L_geo and dL_geo/dφ per point (through the normals only: W is piecewise constant; the
//!    k = 0 entries get 0), one writer per value: deterministic.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::ProbeSettings;
use crate::error::Result;
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::gpu::{GradOut, check_binding, check_floats, groups};
use crate::primitives::sum::{Sum, SumPush};
use crate::specs;

/// Points evaluated per surface candidate: 7 centres × (the centre + 6 stencil points).
pub const POINTS_PER_CANDIDATE: u32 = 49;

/// Gradients shorter than this give `n = g / NORMAL_EPS` instead of `g / |g|` (a flat φ has no
/// normal; f32 differences of φ below this are rounding anyway).
pub const NORMAL_EPS: f32 = 1e-6;

/// Push constants of `probe_geo_points.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct PointsPush {
    candidates: u32,
    delta: f32,
    delta_n: f32,
    pad: u32,
}

/// Push constants of `probe_geo_loss.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct LossPush {
    candidates: u32,
    write_grad: u32,
    accumulate: u32,
    epsilon: f32,
    p: f32,
    coef: f32,
    normal_eps: f32,
    pad: u32,
}

/// The regularizer's kernels and buffers, for [`ProbeSettings::geo_candidates`] candidates.
pub struct GeoRegularizer {
    points_kernel: Arc<Kernel>,
    loss_kernel: Arc<Kernel>,
    sum: Sum,
    settings: ProbeSettings,
    points: Buffer,
    terms: Buffer,
    loss: Buffer,
}

impl GeoRegularizer {
    /// Pipelines and buffers.
    pub fn new(ctx: &Context, settings: &ProbeSettings) -> Result<Self> {
        settings.validate()?;
        let n = u64::from(settings.geo_candidates);
        let points = n * u64::from(POINTS_PER_CANDIDATE);
        check_binding(ctx, "geometric regularizer: points", 16 * points)?;
        Ok(Self {
            points_kernel: ctx.kernel(&specs::PROBE_GEO_POINTS, &[])?,
            loss_kernel: ctx.kernel(&specs::PROBE_GEO_LOSS, &[])?,
            sum: Sum::new(ctx)?,
            settings: *settings,
            points: ctx.create_buffer("geo points", 16 * points, MemoryKind::Device)?,
            terms: ctx.create_buffer("geo terms", 4 * n, MemoryKind::Device)?,
            loss: ctx.create_buffer("geo loss", 4, MemoryKind::Device)?,
        })
    }

    fn candidates(&self) -> u64 {
        u64::from(self.settings.geo_candidates)
    }

    /// Points to evaluate φ at: `49 N`.
    pub fn point_count(&self) -> u64 {
        self.candidates() * u64::from(POINTS_PER_CANDIDATE)
    }

    /// Records the points of `candidates` (`vec4` each, N of them) into [`GeoRegularizer::points`].
    pub fn record_points(&self, rec: &mut Recorder<'_>, candidates: BufferRange<'_>) -> Result<()> {
        check_floats(
            "geometric regularizer: candidates",
            &candidates,
            4 * self.candidates(),
        )?;
        rec.dispatch(
            &self.points_kernel,
            &specs::ProbeGeoPointsBindings {
                candidates: candidates.sub(0, 16 * self.candidates()),
                points: self.points.whole(),
            }
            .for_kernel(&self.points_kernel)?,
            &PointsPush {
                candidates: self.settings.geo_candidates,
                delta: self.settings.geo_delta as f32,
                delta_n: self.settings.geo_normal_delta as f32,
                pad: 0,
            },
            groups(self.point_count(), 64)?,
        )
    }

    /// The points (`vec4` each, w = 1) of the last [`GeoRegularizer::record_points`].
    pub fn points(&self) -> &Buffer {
        &self.points
    }

    /// Records L_geo of `phi` (φ at [`GeoRegularizer::points`], one `f32` each) into
    /// [`GeoRegularizer::loss_buffer`] and, with `d_phi`, `weight · dL_geo/dφ` per point (pass
    /// λ as the weight for the `λ L_geo` term).
    pub fn record_loss(
        &self,
        rec: &mut Recorder<'_>,
        phi: BufferRange<'_>,
        d_phi: Option<GradOut<'_>>,
    ) -> Result<()> {
        let m = self.point_count();
        check_floats("geometric regularizer: φ", &phi, m)?;
        if let Some(d) = &d_phi {
            check_floats("geometric regularizer: d_phi", &d.range, m)?;
        }
        let n = self.candidates();
        let push = LossPush {
            candidates: self.settings.geo_candidates,
            write_grad: u32::from(d_phi.is_some()),
            accumulate: u32::from(d_phi.is_some_and(|d| d.accumulate)),
            epsilon: self.settings.geo_epsilon as f32,
            p: self.settings.geo_p as f32,
            coef: d_phi.map_or(0.0, |d| (f64::from(d.weight) / n as f64) as f32),
            normal_eps: NORMAL_EPS,
            pad: 0,
        };
        // Without a gradient, the kernel writes none; any bound range will do.
        let d_range = d_phi.map_or(self.terms.whole(), |d| d.range.sub(0, 4 * m));
        rec.dispatch(
            &self.loss_kernel,
            &specs::ProbeGeoLossBindings {
                phi: phi.sub(0, 4 * m),
                terms: self.terms.whole(),
                d_phi: d_range,
            }
            .for_kernel(&self.loss_kernel)?,
            &push,
            groups(n, 64)?,
        )?;
        self.sum.record(
            rec,
            self.terms.whole(),
            self.loss.whole(),
            SumPush {
                n: self.settings.geo_candidates,
                stride: 1,
                offset: 0,
                out_index: 0,
                scale: (1.0 / n as f64) as f32,
                bias: 0.0,
            },
            1,
        )
    }

    /// One `f32`: L_geo of the last [`GeoRegularizer::record_loss`] (without λ).
    pub fn loss_buffer(&self) -> &Buffer {
        &self.loss
    }

    /// Reads L_geo back.
    pub fn read_loss(&self, ctx: &Context) -> Result<f32> {
        Ok(ctx.read_buffer::<f32>(&self.loss, 0, 1)?[0])
    }

    /// The per-candidate terms of the last loss.
    pub fn terms(&self) -> &Buffer {
        &self.terms
    }
}

/// CPU twins.
pub mod cpu {
    use super::{NORMAL_EPS, POINTS_PER_CANDIDATE};
    use crate::probe::ProbeSettings;

    fn offset(k: usize, step: f32) -> [f32; 3] {
        let mut r = [0.0; 3];
        if k > 0 {
            r[(k - 1) / 2] = if k % 2 == 1 { step } else { -step };
        }
        r
    }

    /// `probe_geo_points.comp`: the 49 points of every candidate.
    pub fn points(candidates: &[[f32; 4]], delta: f64, delta_n: f64) -> Vec<[f32; 4]> {
        let (delta, delta_n) = (delta as f32, delta_n as f32);
        let mut out = Vec::with_capacity(candidates.len() * POINTS_PER_CANDIDATE as usize);
        for s in candidates {
            for c in 0..7 {
                let oc = offset(c, delta);
                let q = [s[0] + oc[0], s[1] + oc[1], s[2] + oc[2]];
                for k in 0..7 {
                    let ok = offset(k, delta_n);
                    out.push([q[0] + ok[0], q[1] + ok[1], q[2] + ok[2], 1.0]);
                }
            }
        }
        out
    }

    /// L_geo of φ at the points of N candidates (`49 N` values) and dL_geo/dφ per point.
    pub fn loss(settings: &ProbeSettings, phi: &[f64]) -> (f64, Vec<f64>) {
        let per = POINTS_PER_CANDIDATE as usize;
        assert_eq!(phi.len() % per, 0, "49 values per candidate");
        let n = phi.len() / per;
        let (eps, p) = (settings.geo_epsilon, settings.geo_p);
        let neps = f64::from(NORMAL_EPS);
        let powp = |x: f64| if x == 0.0 { 0.0 } else { x.abs().powf(p) };
        let dpow = |x: f64| {
            if x == 0.0 {
                0.0
            } else {
                p * x.abs().powf(p - 1.0) * x.signum()
            }
        };
        let mut total = 0.0;
        let mut grad = vec![0.0; phi.len()];
        for j in 0..n {
            let f = &phi[j * per..(j + 1) * per];
            let mut g = [[0.0; 3]; 7];
            let mut len = [0.0; 7];
            let mut nrm = [[0.0; 3]; 7];
            let mut w = [false; 7];
            for c in 0..7 {
                let b = 7 * c;
                g[c] = [
                    f[b + 1] - f[b + 2],
                    f[b + 3] - f[b + 4],
                    f[b + 5] - f[b + 6],
                ];
                len[c] = (g[c][0] * g[c][0] + g[c][1] * g[c][1] + g[c][2] * g[c][2]).sqrt();
                let l = len[c].max(neps);
                nrm[c] = g[c].map(|x| x / l);
                w[c] = (f[b] - 0.5).abs() < eps;
            }
            let denom = (1..7).filter(|&l| w[l]).count() as f64;
            if !(w[0] && denom > 0.0) {
                continue;
            }
            let mut term = 0.0;
            let mut dn = [[0.0; 3]; 7];
            for l in (1..7).filter(|&l| w[l]) {
                for a in 0..3 {
                    let diff = nrm[0][a] - nrm[l][a];
                    term += powp(diff);
                    let gd = dpow(diff) / denom;
                    dn[0][a] += gd;
                    dn[l][a] -= gd;
                }
            }
            total += term / denom;
            for c in 0..7 {
                let dot: f64 = (0..3).map(|a| nrm[c][a] * dn[c][a]).sum();
                let dg: [f64; 3] = if len[c] > neps {
                    [0, 1, 2].map(|a| (dn[c][a] - nrm[c][a] * dot) / len[c])
                } else {
                    dn[c].map(|x| x / neps)
                };
                let b = j * per + 7 * c;
                for a in 0..3 {
                    grad[b + 1 + 2 * a] += dg[a] / n as f64;
                    grad[b + 2 + 2 * a] -= dg[a] / n as f64;
                }
            }
        }
        (total / n as f64, grad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use softvk_testing::{Lcg, assert_grad_matches_fd};

    #[test]
    fn push_layouts_match_the_kernels() {
        assert_eq!(
            std::mem::size_of::<PointsPush>() as u32,
            specs::PROBE_GEO_POINTS.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<LossPush>() as u32,
            specs::PROBE_GEO_LOSS.push_constant_size
        );
    }

    #[test]
    fn points_follow_the_documented_layout() {
        let pts = cpu::points(&[[0.5, -0.25, 0.125, 1.0]], 0.25, 0.125);
        assert_eq!(pts.len(), 49);
        assert_eq!(pts[0], [0.5, -0.25, 0.125, 1.0]);
        // Centre 3 (+y neighbour), stencil point 6 (−z).
        assert_eq!(pts[3 * 7 + 6], [0.5, 0.0, 0.0, 1.0]);
        // Centre 2 (−x), stencil point 1 (+x).
        assert_eq!(pts[2 * 7 + 1], [0.375, -0.25, 0.125, 1.0]);
    }

    /// φ of a noisy sphere of radius 0.5 at the points of `n` candidates near its surface.
    fn noisy_sphere_phi(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = Lcg(seed);
        let cands: Vec<[f32; 4]> = (0..n)
            .map(|_| {
                let d = [
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                ];
                let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let r = 0.5 + rng.range(-0.03, 0.03);
                [
                    (d[0] / l * r) as f32,
                    (d[1] / l * r) as f32,
                    (d[2] / l * r) as f32,
                    1.0,
                ]
            })
            .collect();
        cpu::points(&cands, 0.0625, 0.03125)
            .iter()
            .map(|p| {
                let r =
                    (f64::from(p[0]).powi(2) + f64::from(p[1]).powi(2) + f64::from(p[2]).powi(2))
                        .sqrt();
                let bump = 0.3 * (7.0 * f64::from(p[0])).sin() * (5.0 * f64::from(p[1])).cos();
                1.0 / (1.0 + (-(0.5 - r) * 20.0 - bump).exp())
            })
            .collect()
    }

    #[test]
    fn geo_twin_gradient_matches_central_differences() {
        for p in [2.0, 1.5, 1.0] {
            let settings = ProbeSettings {
                geo_p: p,
                geo_epsilon: 0.25,
                ..ProbeSettings::default()
            };
            let phi = noisy_sphere_phi(12, 5);
            let (loss, grad) = cpu::loss(&settings, &phi);
            assert!(loss > 0.0, "p = {p}: a loss of 0 checks nothing");
            // FD steps of 1e-6 do not cross W's window edges here (φ is 1e-3 away from them).
            for &x in phi.iter().step_by(7) {
                assert!(((x - 0.5).abs() - 0.25).abs() > 1e-5);
            }
            assert_grad_matches_fd(&phi, &grad, 1e-5, |x| cpu::loss(&settings, x).0);
        }
    }
}
