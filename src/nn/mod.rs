//! Neural-network layers as GPU kernels with f64 CPU twins: what the reconstruction network
//! ([`crate::recon`]) is built from.
//!
//! - [`Conv2d`] (square kernel, stride, zero padding) and [`Linear`], each with a fused
//!   [`Activation`] whose derivative is read from the layer's *output*, so the backward needs no
//!   stored pre-activations.
//! - [`Sequential`]: layers whose sizes chain, their parameters in one flat buffer (so one
//!   [`crate::fit::Adam`] serves the whole network), activation buffers for a batch capacity,
//!   and the recorded forward and backward.
//! - [`cpu`]: the f64 twins, the oracle the kernels are tested against.
//!
//! **Layouts.** Tensors are `f32`, batch-major; images NCHW, so flattening a conv's output is the
//! identity on memory and it feeds a [`Linear`] directly. A layer's parameters are PyTorch's:
//! the weights (`[out][in][ky][kx]` for a conv, `[out][in]` for a linear), then the bias
//! `[out]`. A network's parameters are its layers', one after the other
//! ([`Sequential::param_offsets`]).
//!
//! **Determinism.** No float atomics: every sum has one writer and a fixed order (a conv's
//! parameter gradient is summed per sample over its outputs, then over the batch in order), so
//! reruns are bit-identical. Gradients are written, not accumulated.
//!
//! **Loop bounds.** On llvmpipe ([`crate::gpu::DeviceInfo::shader_loop_limit`]) the loops of one
//! invocation grow with the layer's size (a conv's `in_channels · kernel²`, a linear's inputs
//! and outputs, the batch, a conv's `out_h · out_w`): a network or batch capacity over the cap is
//! refused up front with [`Error::DeviceLimit`] of kind [`LoopIterations`](crate::LimitKind::LoopIterations).

pub mod cpu;
mod gpu;

pub use gpu::Sequential;

use crate::error::{Error, Result};
use crate::rng::SplitMix64;

/// A layer's fused activation (applied to its output; its derivative is computed from the
/// output).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Activation {
    /// `y = x`.
    Identity,
    /// `y = max(x, 0)`; `y' = [y > 0]`.
    Relu,
    /// `y = x > 0 ? x : slope · x` with `slope > 0` (so `y > 0 ⇔ x > 0`); `y' = y > 0 ? 1 : slope`.
    LeakyRelu(f32),
    /// `y = 1 / (1 + e^{−x})`; `y' = y (1 − y)`.
    Sigmoid,
    /// `y = tanh x`; `y' = 1 − y²`.
    Tanh,
}

impl Activation {
    /// [`Error::Input`] for a leaky slope that is not finite and positive.
    pub fn validate(&self) -> Result<()> {
        if let Activation::LeakyRelu(slope) = *self {
            if !(slope.is_finite() && slope > 0.0) {
                return Err(Error::Input(format!(
                    "LeakyRelu slope {slope}: it must be finite and > 0 (the derivative is read \
                     from the output's sign)"
                )));
            }
        }
        Ok(())
    }

    /// The kernels' specialization constants: `[mode, slope bits]` (`ACT`, `SLOPE` in `nn.glsl`).
    pub(crate) fn constants(&self) -> [u32; 2] {
        let slope = |s: f32| s.to_bits();
        match *self {
            Activation::Identity => [0, slope(0.2)],
            Activation::Relu => [1, slope(0.2)],
            Activation::LeakyRelu(s) => [2, slope(s)],
            Activation::Sigmoid => [3, slope(0.2)],
            Activation::Tanh => [4, slope(0.2)],
        }
    }
}

/// A 2-D convolution over NCHW images, PyTorch's `nn.Conv2d` (square kernel, zero padding, no
/// dilation or groups) with a fused activation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conv2d {
    /// Input channels C.
    pub in_channels: u32,
    /// Output channels O.
    pub out_channels: u32,
    /// Kernel side K.
    pub kernel: u32,
    /// Stride S ≥ 1.
    pub stride: u32,
    /// Zero padding P on every side.
    pub padding: u32,
    /// Input height.
    pub in_h: u32,
    /// Input width.
    pub in_w: u32,
    /// The fused activation.
    pub activation: Activation,
}

