//! The analytic shapes' kernels (`field_shape_eval`, `field_shape_grad`); the maths is in
//! [`super::shape`].

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::shape::Shape;
use super::{FIELD_CHUNK, SumChunks};
use crate::error::Result;
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::specs;

/// Points per backward batch.
pub(crate) const SHAPE_BATCH: u32 = 1 << 16;

/// Push constants of both shape kernels.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ShapePush {
    kind: u32,
    n: u32,
    sharpness: f32,
    param_count: u32,
    chunks: u32,
    pad: [u32; 3],
}

pub(crate) struct ShapeGpu {
    code: u32,
    param_count: u32,
    sharpness: f32,
    eval: Arc<Kernel>,
    grad: Arc<Kernel>,
    partial: Buffer,
}

impl ShapeGpu {
    pub fn new(ctx: &Context, shape: &Shape, sharpness: f64) -> Result<Self> {
        let p = shape.param_count() as u64;
        Ok(Self {
            code: shape.code(),
            param_count: p as u32,
            sharpness: sharpness as f32,
            eval: ctx.kernel(&specs::FIELD_SHAPE_EVAL, &[])?,
            grad: ctx.kernel(&specs::FIELD_SHAPE_GRAD, &[])?,
            partial: ctx.create_buffer(
                "shape field chunk partials",
                4 * p * u64::from(SHAPE_BATCH / FIELD_CHUNK),
                MemoryKind::Device,
            )?,
        })
    }

    fn push(&self, n: u32, chunks: u32) -> ShapePush {
        ShapePush {
            kind: self.code,
            n,
            sharpness: self.sharpness,
            param_count: self.param_count,
            chunks,
            pad: [0; 3],
        }
    }

    pub fn record_eval(
        &self,
        rec: &mut Recorder<'_>,
        params: BufferRange<'_>,
        points: BufferRange<'_>,
        n: u32,
        phi: BufferRange<'_>,
    ) -> Result<()> {
        rec.dispatch(
            &self.eval,
            &specs::FieldShapeEvalBindings {
                params,
                points,
                phi,
            }
            .for_kernel(&self.eval)?,
            &self.push(n, 0),
            n.div_ceil(64),
        )
    }

    /// One batch of at most [`SHAPE_BATCH`] points.
    #[allow(clippy::too_many_arguments)]
    pub fn record_backward_batch(
        &self,
        rec: &mut Recorder<'_>,
        sum: &SumChunks,
        params: BufferRange<'_>,
        points: BufferRange<'_>,
        n: u32,
        d_phi: BufferRange<'_>,
        d_params: BufferRange<'_>,
        accumulate: bool,
    ) -> Result<()> {
        let chunks = n.div_ceil(FIELD_CHUNK);
        let p = u64::from(self.param_count);
        let partial = self.partial.range(0, 4 * p * u64::from(chunks));
        rec.dispatch(
            &self.grad,
            &specs::FieldShapeGradBindings {
                params,
                points,
                d_phi,
                partial,
            }
            .for_kernel(&self.grad)?,
            &self.push(n, chunks),
            super::groups(p * u64::from(chunks), 64)?,
        )?;
        sum.record(rec, partial, d_params, self.param_count, chunks, accumulate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_struct_matches_the_kernels_layout() {
        let size = std::mem::size_of::<ShapePush>() as u32;
        assert_eq!(size, specs::FIELD_SHAPE_EVAL.push_constant_size);
        assert_eq!(size, specs::FIELD_SHAPE_GRAD.push_constant_size);
        assert_eq!(specs::FIELD_SHAPE_GRAD.bindings.len(), 4);
    }
}
