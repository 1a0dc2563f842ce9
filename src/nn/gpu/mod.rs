//! The layers' kernels (`kernels/softvk/nn/`) and [`Sequential`], which records a network's forward and
//! backward.

mod backward;
mod build;
mod forward;

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::{Conv2d, Layer};
use crate::error::{Error, Result};
use crate::gpu::groups;
use crate::gpu::{Buffer, BufferRange, Kernel, Recorder, TEXEL_BYTES};
use crate::specs;

/// Push constants of the conv kernels (`NN_CONV_PUSH` in `nn.glsl`).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct ConvPush {
    batch: u32,
    in_c: u32,
    in_h: u32,
    in_w: u32,
    out_c: u32,
    out_h: u32,
    out_w: u32,
    kernel: u32,
    stride: u32,
    padding: u32,
    param_offset: u32,
    total: u32,
}

/// Push constants of the linear kernels (`NN_LINEAR_PUSH` in `nn.glsl`).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct LinearPush {
    batch: u32,
    in_f: u32,
    out_f: u32,
    param_offset: u32,
    total: u32,
    pad: [u32; 3],
}

/// Push constants of `nn_act_backward.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ActPush {
    n: u32,
}

/// Push constants of `nn_sum_rows.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct SumPush {
    rows: u32,
    cols: u32,
    dst_offset: u32,
    pad: u32,
}

/// Invocations per sample of the conv kernels, which each compute a block of 4 channels × 4
/// columns (see the kernels' headers).
pub(crate) struct ConvBlocks {
    /// `nn_conv_forward`: 4 output channels × 4 adjacent columns of one output row.
    pub forward: u64,
    /// `nn_conv_dinput`: 4 input channels × 4 columns of one input row sharing a residue mod s.
    pub input_gradient: u64,
    /// `nn_conv_wgrad`: 4 output × 4 input channels per tap, then one per bias.
    pub weight_gradient: u64,
    /// `nn_conv_wgrad4`: 4 output channels × 1 input channel per kernel row, then one per bias.
    pub weight_gradient4: u64,
    /// `nn_conv_dinput4`: 4 input channels × 4 s columns of one input row.
    pub input_gradient4: u64,
}

impl ConvBlocks {
    pub fn of(c: &Conv2d) -> Self {
        let by4 = |n: u32| u64::from(n.div_ceil(4));
        let (k, s) = (u64::from(c.kernel), u64::from(c.stride));
        Self {
            forward: by4(c.out_channels) * u64::from(c.out_h()) * by4(c.out_w()),
            input_gradient: by4(c.in_channels)
                * u64::from(c.in_h)
                * s
                * u64::from(c.in_w.div_ceil(c.stride)).div_ceil(4),
            weight_gradient: by4(c.out_channels) * by4(c.in_channels) * k * k
                + u64::from(c.out_channels),
            weight_gradient4: by4(c.out_channels) * u64::from(c.in_channels) * k
                + u64::from(c.out_channels),
            input_gradient4: by4(c.in_channels)
                * u64::from(c.in_h)
                * u64::from(c.in_w).div_ceil(4 * s),
        }
    }
}

/// Invocations of the linear kernels for a batch, which each compute a block of 4 × 4 (see the
/// kernels' headers).
struct LinearBlocks {
    /// `nn_linear_forward`: 4 outputs × 4 samples.
    forward: u64,
    /// `nn_linear_dinput`: 4 inputs × 4 samples.
    input_gradient: u64,
    /// `nn_linear_wgrad`: 4 outputs × 4 inputs, then one per bias.
    weight_gradient: u64,
    /// `nn_linear_dinput4`: 8 inputs (2 texels) × 4 samples.
    input_gradient4: u64,
    /// `nn_linear_wgrad4`: 4 outputs × 8 inputs, then one per bias.
    weight_gradient4: u64,
}

impl LinearBlocks {
    fn of(layer: &Layer, batch: u32) -> Self {
        let by4 = |n: u64| n.div_ceil(4);
        let (i, o) = (layer.input_len(), layer.output_len());
        let b = by4(u64::from(batch));
        Self {
            forward: by4(o) * b,
            input_gradient: by4(i) * b,
            weight_gradient: by4(o) * by4(i) + o,
            input_gradient4: by4(i).div_ceil(2) * b,
            weight_gradient4: by4(o) * by4(i).div_ceil(2) + o,
        }
    }
}

