//! [`TrainedParams`]: a trainer's parameters, their gradient and Adam's moments on the GPU, and
//! their packed host form.

use crate::error::{Error, Result};
use crate::fit::{Adam, AdamOptions};
use crate::gpu::{Buffer, Context, MemoryKind, Recorder};

/// A trainer's parameters, their gradient and Adam over them, in buffers that may pad between
/// packed ranges (the conditioned field keeps its field's part at a bindable offset): the values
/// as a model file holds them are the ranges, one after another.
pub struct TrainedParams {
    pub(crate) params: Buffer,
    pub(crate) d_params: Buffer,
    pub(crate) adam: Adam,
    /// `(offset, count)` in floats of each packed range, in order.
    ranges: Vec<(u64, u64)>,
}

impl TrainedParams {
    /// `padded` (the buffers' layout) uploaded, the gradient zeroed, Adam's moments reset.
    pub(crate) fn new(
        ctx: &Context,
        name: &str,
        padded: &[f32],
        ranges: Vec<(u64, u64)>,
        adam: AdamOptions,
    ) -> Result<Self> {
        let n = padded.len() as u64;
        let trained = Self {
            params: ctx.upload_buffer(&format!("{name} params"), padded)?,
            d_params: ctx.create_buffer(
                &format!("{name} d_params"),
                4 * n.max(1),
                MemoryKind::Device,
            )?,
            adam: Adam::new(ctx, n, adam)?,
            ranges,
        };
        ctx.submit_and_wait(|rec| {
            rec.fill(trained.d_params.whole(), 0);
            trained.adam.record_reset(rec);
            Ok(())
        })?;
        Ok(trained)
    }

    /// Packed values in all.
    fn len(&self) -> usize {
        self.ranges.iter().map(|r| r.1 as usize).sum()
    }

    /// The packed values of one of the buffers.
    fn read(&self, ctx: &Context, buffer: &Buffer) -> Result<Vec<f32>> {
        let end = self.ranges.iter().map(|r| r.0 + r.1).max().unwrap_or(0);
        let all: Vec<f32> = ctx.read_buffer(buffer, 0, end as usize)?;
        Ok(self
            .ranges
            .iter()
            .flat_map(|&(at, n)| all[at as usize..(at + n) as usize].iter().copied())
            .collect())
    }

    /// Writes packed values into one of the buffers.
    fn write(&self, ctx: &Context, buffer: &Buffer, packed: &[f32]) -> Result<()> {
        if packed.len() != self.len() {
            return Err(Error::Input(format!(
                "{} values for a network of {}",
                packed.len(),
                self.len()
            )));
        }
        let mut from = 0;
        for &(at, n) in &self.ranges {
            ctx.write_buffer(buffer, 4 * at, &packed[from..from + n as usize])?;
            from += n as usize;
        }
        Ok(())
    }

    /// The parameters now (packed).
    pub fn read_params(&self, ctx: &Context) -> Result<Vec<f32>> {
        self.read(ctx, &self.params)
    }

    /// Replaces the parameters (packed, finite).
    pub fn write_params(&self, ctx: &Context, params: &[f32]) -> Result<()> {
        if let Some(i) = params.iter().position(|p| !p.is_finite()) {
            return Err(Error::Input(format!("parameter {i} is not finite")));
        }
        self.write(ctx, &self.params, params)
    }

    /// dL/d(params) of the last iteration run (packed).
    pub fn read_gradient(&self, ctx: &Context) -> Result<Vec<f32>> {
        self.read(ctx, &self.d_params)
    }

    /// Adam's moments now (first, second; packed).
    pub fn read_moments(&self, ctx: &Context) -> Result<(Vec<f32>, Vec<f32>)> {
        let (m, v) = self.adam.moments();
        Ok((self.read(ctx, m)?, self.read(ctx, v)?))
    }

    /// Sets Adam's moments (a resumed run; packed).
    pub fn write_moments(&self, ctx: &Context, m: &[f32], v: &[f32]) -> Result<()> {
        let (mb, vb) = self.adam.moments();
        self.write(ctx, mb, m)?;
        self.write(ctx, vb, v)
    }

    /// Records iteration `it`'s Adam step at learning rate `lr`.
    pub(crate) fn record_step(&self, rec: &mut Recorder<'_>, it: u32, lr: f64) -> Result<()> {
        rec.pass("adam", |rec| {
            self.adam
                .record_step_lr(rec, self.params.whole(), self.d_params.whole(), it, lr)
        })
    }
}
