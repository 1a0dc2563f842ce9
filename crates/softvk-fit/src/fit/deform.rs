//! SoftRas's deformation parameterization (`demo_deform.py`): vertex positions from a per-vertex
//! displacement and a centre, both unconstrained, through sigmoid and tanh so every vertex stays
//! inside the (−1, 1) cube. With the template t (each coordinate in (−1, 1), nonzero):
//!
//! ```text
//! base = log(|t| / (1 − |t|)); c = tanh(center)
//! v = sigmoid(base + displace) · sign(t)
//! v = relu(v) (1 − c) − relu(−v) (c + 1) + c
//! ```
//!
//! Zero parameters give back the template. SoftRas's demo scales its template sphere by 0.5
//! first; that is the caller's choice here.
//!
//! **Parameter layout**: one buffer of `3 V + 3` floats, the displacements (3 per vertex, as the
//! positions) then the centre — one tensor for [`super::Adam`], which is elementwise, so this
//! equals SoftRas's two parameter groups at the same learning rate.
//!
//! `base` and `sign(t)` are computed once on the host in f64 and uploaded as `f32`. Kernels:
//! `deform_forward.comp`; `deform_backward.comp` then `fit_sum.comp` for the centre's gradient,
//! a sum over the vertices in a fixed order.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::gpu::{check_binding, check_floats, groups};
use crate::primitives::sum::{Sum, SumPush};
use crate::specs;

/// Push constants of `deform_forward.comp` and `deform_backward.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DeformPush {
    vertex_count: u32,
}

/// The deformation on the GPU for one template.
pub struct Deform {
    forward: Arc<Kernel>,
    backward: Arc<Kernel>,
    sum: Sum,
    vertex_count: u32,
    base: Buffer,
    signs: Buffer,
    partials: Buffer,
}

impl Deform {
    /// Pipelines and the template's `base`/`sign` buffers. Every template coordinate must be
    /// finite, nonzero and inside (−1, 1), else [`Error::Input`].
    pub fn new(ctx: &Context, template: &[[f32; 3]]) -> Result<Self> {
        let (base, signs) = cpu::template_terms(template)?;
        let vertex_count = u32::try_from(template.len())
            .map_err(|_| Error::Limit("the template has more than 2^32 vertices".into()))?;
        check_binding(
            ctx,
            "the deformation's parameters",
            4 * (3 * base.len() as u64 + 3),
        )?;
        let to_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        Ok(Self {
            forward: ctx.kernel(&specs::DEFORM_FORWARD, &[])?,
            backward: ctx.kernel(&specs::DEFORM_BACKWARD, &[])?,
            sum: Sum::new(ctx)?,
            vertex_count,
            base: ctx.upload_buffer("deform base", &to_f32(&base))?,
            signs: ctx.upload_buffer("deform signs", &to_f32(&signs))?,
            partials: ctx.create_buffer(
                "deform centre partials",
                12 * u64::from(vertex_count),
                MemoryKind::Device,
            )?,
        })
    }

    /// Template vertices.
    pub fn vertex_count(&self) -> u32 {
        self.vertex_count
    }

    /// Floats of the parameter buffer: `3 V` displacements, then the centre.
    pub fn param_count(&self) -> u64 {
        3 * u64::from(self.vertex_count) + 3
    }

    /// Records params (`3 V + 3` floats) → positions (`3 V` floats).
    pub fn record_forward(
        &self,
        rec: &mut Recorder<'_>,
        params: BufferRange<'_>,
        positions: BufferRange<'_>,
    ) -> Result<()> {
        let n = 3 * u64::from(self.vertex_count);
        check_floats("deform: params", &params, n + 3)?;
        check_floats("deform: positions", &positions, n)?;
        rec.dispatch(
            &self.forward,
            &specs::DeformForwardBindings {
                params: params.sub(0, 4 * (n + 3)),
                base: self.base.whole(),
                signs: self.signs.whole(),
                positions: positions.sub(0, 4 * n),
            }
            .for_kernel(&self.forward)?,
            &DeformPush {
                vertex_count: self.vertex_count,
            },
            groups(u64::from(self.vertex_count), 64)?,
        )
    }

    /// Records the backward at `params`: dL/d(positions) (`3 V` floats) → dL/d(params)
    /// (`3 V + 3` floats, overwritten).
    pub fn record_backward(
        &self,
        rec: &mut Recorder<'_>,
        params: BufferRange<'_>,
        d_positions: BufferRange<'_>,
        d_params: BufferRange<'_>,
    ) -> Result<()> {
        let n = 3 * u64::from(self.vertex_count);
        check_floats("deform: params", &params, n + 3)?;
        check_floats("deform: d_positions", &d_positions, n)?;
        check_floats("deform: d_params", &d_params, n + 3)?;
        let d_params = d_params.sub(0, 4 * (n + 3));
        rec.dispatch(
            &self.backward,
            &specs::DeformBackwardBindings {
                params: params.sub(0, 4 * (n + 3)),
                base: self.base.whole(),
                signs: self.signs.whole(),
                d_positions: d_positions.sub(0, 4 * n),
                d_params,
                partials: self.partials.whole(),
            }
            .for_kernel(&self.backward)?,
            &DeformPush {
                vertex_count: self.vertex_count,
            },
            groups(u64::from(self.vertex_count), 64)?,
        )?;
        self.sum.record(
            rec,
            self.partials.whole(),
            d_params,
            SumPush {
                n: self.vertex_count,
                stride: 3,
                offset: 0,
                out_index: n as u32,
                scale: 1.0,
                bias: 0.0,
            },
            3,
        )
    }
}

