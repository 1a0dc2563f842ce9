//! The layers' kernels (`kernels/nn/`) and [`Sequential`], which records a network's forward and
//! backward.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::{Activation, Conv2d, Layer, param_offsets, validate_chain};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{
    Buffer, BufferRange, Context, Kernel, KernelVariants, MemoryKind, Recorder, TEXEL_BYTES, specs,
};
use crate::gpu::{check_binding, check_texels, groups};

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

/// The caller's ranges of one backward.
#[derive(Clone, Copy)]
struct BackwardBuffers<'a> {
    params: BufferRange<'a>,
    input: BufferRange<'a>,
    d_output: BufferRange<'a>,
    d_params: BufferRange<'a>,
    d_input: Option<BufferRange<'a>>,
}

/// Where a gradient of the backward lives: the caller's d_output, or one of the two scratch
/// buffers (ping-pong).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Slot {
    Caller,
    Scratch(usize),
}

impl Slot {
    fn other(self) -> Slot {
        match self {
            Slot::Caller | Slot::Scratch(1) => Slot::Scratch(0),
            Slot::Scratch(_) => Slot::Scratch(1),
        }
    }
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
    /// The network of `layers` for batches of at most `capacity` samples: its pipelines (one
    /// per activation used) and buffers.
    ///
    /// [`Error::Input`] for an empty chain, an invalid layer or sizes that do not chain, or a
    /// zero capacity; [`Error::DeviceLimit`] when a layer's loops at this capacity pass the
    /// device's loop cap ([`Layer::loop_iterations`]) or a buffer does not fit one binding.
    pub fn new(ctx: &Context, layers: &[Layer], capacity: u32) -> Result<Self> {
        validate_chain(layers)?;
        if capacity == 0 {
            return Err(Error::Input(
                "a network's batch capacity must be ≥ 1".into(),
            ));
        }
        if let Some(limit) = ctx.info().shader_loop_limit() {
            for (i, layer) in layers.iter().enumerate() {
                let need = layer.loop_iterations(capacity);
                if need > limit {
                    return Err(Error::DeviceLimit {
                        kind: LimitKind::LoopIterations,
                        what: format!("layer {i} ({layer:?}) at a batch capacity of {capacity}"),
                        need,
                        max: limit,
                        device: ctx.info().name.clone(),
                        hint: "use smaller layers or a smaller batch capacity",
                    });
                }
            }
        }
        let (offsets, param_count) = param_offsets(layers);
        check_binding(ctx, "the network's parameters", 4 * param_count)?;
        let cap = u64::from(capacity);
        let widest = layers
            .iter()
            .map(|l| l.output_len().max(l.input_len()))
            .max()
            .unwrap_or(1);
        let conv_params = layers
            .iter()
            .filter(|l| matches!(l, Layer::Conv2d(_)))
            .map(Layer::param_count)
            .max()
            .unwrap_or(0);
        let scratch_bytes = check_binding(ctx, "the network's gradient scratch", 4 * cap * widest)?;
        let partial_bytes = check_binding(
            ctx,
            "the convs' per-sample parameter gradients",
            4 * cap * conv_params,
        )?;

        let conv_forward = KernelVariants::new(&specs::NN_CONV_FORWARD);
        let linear_forward = KernelVariants::new(&specs::NN_LINEAR_FORWARD);
        let linear_forward4 = KernelVariants::new(&specs::NN_LINEAR_FORWARD4);
        let conv_forward4 = KernelVariants::new(&specs::NN_CONV_FORWARD4);
        let conv_wgrad4 = KernelVariants::new(&specs::NN_CONV_WGRAD4);
        let mut wgrad4 = Vec::with_capacity(layers.len());
        let conv_dinput4 = KernelVariants::new(&specs::NN_CONV_DINPUT4);
        let mut dinput4 = Vec::with_capacity(layers.len());
        let act = KernelVariants::new(&specs::NN_ACT_BACKWARD);
        let mut forward = Vec::with_capacity(layers.len());
        let mut forward4 = Vec::with_capacity(layers.len());
        let mut act_backward = Vec::with_capacity(layers.len());
        let mut outputs = Vec::with_capacity(layers.len());
        for (i, layer) in layers.iter().enumerate() {
            let constants = layer.activation().constants();
            forward.push(match layer {
                Layer::Conv2d(_) => conv_forward.get(ctx, &constants)?,
                Layer::Linear(_) => linear_forward.get(ctx, &constants)?,
            });
            forward4.push(match layer {
                Layer::Linear(f) if f.in_features % 4 == 0 => {
                    Some(linear_forward4.get(ctx, &constants)?)
                }
                Layer::Conv2d(c) if c.in_w % 4 == 0 => {
                    let shape = [c.kernel, c.stride, c.padding];
                    Some(conv_forward4.get(ctx, &[&constants[..], &shape[..]].concat())?)
                }
                _ => None,
            });
            dinput4.push(match layer {
                Layer::Conv2d(c) if c.out_w() % 4 == 0 => {
                    let shape = [c.kernel, c.stride, c.padding];
                    Some(conv_dinput4.get(ctx, &[&constants[..], &shape[..]].concat())?)
                }
                _ => None,
            });
            wgrad4.push(match layer {
                Layer::Conv2d(c) if c.in_w % 4 == 0 && c.out_w() % 4 == 0 => {
                    let shape = [c.kernel, c.stride, c.padding];
                    Some(conv_wgrad4.get(ctx, &[&constants[..], &shape[..]].concat())?)
                }
                _ => None,
            });
            act_backward.push(match layer.activation() {
                Activation::Identity => None,
                _ => Some(act.get(ctx, &constants)?),
            });
            let what = format!("layer {i}'s outputs");
            let bytes = check_binding(ctx, &what, 4 * cap * layer.output_len())?;
            outputs.push(ctx.create_buffer(
                &format!("nn layer {i} output"),
                bytes,
                MemoryKind::Device,
            )?);
        }
        let packed_texels = layers
            .iter()
            .filter_map(|l| match l {
                Layer::Conv2d(c) => Some(packed_texels(c, false).max(packed_texels(c, true))),
                _ => None,
            })
            .max()
            .unwrap_or(0);
        check_texels(ctx, "a conv layer's packed weights", 16 * packed_texels)?;
        Ok(Self {
            layers: layers.to_vec(),
            offsets,
            param_count,
            capacity,
            forward,
            conv_pack: ctx.kernel(&specs::NN_CONV_PACK_WEIGHTS, &[])?,
            // Constant 2 (BY_INPUT) true; 0 and 1 (the activation's) unused.
            conv_pack_by_input: ctx.kernel(&specs::NN_CONV_PACK_WEIGHTS, &[0, 0, 1])?,
            dinput4,
            conv_packed: ctx.create_buffer(
                "nn conv packed weights",
                crate::gpu::TEXEL_BYTES * packed_texels.max(1),
                MemoryKind::Device,
            )?,
            forward4,
            wgrad4,
            act_backward,
            conv_dinput: ctx.kernel(&specs::NN_CONV_DINPUT, &[])?,
            conv_wgrad: ctx.kernel(&specs::NN_CONV_WGRAD, &[])?,
            sum_rows: ctx.kernel(&specs::NN_SUM_ROWS, &[])?,
            linear_dinput: ctx.kernel(&specs::NN_LINEAR_DINPUT, &[])?,
            linear_wgrad: ctx.kernel(&specs::NN_LINEAR_WGRAD, &[])?,
            linear_dinput4: ctx.kernel(&specs::NN_LINEAR_DINPUT4, &[])?,
            linear_wgrad4: ctx.kernel(&specs::NN_LINEAR_WGRAD4, &[])?,
            outputs,
            scratch: [
                ctx.create_buffer("nn gradient scratch 0", scratch_bytes, MemoryKind::Device)?,
                ctx.create_buffer("nn gradient scratch 1", scratch_bytes, MemoryKind::Device)?,
            ],
            partial: ctx.create_buffer(
                "nn conv per-sample parameter gradients",
                partial_bytes,
                MemoryKind::Device,
            )?,
        })
    }

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

