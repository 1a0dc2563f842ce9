//! [`Sequential::new`]: a network's chain checked against the device's limits, its pipelines
//! and its buffers.

use super::{Sequential, packed_texels};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{Context, KernelVariants, MemoryKind, check_binding, check_texels};
use crate::nn::{Activation, Layer, param_offsets, validate_chain};
use crate::specs;

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
}
