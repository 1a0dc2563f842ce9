//! Adam with PyTorch's semantics (`torch.optim.Adam`: bias-corrected, no weight decay, no
//! amsgrad), updating parameters and both moments in place (`adam.glsl`: `adam_step4.comp` on
//! whole texels of four parameters, `adam_step.comp` on the rest):
//!
//! ```text
//! m ← lerp(m, g, 1 − β1); v ← β2 v + (1 − β2) g²
//! p ← p − lr / (1 − β1^t) · m / (sqrt(v) / sqrt(1 − β2^t) + eps)
//! ```
//!
//! The step number t (from 1) is given at record time; the bias corrections are computed on the
//! host in f64, as PyTorch computes them in Python floats.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, Recorder};
use crate::gpu::{check_binding, check_floats, groups};
use crate::specs;

/// Adam's hyper-parameters; the default is PyTorch's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamOptions {
    /// Learning rate (PyTorch: 1e-3; SoftRas's deformation demo: 0.01).
    pub lr: f64,
    /// β1, β2 (PyTorch: 0.9, 0.999; SoftRas's demo: 0.5, 0.99).
    pub betas: (f64, f64),
    /// Added to the denominator (1e-8).
    pub eps: f64,
}

impl Default for AdamOptions {
    fn default() -> Self {
        Self {
            lr: 1e-3,
            betas: (0.9, 0.999),
            eps: 1e-8,
        }
    }
}

impl AdamOptions {
    /// [`Error::Input`] unless `lr ≥ 0`, `0 ≤ β < 1` and `eps ≥ 0`, all finite (PyTorch's checks).
    pub fn validate(&self) -> Result<()> {
        let (b1, b2) = self.betas;
        let ok = |x: f64| x.is_finite() && x >= 0.0;
        if !(ok(self.lr) && ok(self.eps) && ok(b1) && ok(b2) && b1 < 1.0 && b2 < 1.0) {
            return Err(Error::Input(format!(
                "Adam options {self:?}: need lr >= 0, eps >= 0 and 0 <= beta < 1"
            )));
        }
        Ok(())
    }
}

/// Push constants of `adam_step.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct AdamPush {
    n: u32,
    lerp_weight: f32,
    beta2: f32,
    one_minus_beta2: f32,
    step_size: f32,
    bias2_sqrt: f32,
    eps: f32,
    first: u32,
}

impl AdamPush {
    fn new(n: u32, first: u32, o: &AdamOptions, step: u32) -> Self {
        let (b1, b2) = o.betas;
        let t = f64::from(step);
        Self {
            n,
            lerp_weight: (1.0 - b1) as f32,
            beta2: b2 as f32,
            one_minus_beta2: (1.0 - b2) as f32,
            step_size: (o.lr / (1.0 - b1.powf(t))) as f32,
            bias2_sqrt: (1.0 - b2.powf(t)).sqrt() as f32,
            eps: o.eps as f32,
            first,
        }
    }
}

/// Adam over `n` parameters on the GPU: the kernels (whole texels of four parameters, and the
/// rest one by one) and the two moment buffers.
pub struct Adam {
    kernel: Arc<Kernel>,
    kernel4: Arc<Kernel>,
    n: u32,
    options: AdamOptions,
    m: Buffer,
    v: Buffer,
}

impl Adam {
    /// The optimizer for `n` parameters, its moments zero.
    pub fn new(ctx: &Context, n: u64, options: AdamOptions) -> Result<Self> {
        options.validate()?;
        check_binding(ctx, "Adam's parameters", 4 * n)?;
        let zeros = vec![0f32; n as usize];
        Ok(Self {
            kernel: ctx.kernel(&specs::ADAM_STEP, &[])?,
            kernel4: ctx.kernel(&specs::ADAM_STEP4, &[])?,
            n: n as u32, // < maxStorageBufferRange / 4
            options,
            m: ctx.upload_buffer("adam first moment", &zeros)?,
            v: ctx.upload_buffer("adam second moment", &zeros)?,
        })
    }

    /// The hyper-parameters.
    pub fn options(&self) -> &AdamOptions {
        &self.options
    }

    /// Changes the hyper-parameters for later steps (a learning-rate schedule, say).
    pub fn set_options(&mut self, options: AdamOptions) -> Result<()> {
        options.validate()?;
        self.options = options;
        Ok(())
    }

    /// Parameters served.
    pub fn len(&self) -> u64 {
        u64::from(self.n)
    }

    /// True for an optimizer of no parameters.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The first and second moments (`n` floats each).
    pub fn moments(&self) -> (&Buffer, &Buffer) {
        (&self.m, &self.v)
    }

    /// Records step `step` (1 for the first, as PyTorch counts): updates `params` and the
    /// moments in place from `grads` (`n` floats each).
    pub fn record_step(
        &self,
        rec: &mut Recorder<'_>,
        params: BufferRange<'_>,
        grads: BufferRange<'_>,
        step: u32,
    ) -> Result<()> {
        self.record_step_lr(rec, params, grads, step, self.options.lr)
    }