    /// Records the forward of `batch` samples of `input` (`batch × input_len` floats) with
    /// `params` ([`Sequential::param_count`] floats): every layer's output into its buffer.
    ///
    /// [`Error::Input`] for a batch over the capacity; [`Error::BufferTooSmall`] for a range
    /// too small.
    pub fn record_forward(
        &self,
        rec: &mut Recorder<'_>,
        params: BufferRange<'_>,
        input: BufferRange<'_>,
        batch: u32,
    ) -> Result<()> {
        self.check_batch(batch)?;
        let n = u64::from(batch);
        params.require(4 * self.param_count, "the network's parameters")?;
        input.require(4 * n * self.input_len(), "the network's input batch")?;
        if batch == 0 {
            return Ok(());
        }
        for (l, layer) in self.layers.iter().enumerate() {
            let x = match l {
                0 => input.sub(0, 4 * n * layer.input_len()),
                _ => self.outputs[l - 1].range(0, 4 * n * layer.input_len()),
            };
            let y = self.outputs[l].range(0, 4 * n * layer.output_len());
            let kernel = &self.forward[l];
            rec.pass(&format!("nn forward layer {l}"), |rec| match layer {
                Layer::Conv2d(c) => {
                    let blocks = n * ConvBlocks::of(c).forward;
                    let push = self.conv_push(l, batch, blocks);
                    if let Some(kernel4) =
                        self.forward4[l].as_ref().filter(|_| texel_input(rec, &x))
                    {
                        let packed = self.record_pack(rec, l, batch, params, false)?;
                        return rec.dispatch(
                            kernel4,
                            &specs::NnConvForward4Bindings {
                                params,
                                weights: packed,
                                inp: x,
                                output: y,
                            }
                            .for_kernel(kernel4)?,
                            &push,
                            groups(blocks, 64)?,
                        );
                    }
                    rec.dispatch(
                        kernel,
                        &specs::NnConvForwardBindings {
                            params,
                            input: x,
                            output: y,
                        }
                        .for_kernel(kernel)?,
                        &push,
                        groups(blocks, 64)?,
                    )
                }
                Layer::Linear(_) => {
                    let push = self.linear_push(l, batch, LinearBlocks::of(layer, batch).forward);
                    let groups = groups(LinearBlocks::of(layer, batch).forward, 64)?;
                    match self.texel_rows(rec, l, params, x) {
                        Some((kernel, weights)) => rec.dispatch(
                            kernel,
                            &specs::NnLinearForward4Bindings {
                                params,
                                weights,
                                inp: x,
                                output: y,
                            }
                            .for_kernel(kernel)?,
                            &push,
                            groups,
                        ),
                        None => rec.dispatch(
                            kernel,
                            &specs::NnLinearForwardBindings {
                                params,
                                input: x,
                                output: y,
                            }
                            .for_kernel(kernel)?,
                            &push,
                            groups,
                        ),
                    }
                }
            })?;
        }
        Ok(())
    }