/// Whether `r` binds as a texel buffer on the recorder's device: at a texel-aligned offset, of
/// whole texels, within `maxTexelBufferElements`.
fn texel_input(rec: &Recorder<'_>, r: &BufferRange<'_>) -> bool {
    let limits = &rec.context().info().limits;
    r.offset % limits.min_texel_buffer_offset_alignment == 0
        && r.size % TEXEL_BYTES == 0
        && r.size / TEXEL_BYTES <= u64::from(limits.max_texel_buffer_elements)
}

/// Texels of a conv layer's packed weights: one per (input channel, tap, block of 4 output
/// channels) or, `by_input`, per (output channel, tap, block of 4 input channels).
fn packed_texels(c: &Conv2d, by_input: bool) -> u64 {
    let (whole, blocked) = if by_input {
        (c.out_channels, c.in_channels)
    } else {
        (c.in_channels, c.out_channels)
    };
    u64::from(whole) * u64::from(c.kernel * c.kernel) * u64::from(blocked.div_ceil(4))
}

/// A network of [`Layer`]s whose sizes chain, recorded on the GPU for batches of up to a fixed
/// capacity.
///
/// It owns each layer's output buffer (`capacity × output_len` floats, batch-major; the first
/// `batch × output_len` hold the last recorded forward) and the backward's scratch; the caller
/// owns the parameters, inputs and gradients and passes them as [`BufferRange`]s. The parameters
/// are one flat vector ([`Sequential::param_offsets`]; [`Sequential::init`] makes PyTorch's
/// default initial values), so one [`crate::fit::Adam`] of [`Sequential::param_count`] serves the
/// whole network.
pub struct Sequential {
    layers: Vec<Layer>,
    offsets: Vec<u64>,
    param_count: u64,
    capacity: u32,
    /// Per layer: its forward pipeline and, unless its activation is the identity, the
    /// activation's backward.
    forward: Vec<Arc<Kernel>>,
    /// Per layer whose rows are whole texels (a linear layer's `in_features`, a conv's `in_w`, a
    /// multiple of 4): its forward reading inputs and weights as texels
    /// ([`Sequential::texel_rows`] and [`texel_input`] say when it applies).
    forward4: Vec<Option<Arc<Kernel>>>,
    /// Per conv layer whose input and output rows are whole texels: its weight gradient reading
    /// the input and dL/d(pre-activation) as texels.
    wgrad4: Vec<Option<Arc<Kernel>>>,
    /// Per conv layer whose output rows are whole texels: its input gradient reading
    /// dL/d(pre-activation) and the weights packed by input channel as texels.
    dinput4: Vec<Option<Arc<Kernel>>>,
    /// Packs a conv layer's weights as texels of 4 output channels for its texel forward.
    conv_pack: Arc<Kernel>,
    /// Packs them as texels of 4 input channels for its texel input gradient.
    conv_pack_by_input: Arc<Kernel>,
    /// The packed weights of the conv layer being run (the largest such layer's size).
    conv_packed: Buffer,
    act_backward: Vec<Option<Arc<Kernel>>>,
    conv_dinput: Arc<Kernel>,
    conv_wgrad: Arc<Kernel>,
    sum_rows: Arc<Kernel>,
    linear_dinput: Arc<Kernel>,
    linear_wgrad: Arc<Kernel>,
    linear_dinput4: Arc<Kernel>,
    linear_wgrad4: Arc<Kernel>,
    outputs: Vec<Buffer>,
    /// The backward's ping-pong gradients (dL/d(pre-activation), dL/d(a layer's input)).
    scratch: [Buffer; 2],
    /// The convs' per-sample parameter gradients, `capacity × P` of the largest conv.
    partial: Buffer,
}

impl Sequential {
    /// The layers.
    pub fn layers(&self) -> &[Layer] {
        &self.layers
    }

    /// Each layer's first parameter (in floats) in the flat parameter vector.
    pub fn param_offsets(&self) -> &[u64] {
        &self.offsets
    }

    /// Parameters of the whole network.
    pub fn param_count(&self) -> u64 {
        self.param_count
    }

    /// The largest batch the buffers hold.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Floats of one sample's input.
    pub fn input_len(&self) -> u64 {
        self.layers[0].input_len()
    }

    /// Floats of one sample's final output.
    pub fn output_len(&self) -> u64 {
        self.layers[self.layers.len() - 1].output_len()
    }

    /// PyTorch's default initial parameters from `seed` ([`super::init`]).
    pub fn init(&self, seed: u64) -> Vec<f32> {
        super::init(&self.layers, seed)
    }

    /// The final output (`capacity × output_len` floats; the first `batch × output_len` are the
    /// last recorded forward's).
    pub fn output(&self) -> &Buffer {
        &self.outputs[self.outputs.len() - 1]
    }

