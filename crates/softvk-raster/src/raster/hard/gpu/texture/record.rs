//! The recorded passes of [`TextureSampler`] over caller buffers: the mip levels, the forward
//! and the backward (its sort, runs, partial sums and reduce), with the push constants and
//! specialization constants they share.

use super::{
    Lookups, PARTIAL_BLOCK, TexLayout, TexMode, TexPush, TextureGradOutputs, TextureInputs,
    TextureSampler,
};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{BufferRange, Context, Recorder, groups};
use crate::primitives::sort::SortScratch;
use crate::raster::hard::gpu::device_buffer;
use crate::raster::hard::texture::{Boundary, Filter};
use crate::raster::specs;
/// The kernels' specialization constants of a mode: `[FILTER, BOUNDARY]`.
fn mode_constants(mode: TexMode) -> [u32; 2] {
    let filter = match mode.filter() {
        Filter::Nearest => 0,
        Filter::Linear => 1,
        Filter::LinearMipmapNearest => 2,
        Filter::LinearMipmapLinear => 3,
    };
    let boundary = match mode {
        TexMode::Flat(m) => match m.boundary {
            Boundary::Wrap => 0,
            Boundary::Clamp => 1,
            Boundary::Zero => 2,
        },
        TexMode::Cube(_) => 3,
    };
    [filter, boundary]
}

/// Texel entries a lookup gives the backward (`TAPS` in `kernels/raster/include/texture.glsl`).
fn taps(filter: Filter) -> u64 {
    match filter {
        Filter::Nearest => 1,
        Filter::Linear | Filter::LinearMipmapNearest => 4,
        Filter::LinearMipmapLinear => 8,
    }
}

/// The push constants of a call, checked: the grid against the stack, the sizes against the
/// kernels' 32-bit indices and the device's bindings.
pub(super) fn push_for(
    ctx: &Context,
    layout: &TexLayout,
    mode: TexMode,
    grid: &Lookups,
) -> Result<TexPush> {
    if grid.batch == 0 || grid.height == 0 || grid.width == 0 {
        return Err(Error::Input(format!(
            "texture: uv must have a positive size, not [{}, {}, {}, {}]",
            grid.batch,
            grid.height,
            grid.width,
            mode.uv_floats()
        )));
    }
    if mode.is_cube() {
        let cubes = layout.items / 6;
        if layout.width != layout.height || layout.items % 6 != 0 {
            return Err(Error::Input(format!(
                "texture: a cube map is [B, 6, S, S, C]: a stack of 6 B square faces, not {} of \
                 {}x{}",
                layout.items, layout.height, layout.width
            )));
        }
        if cubes != 1 && cubes != grid.batch {
            return Err(Error::Input(format!(
                "texture: tex has {cubes} minibatch items, uv {}: they must match, or tex have 1",
                grid.batch
            )));
        }
    } else if layout.items != 1 && layout.items != grid.batch {
        return Err(Error::Input(format!(
            "texture: tex has {} minibatch items, uv {}: they must match, or tex have 1",
            layout.items, grid.batch
        )));
    }
    if mode.filter().uses_mips() && !grid.uv_da && !grid.bias {
        return Err(Error::Input(
            "texture: the mipmap filter modes need uv_da or mip_level_bias".into(),
        ));
    }
    let points = grid.points();
    let limit = u64::from(ctx.info().limits.max_storage_buffer_range);
    let widest = (4 * mode.uv_da_floats() * points).max(4 * layout.floats());
    if widest > limit || points * taps(mode.filter()) > u64::from(u32::MAX) {
        return Err(Error::DeviceLimit {
            kind: LimitKind::StorageBinding,
            what: format!(
                "texture: {points} lookups into a stack of {} floats",
                layout.floats()
            ),
            need: widest,
            max: limit,
            device: ctx.info().name.clone(),
            hint: "sample fewer minibatch items at once or a smaller texture",
        });
    }
    Ok(TexPush {
        width: layout.width,
        height: layout.height,
        channels: layout.channels,
        tex_items: layout.items,
        levels: layout.levels,
        points: points as u32,
        item_points: grid.height * grid.width,
        has_uv_da: u32::from(grid.uv_da),
        has_bias: u32::from(grid.bias),
        level: 0,
        entries: 0,
        texels: layout.texels() as u32,
    })
}

/// Checks that the optional level inputs are bound exactly when the grid says so.
fn check_level_inputs(
    mode: TexMode,
    grid: &Lookups,
    uv_da: Option<&BufferRange<'_>>,
    bias: Option<&BufferRange<'_>>,
    what: &str,
) -> Result<()> {
    let points = grid.points();
    match (grid.uv_da, uv_da) {
        (true, Some(r)) => r.require(4 * mode.uv_da_floats() * points, what)?,
        (false, None) => {}
        _ => {
            return Err(Error::Misuse(format!(
                "texture: {what}: uv_da bound where the grid says {}",
                grid.uv_da
            )));
        }
    }
    match (grid.bias, bias) {
        (true, Some(r)) => r.require(4 * points, what)?,
        (false, None) => {}
        _ => {
            return Err(Error::Misuse(format!(
                "texture: {what}: mip_level_bias bound where the grid says {}",
                grid.bias
            )));
        }
    }
    Ok(())
}

