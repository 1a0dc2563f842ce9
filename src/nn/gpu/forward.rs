//! [`Sequential::record_forward`]: every layer's output recorded into its buffer, by the texel
//! or the scalar kernels.

use super::{ConvBlocks, LinearBlocks, Sequential, texel_input};
use crate::error::Result;
use crate::gpu::{BufferRange, Recorder, groups};
use crate::nn::Layer;
use crate::specs;

impl Sequential {
    /// Records the forward of `batch` samples of `input` (`batch × input_len` floats) with
    /// `params` ([`Sequential::param_count`] floats): every layer's output into its buffer.
    ///
    /// [`Error::Input`](crate::Error::Input) for a batch over the capacity;
    /// [`Error::BufferTooSmall`](crate::Error::BufferTooSmall) for a range too small.
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
}
