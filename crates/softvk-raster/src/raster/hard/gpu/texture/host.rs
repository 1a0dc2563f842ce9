//! [`TextureSampler`]'s host-slice entry points: the checks of a host call's arrays, the
//! upload of the stack and lookups, and `construct_mip`, `sample` and `sample_grad`.

use super::record::push_for;
use super::{
    Levels, Lookup, Lookups, TexLayout, TexMode, TextureGradOutputs, TextureGrads32, TextureInputs,
    TextureSampler,
};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, MemoryKind, Recorder};
use crate::raster::hard::gpu::{device_buffer, get, host_buffer, layout_of, put};
use crate::raster::hard::texture::{Boundary, Filter, Mode};
/// Checks a host call's arrays against its layout and grid: lengths, and every value finite.
fn check_host(
    layout: &TexLayout,
    mode: TexMode,
    levels: Levels<'_>,
    lookup: &Lookup<'_>,
) -> Result<()> {
    let (stack, need, what) = match levels {
        Levels::Build(t) => (
            t,
            layout.level_texels(0) * u64::from(layout.channels),
            "tex",
        ),
        Levels::Built(t) | Levels::Given(t) => (t, layout.floats(), "the mip stack"),
    };
    if stack.len() as u64 != need {
        return Err(Error::Input(format!(
            "texture: {what} holds {} floats, the layout needs {need}",
            stack.len()
        )));
    }
    if let Some(i) = stack.iter().position(|v| !v.is_finite()) {
        let level = (1..layout.levels)
            .take_while(|&l| layout.level_offset(l) <= i as u64)
            .last()
            .unwrap_or(0);
        let name = if level == 0 {
            "tex".to_string()
        } else {
            format!("mip level {level}")
        };
        return Err(Error::Input(format!(
            "texture: {name} has a value that is not finite ({}) at float {}",
            stack[i],
            i as u64 - layout.level_offset(level)
        )));
    }
    let points = lookup.grid.points();
    let arrays = [
        ("uv", Some(lookup.uv), mode.uv_floats()),
        ("uv_da", lookup.uv_da, mode.uv_da_floats()),
        ("mip_level_bias", lookup.bias, 1),
    ];
    for (name, array, per) in arrays {
        let Some(a) = array else { continue };
        if a.len() as u64 != per * points {
            return Err(Error::Input(format!(
                "texture: {name} holds {} floats, the grid needs {}",
                a.len(),
                per * points
            )));
        }
        if let Some(i) = a.iter().position(|v| !v.is_finite()) {
            return Err(Error::Input(format!(
                "texture: {name} has a value that is not finite ({}) at lookup {}",
                a[i],
                i as u64 / per
            )));
        }
    }
    if lookup.grid.uv_da != lookup.uv_da.is_some() || lookup.grid.bias != lookup.bias.is_some() {
        return Err(Error::Misuse(
            "texture: the grid's level inputs differ from the arrays given".into(),
        ));
    }
    Ok(())
}

impl TextureSampler {
    /// Uploads a host call's stack and lookups (and `dy`): the input buffer's parts `[stack,
    /// uv, uv_da, bias, dy, total]`, and the stack copied to the device buffer, its mip levels
    /// built there for [`Levels::Build`].
    fn upload(
        &mut self,
        ctx: &Context,
        layout: &TexLayout,
        levels: Levels<'_>,
        lookup: &Lookup<'_>,
        dy: &[f32],
    ) -> Result<Vec<u64>> {
        let base = levels.floats();
        let at = layout_of(&[
            4 * base.len() as u64,
            4 * lookup.uv.len() as u64,
            4 * lookup.uv_da.map_or(0, <[f32]>::len) as u64,
            4 * lookup.bias.map_or(0, <[f32]>::len) as u64,
            4 * dy.len() as u64,
        ]);
        let input = host_buffer(
            ctx,
            &mut self.host.inputs,
            "texture inputs",
            at[5],
            MemoryKind::Upload,
        )?;
        let bytes = input
            .mapped_mut()
            .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
        put(bytes, at[0], base);
        put(bytes, at[1], lookup.uv);
        if let Some(d) = lookup.uv_da {
            put(bytes, at[2], d);
        }
        if let Some(b) = lookup.bias {
            put(bytes, at[3], b);
        }
        put(bytes, at[4], dy);
        device_buffer(ctx, &mut self.stack, "texture stack", 4 * layout.floats())?;
        Ok(at)
    }

    /// Records the stack's copy to the device buffer and, for [`Levels::Build`], its levels.
    fn record_stack(
        &self,
        rec: &mut Recorder<'_>,
        layout: &TexLayout,
        levels: Levels<'_>,
        input: &Buffer,
    ) -> Result<()> {
        let stack = self.stack.as_ref().expect("made by upload");
        let base = levels.floats();
        rec.copy(input, 0, stack, 0, 4 * base.len() as u64);
        if matches!(levels, Levels::Build(_)) {
            self.record_construct_mip(rec, layout, stack.range(0, 4 * layout.floats()))?;
        }
        Ok(())
    }

    /// `texture_construct_mip` on host slices: the whole stack of `layout` from its base
    /// `tex`. Waits for the device.
    pub fn construct_mip(
        &mut self,
        ctx: &Context,
        layout: &TexLayout,
        tex: &[f32],
    ) -> Result<Vec<f32>> {
        let grid = Lookups {
            batch: 1,
            height: 1,
            width: 1,
            uv_da: false,
            bias: false,
        };
        let lookup = Lookup {
            grid,
            uv: &[0.0, 0.0],
            uv_da: None,
            bias: None,
        };
        check_host(
            layout,
            TexMode::Flat(Mode {
                filter: Filter::Linear,
                boundary: Boundary::Wrap,
            }),
            Levels::Build(tex),
            &lookup,
        )?;
        self.upload(ctx, layout, Levels::Build(tex), &lookup, &[])?;
        let floats = layout.floats();
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "texture outputs",
            4 * floats,
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made by upload");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            self.submit(ctx, |this, rec| {
                this.record_stack(rec, layout, Levels::Build(tex), &input)?;
                let stack = this.stack.as_ref().expect("made by upload");
                rec.copy(stack, 0, &output, 0, 4 * floats);
                Ok(())
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut out = vec![0.0f32; floats as usize];
            get(bytes, 0, &mut out);
            Ok(out)
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }

