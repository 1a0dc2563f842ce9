//! Checks and sizes shared by the kernels' dispatches: a binding's and a grid's limits, and
//! where a kernel writes a gradient ([`GradOut`]).

use crate::error::{Error, LimitKind, Result};
use crate::gpu::{BufferRange, Context};

/// Where a kernel writes a gradient, and how: `out = weight · g`, or with `accumulate`,
/// `out += weight · g` (each element has one writer, so accumulating is deterministic).
#[derive(Clone, Copy)]
pub struct GradOut<'a> {
    /// The destination; it must hold at least as many floats as the gradient has.
    pub range: BufferRange<'a>,
    /// Factor applied to the gradient (a loss term's weight).
    pub weight: f32,
    /// Add to the destination instead of overwriting it.
    pub accumulate: bool,
}

impl<'a> GradOut<'a> {
    /// Overwrite `range` with the gradient (weight 1).
    pub fn write(range: BufferRange<'a>) -> Self {
        Self {
            range,
            weight: 1.0,
            accumulate: false,
        }
    }

    /// Add `weight ·` the gradient to what `range` holds.
    pub fn accumulate(range: BufferRange<'a>, weight: f32) -> Self {
        Self {
            range,
            weight,
            accumulate: true,
        }
    }

    /// The same destination with another weight.
    pub fn weighted(self, weight: f32) -> Self {
        Self { weight, ..self }
    }
}

/// Fails with [`Error::Input`] when `range` holds fewer than `floats` `f32`s.
pub fn check_floats(what: &str, range: &BufferRange<'_>, floats: u64) -> Result<()> {
    if range.size < 4 * floats {
        return Err(Error::Input(format!(
            "{what} (buffer `{}`): {} bytes hold fewer than the {floats} floats it needs",
            range.buffer.name(),
            range.size
        )));
    }
    Ok(())
}

/// [`Error::DeviceLimit`] of `kind` naming `what` when `need` is over the device's `max`.
fn check_limit(ctx: &Context, kind: LimitKind, what: &str, need: u64, max: u64) -> Result<()> {
    if need > max {
        return Err(Error::DeviceLimit {
            kind,
            what: what.to_string(),
            need,
            max,
            device: ctx.info().name.clone(),
            hint: "",
        });
    }
    Ok(())
}

/// [`Error::DeviceLimit`] when `bytes` do not fit one storage-buffer binding
/// (`maxStorageBufferRange`); the byte count (at least 4, so that empty problems still get a
/// bindable buffer).
pub fn check_binding(ctx: &Context, what: &str, bytes: u64) -> Result<u64> {
    let max = u64::from(ctx.info().limits.max_storage_buffer_range);
    check_limit(ctx, LimitKind::StorageBinding, what, bytes, max)?;
    Ok(bytes.max(4))
}

/// [`Error::DeviceLimit`] unless `bytes` (whole 16-byte texels) fit one texel-buffer binding
/// (`maxTexelBufferElements`); the texel count.
pub fn check_texels(ctx: &Context, what: &str, bytes: u64) -> Result<u64> {
    let texels = bytes.div_ceil(crate::gpu::TEXEL_BYTES);
    let max = u64::from(ctx.info().limits.max_texel_buffer_elements);
    check_limit(ctx, LimitKind::TexelBinding, what, texels, max)?;
    Ok(texels)
}

/// Workgroups of `size` invocations covering `n` items, as the `u32` a dispatch takes.
pub fn groups(n: u64, size: u32) -> Result<u32> {
    u32::try_from(n.div_ceil(u64::from(size)))
        .map_err(|_| Error::Limit(format!("{n} items need more than 2^32 workgroups")))
}