    /// Layer `l`'s output, laid out as [`Sequential::output`]; `None` past the last layer.
    pub fn layer_output(&self, l: usize) -> Option<&Buffer> {
        self.outputs.get(l)
    }

    fn check_batch(&self, batch: u32) -> Result<()> {
        if batch > self.capacity {
            return Err(Error::Input(format!(
                "a batch of {batch} is over the network's capacity of {}",
                self.capacity
            )));
        }
        Ok(())
    }

    /// For linear layer `l` with rows of whole texels, whose weights (in `params`) and input
    /// rows (`x`) start at texel boundaries the device can bind: its texel forward and the
    /// weights' range (the texel backward applies too). `None` where the scalar kernels must
    /// serve.
    fn texel_rows<'p>(
        &self,
        rec: &Recorder<'_>,
        l: usize,
        params: BufferRange<'p>,
        x: BufferRange<'_>,
    ) -> Option<(&Arc<Kernel>, BufferRange<'p>)> {
        let kernel = self.forward4[l].as_ref()?;
        let Layer::Linear(f) = &self.layers[l] else {
            return None;
        };
        let weights = params.sub(
            4 * self.offsets[l],
            4 * u64::from(f.in_features) * u64::from(f.out_features),
        );
        (texel_input(rec, &weights) && texel_input(rec, &x)).then_some((kernel, weights))
    }

    /// Records the packing of conv layer `l`'s weights (in `params`) as texels of 4 output
    /// channels or, `by_input`, of 4 input channels; the packed range.
    fn record_pack(
        &self,
        rec: &mut Recorder<'_>,
        l: usize,
        batch: u32,
        params: BufferRange<'_>,
        by_input: bool,
    ) -> Result<BufferRange<'_>> {
        let Layer::Conv2d(c) = &self.layers[l] else {
            unreachable!("record_pack of a conv layer");
        };
        let texels = packed_texels(c, by_input);
        let packed = self.conv_packed.range(0, TEXEL_BYTES * texels);
        let kernel = if by_input {
            &self.conv_pack_by_input
        } else {
            &self.conv_pack
        };
        rec.dispatch(
            kernel,
            &specs::NnConvPackWeightsBindings { params, packed }.for_kernel(kernel)?,
            &self.conv_push(l, batch, texels),
            groups(texels, 64)?,
        )?;
        Ok(packed)
    }

    fn conv_push(&self, l: usize, batch: u32, total: u64) -> ConvPush {
        let Layer::Conv2d(c) = &self.layers[l] else {
            unreachable!("conv_push of a conv layer");
        };
        ConvPush {
            batch,
            in_c: c.in_channels,
            in_h: c.in_h,
            in_w: c.in_w,
            out_c: c.out_channels,
            out_h: c.out_h(),
            out_w: c.out_w(),
            kernel: c.kernel,
            stride: c.stride,
            padding: c.padding,
            // Both fit: every buffer was checked against one binding (< 2^32 bytes).
            param_offset: self.offsets[l] as u32,
            total: total as u32,
        }
    }

    fn linear_push(&self, l: usize, batch: u32, total: u64) -> LinearPush {
        let Layer::Linear(f) = &self.layers[l] else {
            unreachable!("linear_push of a linear layer");
        };
        LinearPush {
            batch,
            in_f: f.in_features,
            out_f: f.out_features,
            param_offset: self.offsets[l] as u32,
            total: total as u32,
            pad: [0; 3],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_structs_match_the_kernels_layouts() {
        let conv = std::mem::size_of::<ConvPush>() as u32;
        for spec in [
            &specs::NN_CONV_FORWARD,
            &specs::NN_CONV_DINPUT,
            &specs::NN_CONV_WGRAD,
        ] {
            assert_eq!(conv, spec.push_constant_size, "{}", spec.name);
            assert_eq!(spec.bindings.len(), 3, "{}", spec.name);
        }
        let linear = std::mem::size_of::<LinearPush>() as u32;
        for spec in [
            &specs::NN_LINEAR_FORWARD,
            &specs::NN_LINEAR_DINPUT,
            &specs::NN_LINEAR_WGRAD,
        ] {
            assert_eq!(linear, spec.push_constant_size, "{}", spec.name);
            assert_eq!(spec.bindings.len(), 3, "{}", spec.name);
        }
        assert_eq!(
            std::mem::size_of::<ActPush>() as u32,
            specs::NN_ACT_BACKWARD.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<SumPush>() as u32,
            specs::NN_SUM_ROWS.push_constant_size
        );
    }
}