    /// `texture` on host slices: `[B, h, w, C]`. Waits for the device.
    pub fn sample(
        &mut self,
        ctx: &Context,
        layout: &TexLayout,
        mode: TexMode,
        levels: Levels<'_>,
        lookup: &Lookup<'_>,
    ) -> Result<Vec<f32>> {
        check_host(layout, mode, levels, lookup)?;
        push_for(ctx, layout, mode, &lookup.grid)?;
        let at = self.upload(ctx, layout, levels, lookup, &[])?;
        let out_len = lookup.grid.points() * u64::from(layout.channels);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "texture outputs",
            4 * out_len,
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made by upload");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            self.submit(ctx, |this, rec| {
                this.record_stack(rec, layout, levels, &input)?;
                let stack = this.stack.as_ref().expect("made by upload");
                this.record_sample(
                    rec,
                    layout,
                    mode,
                    &lookup.grid,
                    host_inputs(stack, &input, &at, layout, mode, lookup),
                    output.range(0, 4 * out_len),
                )
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut out = vec![0.0f32; out_len as usize];
            get(bytes, 0, &mut out);
            Ok(out)
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }

    /// `texture`'s backward on host slices for the output gradient `dy` (`[B, h, w, C]`); but
    /// for [`Levels::Given`], the levels' gradients are carried into the texture's. Waits for
    /// the device.
    pub fn sample_grad(
        &mut self,
        ctx: &Context,
        layout: &TexLayout,
        mode: TexMode,
        levels: Levels<'_>,
        lookup: &Lookup<'_>,
        dy: &[f32],
    ) -> Result<TextureGrads32> {
        check_host(layout, mode, levels, lookup)?;
        push_for(ctx, layout, mode, &lookup.grid)?;
        let points = lookup.grid.points();
        let c = u64::from(layout.channels);
        if dy.len() as u64 != points * c {
            return Err(Error::Input(format!(
                "texture backward: the output's gradient holds {} floats, not {}",
                dy.len(),
                points * c
            )));
        }
        if let Some(i) = dy.iter().position(|v| !v.is_finite()) {
            return Err(Error::Input(format!(
                "texture backward: the output's gradient is not finite ({}) at float {i}",
                dy[i]
            )));
        }
        let at = self.upload(ctx, layout, levels, lookup, dy)?;
        let floats = layout.floats();
        let out_at = layout_of(&[
            4 * floats,
            4 * mode.uv_floats() * points,
            if lookup.grid.uv_da {
                4 * mode.uv_da_floats() * points
            } else {
                0
            },
            if lookup.grid.bias { 4 * points } else { 0 },
        ]);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "texture outputs",
            out_at[4],
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made by upload");
        let output = self.host.outputs.take().expect("made above");
        let pyramid = !matches!(levels, Levels::Given(_));
        let result = (|| {
            self.submit(ctx, |this, rec| {
                this.record_stack(rec, layout, levels, &input)?;
                let stack = this.stack.take().expect("made by upload");
                let result = this.record_sample_grad(
                    rec,
                    layout,
                    mode,
                    &lookup.grid,
                    host_inputs(&stack, &input, &at, layout, mode, lookup),
                    input.range(at[4], 4 * points * c),
                    TextureGradOutputs {
                        stack: output.range(out_at[0], 4 * floats),
                        uv: output.range(out_at[1], 4 * mode.uv_floats() * points),
                        uv_da: lookup
                            .grid
                            .uv_da
                            .then(|| output.range(out_at[2], 4 * mode.uv_da_floats() * points)),
                        bias: lookup
                            .grid
                            .bias
                            .then(|| output.range(out_at[3], 4 * points)),
                    },
                    pyramid,
                );
                this.stack = Some(stack);
                result
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut g = TextureGrads32 {
                stack: vec![0.0; floats as usize],
                uv: vec![0.0; (mode.uv_floats() * points) as usize],
                uv_da: vec![
                    0.0;
                    if lookup.grid.uv_da {
                        (mode.uv_da_floats() * points) as usize
                    } else {
                        0
                    }
                ],
                bias: vec![0.0; if lookup.grid.bias { points as usize } else { 0 }],
            };
            get(bytes, out_at[0], &mut g.stack);
            get(bytes, out_at[1], &mut g.uv);
            get(bytes, out_at[2], &mut g.uv_da);
            get(bytes, out_at[3], &mut g.bias);
            Ok(g)
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }
}

/// The record-level inputs of a host call: the device stack and the uploaded lookups.
fn host_inputs<'a>(
    stack: &'a Buffer,
    input: &'a Buffer,
    at: &[u64],
    layout: &TexLayout,
    mode: TexMode,
    lookup: &Lookup<'_>,
) -> TextureInputs<'a> {
    let points = lookup.grid.points();
    TextureInputs {
        stack: stack.range(0, 4 * layout.floats()),
        uv: input.range(at[1], 4 * mode.uv_floats() * points),
        uv_da: lookup
            .grid
            .uv_da
            .then(|| input.range(at[2], 4 * mode.uv_da_floats() * points)),
        bias: lookup.grid.bias.then(|| input.range(at[3], 4 * points)),
    }
}