    /// Records the backward of the last recorded forward (same `params`, `input` and `batch`;
    /// it reads the layers' outputs): from `d_output` = dL/d(final output)
    /// (`batch × output_len` floats), writes dL/d(params) into `d_params`
    /// ([`Sequential::param_count`] floats, overwritten) and, when given, dL/d(input) into
    /// `d_input` (`batch × input_len` floats; the first layer's input gradient is skipped
    /// without it).
    ///
    /// [`Error::Input`] for a batch over the capacity; [`Error::BufferTooSmall`] for a range
    /// too small.
    #[allow(clippy::too_many_arguments)]
    pub fn record_backward(
        &self,
        rec: &mut Recorder<'_>,
        params: BufferRange<'_>,
        input: BufferRange<'_>,
        d_output: BufferRange<'_>,
        d_params: BufferRange<'_>,
        d_input: Option<BufferRange<'_>>,
        batch: u32,
    ) -> Result<()> {
        self.check_batch(batch)?;
        let n = u64::from(batch);
        params.require(4 * self.param_count, "the network's parameters")?;
        input.require(4 * n * self.input_len(), "the network's input batch")?;
        d_output.require(4 * n * self.output_len(), "the network's output gradient")?;
        d_params.require(4 * self.param_count, "the network's parameter gradient")?;
        if let Some(d_input) = &d_input {
            d_input.require(4 * n * self.input_len(), "the network's input gradient")?;
        }
        if batch == 0 {
            return Ok(());
        }
        let buffers = BackwardBuffers {
            params,
            input,
            d_output,
            d_params,
            d_input,
        };
        let mut d_out = Slot::Caller;
        for l in (0..self.layers.len()).rev() {
            d_out = rec.pass(&format!("nn backward layer {l}"), |rec| {
                self.record_layer_backward(rec, &buffers, l, d_out, batch)
            })?;
        }
        Ok(())
    }

