//! [`Sequential::record_backward`]: the gradients to the parameters and the input, layer by
//! layer from the last, through two ping-pong scratch buffers.

use super::{ActPush, ConvBlocks, LinearBlocks, Sequential, SumPush, texel_input};
use crate::error::Result;
use crate::gpu::{BufferRange, Recorder, groups};
use crate::nn::Layer;
use crate::specs;

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

impl Sequential {
    /// Records the backward of the last recorded forward (same `params`, `input` and `batch`;
    /// it reads the layers' outputs): from `d_output` = dL/d(final output)
    /// (`batch × output_len` floats), writes dL/d(params) into `d_params`
    /// ([`Sequential::param_count`] floats, overwritten) and, when given, dL/d(input) into
    /// `d_input` (`batch × input_len` floats; the first layer's input gradient is skipped
    /// without it).
    ///
    /// [`Error::Input`](crate::Error::Input) for a batch over the capacity;
    /// [`Error::BufferTooSmall`](crate::Error::BufferTooSmall) for a range too small.
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
}