impl Conv2d {
    /// Output height, `⌊(in_h + 2P − K) / S⌋ + 1` (PyTorch's, floored).
    pub fn out_h(&self) -> u32 {
        self.out_side(self.in_h)
    }

    /// Output width, `⌊(in_w + 2P − K) / S⌋ + 1`.
    pub fn out_w(&self) -> u32 {
        self.out_side(self.in_w)
    }

    fn out_side(&self, side: u32) -> u32 {
        let padded = u64::from(side) + 2 * u64::from(self.padding);
        (padded.saturating_sub(u64::from(self.kernel)) / u64::from(self.stride.max(1)) + 1) as u32
    }

    /// Weights `O · C · K²` (the bias follows them).
    pub fn weight_count(&self) -> u64 {
        u64::from(self.out_channels)
            * u64::from(self.in_channels)
            * u64::from(self.kernel)
            * u64::from(self.kernel)
    }

    /// [`Error::Input`] for a zero size, a zero stride, a kernel larger than the padded input or
    /// a bad activation.
    pub fn validate(&self) -> Result<()> {
        self.activation.validate()?;
        let sizes = [
            self.in_channels,
            self.out_channels,
            self.kernel,
            self.stride,
            self.in_h,
            self.in_w,
        ];
        let fits =
            |side: u32| u64::from(side) + 2 * u64::from(self.padding) >= u64::from(self.kernel);
        if sizes.contains(&0) || !fits(self.in_h) || !fits(self.in_w) || self.padding > 1 << 16 {
            return Err(Error::Input(format!(
                "{self:?}: sizes and stride must be ≥ 1, padding ≤ 65536, and the kernel no larger \
                 than the padded input"
            )));
        }
        Ok(())
    }
}

/// A fully connected layer, PyTorch's `nn.Linear`, with a fused activation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Linear {
    /// Inputs I.
    pub in_features: u32,
    /// Outputs O.
    pub out_features: u32,
    /// The fused activation.
    pub activation: Activation,
}

impl Linear {
    /// [`Error::Input`] for a zero size or a bad activation.
    pub fn validate(&self) -> Result<()> {
        self.activation.validate()?;
        if self.in_features == 0 || self.out_features == 0 {
            return Err(Error::Input(format!("{self:?}: sizes must be ≥ 1")));
        }
        Ok(())
    }
}

/// One layer of a [`Sequential`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Layer {
    /// A convolution.
    Conv2d(Conv2d),
    /// A fully connected layer.
    Linear(Linear),
}

impl Layer {
    /// Floats of one sample's input (`C · H · W`, or I).
    pub fn input_len(&self) -> u64 {
        match self {
            Layer::Conv2d(c) => u64::from(c.in_channels) * u64::from(c.in_h) * u64::from(c.in_w),
            Layer::Linear(l) => u64::from(l.in_features),
        }
    }

    /// Floats of one sample's output (`O · out_h · out_w`, or O).
    pub fn output_len(&self) -> u64 {
        match self {
            Layer::Conv2d(c) => {
                u64::from(c.out_channels) * u64::from(c.out_h()) * u64::from(c.out_w())
            }
            Layer::Linear(l) => u64::from(l.out_features),
        }
    }

    /// Weights, then one bias per output channel or feature.
    pub fn param_count(&self) -> u64 {
        match self {
            Layer::Conv2d(c) => c.weight_count() + u64::from(c.out_channels),
            Layer::Linear(l) => {
                u64::from(l.out_features) * u64::from(l.in_features) + u64::from(l.out_features)
            }
        }
    }