impl TextureSampler {
    /// Records `texture_construct_mip` in place: levels 1 and below of `stack` from level 0.
    pub fn record_construct_mip(
        &self,
        rec: &mut Recorder<'_>,
        layout: &TexLayout,
        stack: BufferRange<'_>,
    ) -> Result<()> {
        stack.require(4 * layout.floats(), "texture stack")?;
        if layout.levels == 1 {
            return Ok(());
        }
        let kernel = rec.context().kernel(&specs::HARD_TEX_MIP, &[])?;
        let stack = stack.sub(0, 4 * layout.floats());
        rec.pass("texture mip levels", |rec| {
            for level in 1..layout.levels {
                let push = TexPush {
                    width: layout.width,
                    height: layout.height,
                    channels: layout.channels,
                    tex_items: layout.items,
                    levels: layout.levels,
                    level,
                    ..TexPush::default()
                };
                rec.dispatch(
                    &kernel,
                    &specs::HardTexMipBindings { tex: stack }.for_kernel(&kernel)?,
                    &push,
                    groups(layout.level_texels(level) * u64::from(layout.channels), 64)?,
                )?;
            }
            Ok(())
        })
    }

    /// Records `texture`: `out` (C f32 a lookup) from the stack at `inputs`.
    pub fn record_sample(
        &self,
        rec: &mut Recorder<'_>,
        layout: &TexLayout,
        mode: TexMode,
        grid: &Lookups,
        inputs: TextureInputs<'_>,
        out: BufferRange<'_>,
    ) -> Result<()> {
        let ctx = rec.context();
        let push = push_for(ctx, layout, mode, grid)?;
        let points = grid.points();
        inputs.stack.require(4 * layout.floats(), "texture stack")?;
        inputs
            .uv
            .require(4 * mode.uv_floats() * points, "texture uv")?;
        check_level_inputs(
            mode,
            grid,
            inputs.uv_da.as_ref(),
            inputs.bias.as_ref(),
            "texture",
        )?;
        let c = u64::from(layout.channels);
        out.require(4 * c * points, "texture output")?;
        let kernel = ctx.kernel(&specs::HARD_TEX, &mode_constants(mode))?;
        rec.pass("texture", |rec| {
            rec.dispatch(
                &kernel,
                &specs::HardTexBindings {
                    tex: inputs.stack.sub(0, 4 * layout.floats()),
                    uv: inputs.uv.sub(0, 4 * mode.uv_floats() * points),
                    uv_da: inputs.uv_da.unwrap_or(inputs.uv),
                    bias: inputs.bias.unwrap_or(inputs.uv),
                    out: out.sub(0, 4 * c * points),
                }
                .for_kernel(&kernel)?,
                &push,
                groups(points, 64)?,
            )
        })
    }