/// CPU twin, in f64.
pub mod cpu {
    use crate::error::{Error, Result};

    /// `(base, sign)` per template coordinate; [`Error::Input`] unless every coordinate is
    /// finite, nonzero and inside (−1, 1).
    pub fn template_terms(template: &[[f32; 3]]) -> Result<(Vec<f64>, Vec<f64>)> {
        let mut base = Vec::with_capacity(3 * template.len());
        let mut signs = Vec::with_capacity(3 * template.len());
        for (i, p) in template.iter().enumerate() {
            for &t in p {
                let t = f64::from(t);
                if !(t.is_finite() && t != 0.0 && t.abs() < 1.0) {
                    return Err(Error::Input(format!(
                        "deformation template vertex {i} {p:?}: every coordinate must be \
                         nonzero and inside (-1, 1)"
                    )));
                }
                base.push((t.abs() / (1.0 - t.abs())).ln());
                signs.push(t.signum());
            }
        }
        Ok((base, signs))
    }

    fn sigmoid(x: f64) -> f64 {
        1.0 / (1.0 + (-x).exp())
    }

    fn relu(x: f64) -> f64 {
        x.max(0.0)
    }

    /// Positions (3 per vertex) from params (`3 V` displacements, then the centre).
    pub fn forward(base: &[f64], signs: &[f64], params: &[f64]) -> Vec<f64> {
        let n = base.len();
        assert_eq!(params.len(), n + 3, "3 V displacements and the centre");
        (0..n)
            .map(|o| {
                let c = params[n + o % 3].tanh();
                let v = sigmoid(base[o] + params[o]) * signs[o];
                relu(v) * (1.0 - c) - relu(-v) * (c + 1.0) + c
            })
            .collect()
    }

    /// dL/d(params) from dL/d(positions).
    pub fn backward(base: &[f64], signs: &[f64], params: &[f64], d_positions: &[f64]) -> Vec<f64> {
        let n = base.len();
        assert_eq!(params.len(), n + 3, "3 V displacements and the centre");
        assert_eq!(d_positions.len(), n, "3 per vertex");
        let mut d = vec![0.0; n + 3];
        for o in 0..n {
            let c = params[n + o % 3].tanh();
            let s = sigmoid(base[o] + params[o]);
            let v = s * signs[o];
            let g = d_positions[o];
            let dv = if v > 0.0 { 1.0 - c } else { c + 1.0 };
            d[o] = g * dv * (s * (1.0 - s)) * signs[o];
            d[n + o % 3] += g * (1.0 - v.abs()) * (1.0 - c * c);
        }
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::{Lcg, assert_grad_matches_fd, jittered_icosphere};

    #[test]
    fn push_constant_struct_matches_the_kernels_layout() {
        let size = std::mem::size_of::<DeformPush>() as u32;
        assert_eq!(size, specs::DEFORM_FORWARD.push_constant_size);
        assert_eq!(size, specs::DEFORM_BACKWARD.push_constant_size);
        assert_eq!(specs::DEFORM_BACKWARD.bindings.len(), 6);
    }

    fn template() -> Vec<[f32; 3]> {
        let (x, _) = jittered_icosphere(0, 0.05, 9);
        // SoftRas's demo halves its template; nudge exact zeros off the axes.
        x.chunks(3)
            .map(|p| {
                let f = |v: f64| (if v == 0.0 { 0.01 } else { 0.5 * v }) as f32;
                [f(p[0]), f(p[1]), f(p[2])]
            })
            .collect()
    }

    #[test]
    fn zero_params_give_back_the_template() {
        let t = template();
        let (base, signs) = cpu::template_terms(&t).unwrap();
        let out = cpu::forward(&base, &signs, &vec![0.0; base.len() + 3]);
        for (o, &x) in out.iter().zip(t.iter().flatten()) {
            assert!((o - f64::from(x)).abs() < 1e-12, "{o} vs {x}");
        }
    }

    #[test]
    fn deform_twin_gradient_matches_central_differences() {
        let t = template();
        let (base, signs) = cpu::template_terms(&t).unwrap();
        let mut rng = Lcg(4);
        let params: Vec<f64> = (0..base.len() + 3).map(|_| rng.range(-0.8, 0.8)).collect();
        let weights: Vec<f64> = (0..base.len()).map(|_| rng.range(-1.0, 1.0)).collect();
        // L = Σ w ⊙ positions, so dL/d(positions) = w.
        let grad = cpu::backward(&base, &signs, &params, &weights);
        assert_grad_matches_fd(&params, &grad, 1e-6, |p| {
            let x = cpu::forward(&base, &signs, p);
            x.iter().zip(&weights).map(|(a, b)| a * b).sum()
        });
    }

    #[test]
    fn template_outside_the_open_cube_is_an_input_error() {
        for bad in [[0.5, 0.0, 0.2], [1.0, 0.5, 0.5], [0.5, f32::NAN, 0.5]] {
            assert!(matches!(
                cpu::template_terms(&[[0.1, 0.2, 0.3], bad]),
                Err(Error::Input(m)) if m.contains("vertex 1")
            ));
        }
    }
}