    /// The weights' count, the bias after them.
    pub fn weight_count(&self) -> u64 {
        match self {
            Layer::Conv2d(c) => c.weight_count(),
            Layer::Linear(l) => u64::from(l.out_features) * u64::from(l.in_features),
        }
    }

    /// Inputs each output sees, PyTorch's `fan_in` (`C · K²`, or I).
    pub fn fan_in(&self) -> u64 {
        match self {
            Layer::Conv2d(c) => {
                u64::from(c.in_channels) * u64::from(c.kernel) * u64::from(c.kernel)
            }
            Layer::Linear(l) => u64::from(l.in_features),
        }
    }

    /// The fused activation.
    pub fn activation(&self) -> Activation {
        match self {
            Layer::Conv2d(c) => c.activation,
            Layer::Linear(l) => l.activation,
        }
    }

    /// The layer's own checks ([`Conv2d::validate`], [`Linear::validate`]).
    pub fn validate(&self) -> Result<()> {
        match self {
            Layer::Conv2d(c) => c.validate(),
            Layer::Linear(l) => l.validate(),
        }
    }

    /// Loop iterations one invocation of the layer's costliest kernel runs for a batch of
    /// `batch` (an upper bound mirroring the kernels' loops, counting every iteration of nested
    /// loops and one exit per loop entered): what [`Sequential::new`] checks against the
    /// device's [`shader_loop_limit`](crate::gpu::DeviceInfo::shader_loop_limit).
    pub fn loop_iterations(&self, batch: u32) -> u64 {
        // Each kernel's 4 × 4 block store loops up to 4 + 16 more times.
        const STORES: u64 = 32;
        let batch = u64::from(batch);
        match self {
            Layer::Conv2d(c) => {
                let (ci, co, k) = (
                    u64::from(c.in_channels),
                    u64::from(c.out_channels),
                    u64::from(c.kernel),
                );
                let m = k.div_ceil(u64::from(c.stride));
                let (oh, ow) = (u64::from(c.out_h()), u64::from(c.out_w()));
                let forward = ci * (k * k + 2 * k + 2) + 1 + STORES;
                let d_input = co * (m * m + 2 * m + 2) + 1 + STORES;
                // Both branches (bias, weight) count: llvmpipe may run both.
                let w_grad = (oh * ow + 1) + (oh * (ow + 2) + 1) + STORES;
                let reduce = batch + 1;
                forward.max(d_input).max(w_grad).max(reduce)
            }
            Layer::Linear(l) => {
                let forward = u64::from(l.in_features) + 1 + STORES;
                let d_input = u64::from(l.out_features) + 1 + STORES;
                let w_grad = 2 * (batch + 1) + STORES;
                forward.max(d_input).max(w_grad)
            }
        }
    }
}

impl From<Conv2d> for Layer {
    fn from(c: Conv2d) -> Self {
        Layer::Conv2d(c)
    }
}

impl From<Linear> for Layer {
    fn from(l: Linear) -> Self {
        Layer::Linear(l)
    }
}

/// Each layer's first parameter in the network's flat parameter vector, and the total count.
pub fn param_offsets(layers: &[Layer]) -> (Vec<u64>, u64) {
    let mut offsets = Vec::with_capacity(layers.len());
    let mut total = 0;
    for layer in layers {
        offsets.push(total);
        total += layer.param_count();
    }
    (offsets, total)
}

/// [`Error::Input`] unless `layers` is non-empty, each layer valid, and each layer's input the
/// previous one's output.
pub fn validate_chain(layers: &[Layer]) -> Result<()> {
    if layers.is_empty() {
        return Err(Error::Input("a network needs at least one layer".into()));
    }
    for (i, layer) in layers.iter().enumerate() {
        layer
            .validate()
            .map_err(|e| Error::Input(format!("layer {i}: {e}")))?;
        if i > 0 && layers[i - 1].output_len() != layer.input_len() {
            return Err(Error::Input(format!(
                "layer {i} ({layer:?}) takes {} floats per sample, but layer {} gives {}",
                layer.input_len(),
                i - 1,
                layers[i - 1].output_len()
            )));
        }
    }
    Ok(())
}