    /// Layer `l`'s backward from dL/d(its output) in `d_out`; returns where dL/d(its input) went.
    fn record_layer_backward(
        &self,
        rec: &mut Recorder<'_>,
        buffers: &BackwardBuffers<'_>,
        l: usize,
        d_out: Slot,
        batch: u32,
    ) -> Result<Slot> {
        let BackwardBuffers {
            params,
            input,
            d_output,
            d_params,
            d_input,
        } = *buffers;
        let n = u64::from(batch);
        let layer = &self.layers[l];
        let range = |slot: Slot, floats: u64| match slot {
            Slot::Caller => d_output.sub(0, 4 * floats),
            Slot::Scratch(i) => self.scratch[i].range(0, 4 * floats),
        };
        let out_floats = n * layer.output_len();
        let in_floats = n * layer.input_len();
        let x = match l {
            0 => input.sub(0, 4 * in_floats),
            _ => self.outputs[l - 1].range(0, 4 * in_floats),
        };
        // dL/d(pre-activation): the identity's is dL/d(output) itself.
        let d_pre_slot = match &self.act_backward[l] {
            None => d_out,
            Some(kernel) => {
                let slot = d_out.other();
                rec.pass(&format!("nn layer {l} act"), |rec| {
                    rec.dispatch(
                        kernel,
                        &specs::NnActBackwardBindings {
                            output: self.outputs[l].range(0, 4 * out_floats),
                            d_out: range(d_out, out_floats),
                            d_pre: range(slot, out_floats),
                        }
                        .for_kernel(kernel)?,
                        &ActPush {
                            n: out_floats as u32,
                        },
                        groups(out_floats, 64)?,
                    )
                })?;
                slot
            }
        };
        let d_pre = range(d_pre_slot, out_floats);
        let d_in_slot = d_pre_slot.other();
        let d_in = match (l, &d_input) {
            (0, None) => None,
            (0, Some(d)) => Some(d.sub(0, 4 * in_floats)),
            _ => Some(range(d_in_slot, in_floats)),
        };
        let p = layer.param_count();
        match layer {
            Layer::Conv2d(c) => {
                let blocks = ConvBlocks::of(c);
                let partial = self.partial.range(0, 4 * n * p);
                rec.pass(&format!("nn layer {l} weight gradient"), |rec| {
                    let texels = texel_input(rec, &x) && texel_input(rec, &d_pre);
                    if let Some(kernel) = self.wgrad4[l].as_ref().filter(|_| texels) {
                        let total = n * blocks.weight_gradient4;
                        return rec.dispatch(
                            kernel,
                            &specs::NnConvWgrad4Bindings {
                                inp: x,
                                d_pre,
                                d_pre_floats: d_pre,
                                partial,
                            }
                            .for_kernel(kernel)?,
                            &self.conv_push(l, batch, total),
                            groups(total, 64)?,
                        );
                    }
                    rec.dispatch(
                        &self.conv_wgrad,
                        &specs::NnConvWgradBindings {
                            input: x,
                            d_pre,
                            partial,
                        }
                        .for_kernel(&self.conv_wgrad)?,
                        &self.conv_push(l, batch, n * blocks.weight_gradient),
                        groups(n * blocks.weight_gradient, 64)?,
                    )
                })?;
                rec.pass(&format!("nn layer {l} batch sum"), |rec| {
                    rec.dispatch(
                        &self.sum_rows,
                        &specs::NnSumRowsBindings {
                            rows: partial,
                            sums: d_params,
                        }
                        .for_kernel(&self.sum_rows)?,
                        &SumPush {
                            rows: batch,
                            cols: p as u32,
                            dst_offset: self.offsets[l] as u32,
                            pad: 0,
                        },
                        groups(p, 64)?,
                    )
                })?;
                if let Some(d_in) = d_in {
                    rec.pass(&format!("nn layer {l} input gradient"), |rec| {
                        let texels = texel_input(rec, &d_pre);
                        if let Some(kernel) = self.dinput4[l].as_ref().filter(|_| texels) {
                            let packed = self.record_pack(rec, l, batch, params, true)?;
                            let total = n * blocks.input_gradient4;
                            return rec.dispatch(
                                kernel,
                                &specs::NnConvDinput4Bindings {
                                    weights: packed,
                                    d_pre,
                                    d_input: d_in,
                                }
                                .for_kernel(kernel)?,
                                &self.conv_push(l, batch, total),
                                groups(total, 64)?,
                            );
                        }
                        rec.dispatch(
                            &self.conv_dinput,
                            &specs::NnConvDinputBindings {
                                params,
                                d_pre,
                                d_input: d_in,
                            }
                            .for_kernel(&self.conv_dinput)?,
                            &self.conv_push(l, batch, n * blocks.input_gradient),
                            groups(n * blocks.input_gradient, 64)?,
                        )
                    })?;
                }
            }
            Layer::Linear(_) => {
                let texels = self.texel_rows(rec, l, params, x);
                let blocks = LinearBlocks::of(layer, batch);
                rec.pass(
                    &format!("nn layer {l} weight gradient"),
                    |rec| match texels {
                        Some(_) => rec.dispatch(
                            &self.linear_wgrad4,
                            &specs::NnLinearWgrad4Bindings {
                                inp: x,
                                d_pre,
                                d_params,
                            }
                            .for_kernel(&self.linear_wgrad4)?,
                            &self.linear_push(l, batch, blocks.weight_gradient4),
                            groups(blocks.weight_gradient4, 64)?,
                        ),
                        None => rec.dispatch(
                            &self.linear_wgrad,
                            &specs::NnLinearWgradBindings {
                                input: x,
                                d_pre,
                                d_params,
                            }
                            .for_kernel(&self.linear_wgrad)?,
                            &self.linear_push(l, batch, blocks.weight_gradient),
                            groups(blocks.weight_gradient, 64)?,
                        ),
                    },
                )?;
                if let Some(d_in) = d_in {
                    rec.pass(
                        &format!("nn layer {l} input gradient"),
                        |rec| match texels {
                            Some((_, weights)) => rec.dispatch(
                                &self.linear_dinput4,
                                &specs::NnLinearDinput4Bindings {
                                    weights,
                                    d_pre,
                                    d_input: d_in,
                                }
                                .for_kernel(&self.linear_dinput4)?,
                                &self.linear_push(l, batch, blocks.input_gradient4),
                                groups(blocks.input_gradient4, 64)?,
                            ),
                            None => rec.dispatch(
                                &self.linear_dinput,
                                &specs::NnLinearDinputBindings {
                                    params,
                                    d_pre,
                                    d_input: d_in,
                                }
                                .for_kernel(&self.linear_dinput)?,
                                &self.linear_push(l, batch, blocks.input_gradient),
                                groups(blocks.input_gradient, 64)?,
                            ),
                        },
                    )?;
                }
            }
        }
        Ok(d_in_slot)
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