    /// [`Adam::record_step`] at learning rate `lr` instead of the options' (a schedule's
    /// value for this step).
    pub fn record_step_lr(
        &self,
        rec: &mut Recorder<'_>,
        params: BufferRange<'_>,
        grads: BufferRange<'_>,
        step: u32,
        lr: f64,
    ) -> Result<()> {
        let options = AdamOptions { lr, ..self.options };
        options.validate()?;
        if step == 0 {
            return Err(Error::Input(
                "Adam steps count from 1 (the bias corrections divide by 1 − β^t)".into(),
            ));
        }
        let n = u64::from(self.n);
        check_floats("Adam: params", &params, n)?;
        check_floats("Adam: grads", &grads, n)?;
        if n == 0 {
            return Ok(());
        }
        // Parameters 0 .. 4 t as t texels of four, the rest one by one.
        let texels = n / 4;
        if texels > 0 {
            let bytes = 16 * texels;
            rec.dispatch(
                &self.kernel4,
                &specs::AdamStep4Bindings {
                    params: params.sub(0, bytes),
                    grads: grads.sub(0, bytes),
                    first_moment: self.m.range(0, bytes),
                    second_moment: self.v.range(0, bytes),
                }
                .for_kernel(&self.kernel4)?,
                &AdamPush::new(texels as u32, 0, &options, step),
                groups(texels, 64)?,
            )?;
        }
        let first = 4 * texels;
        if first < n {
            rec.dispatch(
                &self.kernel,
                &specs::AdamStepBindings {
                    params: params.sub(0, 4 * n),
                    grads: grads.sub(0, 4 * n),
                    first_moment: self.m.whole(),
                    second_moment: self.v.whole(),
                }
                .for_kernel(&self.kernel)?,
                &AdamPush::new(self.n, first as u32, &options, step),
                groups(n - first, 64)?,
            )?;
        }
        Ok(())
    }

    /// Records zeroing both moments (to restart the optimization; the next step is 1 again).
    pub fn record_reset(&self, rec: &mut Recorder<'_>) {
        rec.fill(self.m.whole(), 0);
        rec.fill(self.v.whole(), 0);
    }
}

/// CPU twin, in f64.
pub mod cpu {
    use super::AdamOptions;

    /// One step `step` (from 1), in place, as PyTorch's single-tensor Adam.
    pub fn step(
        params: &mut [f64],
        grads: &[f64],
        m: &mut [f64],
        v: &mut [f64],
        step: u32,
        o: &AdamOptions,
    ) {
        let (b1, b2) = o.betas;
        let t = f64::from(step);
        let step_size = o.lr / (1.0 - b1.powf(t));
        let bias2_sqrt = (1.0 - b2.powf(t)).sqrt();
        for i in 0..params.len() {
            let g = grads[i];
            m[i] += (1.0 - b1) * (g - m[i]);
            v[i] = v[i] * b2 + (1.0 - b2) * g * g;
            params[i] -= step_size * m[i] / (v[i].sqrt() / bias2_sqrt + o.eps);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_struct_matches_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<AdamPush>() as u32,
            specs::ADAM_STEP.push_constant_size
        );
        assert_eq!(
            specs::ADAM_STEP4.push_constant_size,
            specs::ADAM_STEP.push_constant_size
        );
        assert_eq!(specs::ADAM_STEP.bindings.len(), 4);
        assert_eq!(specs::ADAM_STEP4.bindings.len(), 4);
    }

    #[test]
    fn adam_twin_follows_a_hand_computed_three_step_sequence() {
        // One parameter p0 = 1, lr 0.1, β = (0.9, 0.999), eps 1e-8, gradients 0.5, −1, 2.
        let o = AdamOptions {
            lr: 0.1,
            ..AdamOptions::default()
        };
        let (mut p, mut m, mut v) = ([1.0], [0.0], [0.0]);
        // Step 1: m = 0.1·0.5 = 0.05, v = 0.001·0.25 = 0.00025; m̂ = 0.5, sqrt(v̂) = 0.5:
        // p = 1 − 0.1 · 0.5 / (0.5 + 1e-8).
        // Step 2: m = 0.045 − 0.1 = −0.055, v = 0.999·0.00025 + 0.001 = 0.00124975;
        // p −= 0.1/(1 − 0.81) · m / (sqrt(v / (1 − 0.999²)) + 1e-8).
        // Step 3: m = 0.9·(−0.055) + 0.2 = 0.1505, v = 0.999·0.00124975 + 0.004 = 0.00524850025;
        // p −= 0.1/(1 − 0.729) · m / (sqrt(v / (1 − 0.999³)) + 1e-8).
        let mut hand = 1.0 - 0.1 * 0.5 / (0.5 + 1e-8);
        let expected = [
            (0.05, 0.00025, hand),
            (-0.055, 0.00124975, {
                hand -= 0.1 / 0.19 * -0.055 / ((0.00124975f64 / 0.001999).sqrt() + 1e-8);
                hand
            }),
            (0.1505, 0.00524850025, {
                hand -= 0.1 / 0.271 * 0.1505 / ((0.00524850025f64 / 0.002997001).sqrt() + 1e-8);
                hand
            }),
        ];
        // The same numbers as PyTorch's formulas evaluated in Python floats.
        let python = [0.900000002, 0.9366103542405654, 0.8946447927181046];
        for (t, (g, (em, ev, ep))) in [0.5, -1.0, 2.0].iter().zip(expected).enumerate() {
            cpu::step(&mut p, &[*g], &mut m, &mut v, t as u32 + 1, &o);
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-13 * b.abs().max(1e-3);
            assert!(close(m[0], em), "step {}: m {} vs {em}", t + 1, m[0]);
            assert!(close(v[0], ev), "step {}: v {} vs {ev}", t + 1, v[0]);
            assert!(close(p[0], ep), "step {}: p {} vs {ep}", t + 1, p[0]);
            assert!(close(p[0], python[t]), "step {}: p {}", t + 1, p[0]);
        }
    }

    #[test]
    fn options_out_of_range_are_input_errors() {
        for o in [
            AdamOptions {
                lr: -1.0,
                ..AdamOptions::default()
            },
            AdamOptions {
                betas: (1.0, 0.9),
                ..AdamOptions::default()
            },
            AdamOptions {
                eps: f64::NAN,
                ..AdamOptions::default()
            },
        ] {
            assert!(matches!(o.validate(), Err(Error::Input(_))), "{o:?}");
        }
    }
}
