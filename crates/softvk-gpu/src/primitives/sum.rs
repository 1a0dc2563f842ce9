//! The strided sum that finishes every fit loss (`kernels/gpu/sum/fit_sum.comp`): one workgroup per
//! component, a fixed order, no atomics.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::gpu::{BufferRange, Context, Kernel, Recorder, specs};

/// Push constants of `fit_sum.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub struct SumPush {
    /// Terms per component.
    pub n: u32,
    /// Floats between consecutive terms.
    pub stride: u32,
    /// Float offset of component 0's first term.
    pub offset: u32,
    /// Output float index of component 0.
    pub out_index: u32,
    /// Factor of the sum.
    pub scale: f32,
    /// Added to the scaled sum.
    pub bias: f32,
}

/// `fit_sum.comp`, made once per owner.
pub struct Sum {
    kernel: Arc<Kernel>,
}

impl Sum {
    /// The kernel, from the context's cache.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            kernel: ctx.kernel(&specs::FIT_SUM, &[])?,
        })
    }

    /// Records `outputs[out_index + k] = bias + scale · Σ_i values[i·stride + offset + k]` for
    /// each of `components` components.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        values: BufferRange<'_>,
        outputs: BufferRange<'_>,
        push: SumPush,
        components: u32,
    ) -> Result<()> {
        let bindings = specs::FitSumBindings { values, outputs };
        rec.dispatch(
            &self.kernel,
            &bindings.for_kernel(&self.kernel)?,
            &push,
            components,
        )
    }
}