    /// Records `texture`'s backward for the output gradient `dy` (C f32 a lookup): every
    /// level's texel gradients into `grads.stack` and the lookups' own; `pyramid`: carry each
    /// level's gradient into the levels above it, as for a stack built by
    /// [`TextureSampler::record_construct_mip`] (level 0 then holds the texture's whole
    /// gradient).
    #[allow(clippy::too_many_arguments)]
    pub fn record_sample_grad(
        &mut self,
        rec: &mut Recorder<'_>,
        layout: &TexLayout,
        mode: TexMode,
        grid: &Lookups,
        inputs: TextureInputs<'_>,
        dy: BufferRange<'_>,
        grads: TextureGradOutputs<'_>,
        pyramid: bool,
    ) -> Result<()> {
        let ctx = rec.context();
        let mut push = push_for(ctx, layout, mode, grid)?;
        let points = grid.points();
        let c = u64::from(layout.channels);
        let floats = layout.floats();
        inputs.stack.require(4 * floats, "texture stack")?;
        inputs
            .uv
            .require(4 * mode.uv_floats() * points, "texture uv")?;
        check_level_inputs(
            mode,
            grid,
            inputs.uv_da.as_ref(),
            inputs.bias.as_ref(),
            "texture",
        )?;
        check_level_inputs(
            mode,
            grid,
            grads.uv_da.as_ref(),
            grads.bias.as_ref(),
            "texture gradients",
        )?;
        dy.require(4 * c * points, "the output's gradient")?;
        grads.stack.require(4 * floats, "the stack's gradient")?;
        grads
            .uv
            .require(4 * mode.uv_floats() * points, "the gradient of uv")?;
        let entries = points * taps(mode.filter());
        let texels = layout.texels();
        let limit = u64::from(ctx.info().limits.max_storage_buffer_range);
        if 4 * entries * c > limit || texels >= u64::from(u32::MAX) {
            return Err(Error::DeviceLimit {
                kind: LimitKind::StorageBinding,
                what: format!("texture backward: {entries} texel entries of {c} channels"),
                need: 4 * entries * c,
                max: limit,
                device: ctx.info().name.clone(),
                hint: "sample fewer minibatch items at once",
            });
        }
        let blocks = entries.div_ceil(PARTIAL_BLOCK);
        if let Some(cap) = ctx.info().shader_loop_limit() {
            if blocks > cap {
                return Err(Error::DeviceLimit {
                    kind: LimitKind::LoopIterations,
                    what: "texture backward: the blocks of one texel's entries".into(),
                    need: blocks,
                    max: cap,
                    device: ctx.info().name.clone(),
                    hint: "sample fewer lookups at once",
                });
            }
        }
        push.entries = entries as u32;
        let key_bits = 64 - texels.leading_zeros();
        let s = &mut self.scratch;
        device_buffer(ctx, &mut s.keys, "texture keys", 8 * entries)?;
        device_buffer(ctx, &mut s.values, "texture values", 4 * entries)?;
        device_buffer(ctx, &mut s.weights, "texture weights", 4 * entries)?;
        device_buffer(ctx, &mut s.partials, "texture partials", 4 * entries * c)?;
        device_buffer(ctx, &mut s.runs, "texture runs", 8 * texels)?;
        if s.sort.as_ref().is_none_or(|x| x.capacity() < entries) {
            s.sort = None;
            s.sort = Some(SortScratch::new(ctx, entries)?);
        }
        let constants = mode_constants(mode);
        let grad = ctx.kernel(&specs::HARD_TEX_GRAD, &constants)?;
        let runs = ctx.kernel(&specs::HARD_TEX_RUNS, &[])?;
        let partials = ctx.kernel(&specs::HARD_TEX_PARTIALS, &constants)?;
        let reduce = ctx.kernel(&specs::HARD_TEX_REDUCE, &[])?;
        let mip_grad = ctx.kernel(&specs::HARD_TEX_MIP_GRAD, &[])?;
        let s = &self.scratch;
        let keys = s.keys.as_ref().expect("made above");
        let values = s.values.as_ref().expect("made above");
        let weights = s
            .weights
            .as_ref()
            .expect("made above")
            .range(0, 4 * entries);
        let part = s
            .partials
            .as_ref()
            .expect("made above")
            .range(0, 4 * entries * c);
        let run_table = s.runs.as_ref().expect("made above").range(0, 8 * texels);
        let stack_grad = grads.stack.sub(0, 4 * floats);
        // Four top-level passes, so that each has its time: the entries, their sort, the sums,
        // the pyramid.
        rec.pass("texture backward entries", |rec| {
            rec.dispatch(
                &grad,
                &specs::HardTexGradBindings {
                    tex: inputs.stack.sub(0, 4 * floats),
                    uv: inputs.uv.sub(0, 4 * mode.uv_floats() * points),
                    uv_da: inputs.uv_da.unwrap_or(inputs.uv),
                    bias: inputs.bias.unwrap_or(inputs.uv),
                    dy: dy.sub(0, 4 * c * points),
                    grad_uv: grads.uv.sub(0, 4 * mode.uv_floats() * points),
                    grad_uv_da: grads.uv_da.unwrap_or(grads.uv),
                    grad_bias: grads.bias.unwrap_or(grads.uv),
                    keys: keys.range(0, 8 * entries),
                    values: values.range(0, 4 * entries),
                    weights,
                }
                .for_kernel(&grad)?,
                &push,
                groups(points, 64)?,
            )
        })?;
        rec.pass("texture backward sort", |rec| {
            self.sort.record(
                rec,
                s.sort.as_ref().expect("made above"),
                keys,
                values,
                entries,
                key_bits,
            )
        })?;
        rec.pass("texture backward sums", |rec| {
            rec.fill(run_table, 0);
            rec.dispatch(
                &runs,
                &specs::HardTexRunsBindings {
                    keys: keys.range(0, 8 * entries),
                    runs: run_table,
                }
                .for_kernel(&runs)?,
                &push,
                groups(entries, 64)?,
            )?;
            rec.dispatch(
                &partials,
                &specs::HardTexPartialsBindings {
                    keys: keys.range(0, 8 * entries),
                    values: values.range(0, 4 * entries),
                    weights,
                    dy: dy.sub(0, 4 * c * points),
                    partials: part,
                }
                .for_kernel(&partials)?,
                &push,
                groups(blocks * c, 64)?,
            )?;
            rec.dispatch(
                &reduce,
                &specs::HardTexReduceBindings {
                    runs: run_table,
                    partials: part,
                    grad_tex: stack_grad,
                }
                .for_kernel(&reduce)?,
                &push,
                groups(texels * c, 64)?,
            )
        })?;
        if !pyramid {
            return Ok(());
        }
        rec.pass("texture backward pyramid", |rec| {
            {
                for level in (0..layout.levels - 1).rev() {
                    rec.dispatch(
                        &mip_grad,
                        &specs::HardTexMipGradBindings {
                            grad_tex: stack_grad,
                        }
                        .for_kernel(&mip_grad)?,
                        &TexPush { level, ..push },
                        groups(layout.level_texels(level) * c, 64)?,
                    )?;
                }
            }
            Ok(())
        })
    }
}