/// PyTorch's default initialization of `layers`' parameters (`kaiming_uniform_(a = √5)` for the
/// weights, and the same bound for the biases: `U(−1/√fan_in, 1/√fan_in)`), layer by layer,
/// weights then bias, from one SplitMix64 stream seeded with `seed` (the same values on every
/// platform; not PyTorch's stream).
pub fn init(layers: &[Layer], seed: u64) -> Vec<f32> {
    let mut rng = SplitMix64(seed);
    let (_, total) = param_offsets(layers);
    let mut params = Vec::with_capacity(total as usize);
    for layer in layers {
        let bound = 1.0 / (layer.fan_in() as f64).sqrt();
        for _ in 0..layer.param_count() {
            params.push((bound * (2.0 * rng.unit() - 1.0)) as f32);
        }
    }
    params
}

#[cfg(test)]
mod tests {
    use super::*;

    fn conv(in_h: u32, kernel: u32, stride: u32, padding: u32) -> Conv2d {
        Conv2d {
            in_channels: 1,
            out_channels: 1,
            kernel,
            stride,
            padding,
            in_h,
            in_w: in_h,
            activation: Activation::Identity,
        }
    }

    #[test]
    fn conv_output_sizes_are_pytorchs_floored_ones() {
        // torch.nn.Conv2d(1, 1, k, s, p)(torch.zeros(1, 1, h, h)).shape[-1]
        for (h, k, s, p, out) in [
            (64, 5, 2, 2, 32),
            (7, 3, 2, 0, 3),
            (8, 4, 2, 1, 4),
            (9, 5, 2, 1, 4),
            (5, 5, 1, 0, 1),
            (3, 5, 3, 2, 1),
            (10, 4, 3, 1, 3),
        ] {
            assert_eq!(conv(h, k, s, p).out_h(), out, "h {h} k {k} s {s} p {p}");
        }
    }

    #[test]
    fn init_is_seeded_and_within_pytorchs_bounds() {
        let layers = [
            Layer::Conv2d(Conv2d {
                in_channels: 2,
                out_channels: 3,
                ..conv(6, 3, 1, 1)
            }),
            Layer::Linear(Linear {
                in_features: 108,
                out_features: 5,
                activation: Activation::Relu,
            }),
        ];
        let a = init(&layers, 7);
        assert_eq!(a, init(&layers, 7));
        assert_ne!(a, init(&layers, 8));
        let (offsets, total) = param_offsets(&layers);
        assert_eq!((offsets, total), (vec![0, 57], 57 + 545));
        let (conv_bound, lin_bound) = (1.0 / 18f32.sqrt(), 1.0 / 108f32.sqrt());
        assert!(a[..57].iter().all(|w| w.abs() <= conv_bound));
        assert!(a[57..].iter().all(|w| w.abs() <= lin_bound));
        // Spread over the whole range, not a corner of it.
        assert!(a[..57].iter().any(|w| w.abs() > 0.8 * conv_bound));
        assert!(a[57..].iter().any(|w| w.abs() > 0.8 * lin_bound));
    }

    #[test]
    fn a_chain_whose_sizes_do_not_match_is_an_input_error() {
        let layers = [
            Layer::Conv2d(conv(6, 3, 1, 0)),
            Layer::Linear(Linear {
                in_features: 36,
                out_features: 2,
                activation: Activation::Identity,
            }),
        ];
        assert!(matches!(validate_chain(&layers), Err(Error::Input(_))));
        assert!(validate_chain(&layers[..1]).is_ok());
        let bad_slope = Layer::Linear(Linear {
            in_features: 1,
            out_features: 1,
            activation: Activation::LeakyRelu(0.0),
        });
        assert!(matches!(validate_chain(&[bad_slope]), Err(Error::Input(_))));
    }
}
