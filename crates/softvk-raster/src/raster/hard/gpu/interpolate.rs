//! nvdiffrast's `interpolate` on [`HardRasterizer`], forward and backward: its plan, the
//! recorded passes over caller buffers and the host-slice entry points.

use super::{
    HardPlan, HardPush, HardRasterizer, InterpolateGrads32, get, host_buffer, layout_of, put,
    vertex_lists,
};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{BufferRange, Context, MemoryKind, Recorder, groups};
use crate::raster::hard::reference::AttrLayout;
use crate::raster::hard::{Shape, Topology};
use crate::raster::specs;

impl HardRasterizer {
    /// The plan `interpolate` reduces over: `rast [B, H, W, 4]`'s ids are triangles of `tri`
    /// (global in range mode), so every minibatch item owns every triangle.
    fn interpolate_plan(
        ctx: &Context,
        layout: AttrLayout,
        rast_len: usize,
        tri: &[[u32; 3]],
        resolution: [u32; 2],
    ) -> Result<HardPlan> {
        let [height, width] = resolution;
        let pixels = u64::from(width) * u64::from(height);
        if pixels == 0 || rast_len as u64 % (4 * pixels) != 0 || rast_len == 0 {
            return Err(Error::Input(format!(
                "interpolate: rast holds {rast_len} floats, not [B, {height}, {width}, 4]"
            )));
        }
        let batch = (rast_len as u64 / (4 * pixels)) as u32;
        if let Some((t, _)) = tri
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v >= layout.vertex_count))
        {
            return Err(Error::Input(format!(
                "interpolate: triangle {t} has a vertex index outside the {} attribute rows",
                layout.vertex_count
            )));
        }
        let shape = Shape {
            width,
            height,
            vertex_count: layout.vertex_count,
            triangle_count: tri.len() as u32,
            topology: Topology::Instanced { batch },
        };
        let mut plan = HardPlan::new(ctx, &shape)?;
        plan.push.instanced = u32::from(layout.per_item);
        plan.push.attr_count = layout.attr_count;
        Ok(plan)
    }

    /// Records `interpolate` over caller buffers: `out` (A f32 a pixel) and, with `diff_count`
    /// differentiated attributes (`diff`: their indices, u32) and `rast_db`, `out_da` (2N f32 a
    /// pixel). `plan` as [`HardRasterizer::rasterize`] made it for `rast`, with `layout`'s
    /// attributes.
    #[allow(clippy::too_many_arguments)]
    pub fn record_interpolate(
        &self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        layout: AttrLayout,
        attr: BufferRange<'_>,
        tri: BufferRange<'_>,
        rast: BufferRange<'_>,
        rast_db: Option<BufferRange<'_>>,
        diff: (BufferRange<'_>, u32),
        out: BufferRange<'_>,
        out_da: Option<BufferRange<'_>>,
    ) -> Result<()> {
        let pixels = plan.pixels();
        let a = u64::from(layout.attr_count);
        let n = if rast_db.is_some() { diff.1 } else { 0 };
        rast.require(16 * pixels, "rast")?;
        out.require(4 * a * pixels, "interpolate output")?;
        if n > 0 {
            out_da
                .as_ref()
                .ok_or_else(|| Error::Misuse("interpolate: out_da is needed".into()))?
                .require(8 * u64::from(n) * pixels, "interpolate derivatives")?;
        }
        let push = HardPush {
            instanced: u32::from(layout.per_item),
            attr_count: layout.attr_count,
            diff_count: n,
            ..plan.push
        };
        rec.pass("hard interpolate", |rec| {
            rec.dispatch(
                &self.interp,
                &specs::HardInterpBindings {
                    attr,
                    tri,
                    rast: rast.sub(0, 16 * pixels),
                    rast_db: rast_db.unwrap_or(rast).sub(0, 16 * pixels),
                    diff: diff.0,
                    out: out.sub(0, (4 * a * pixels).max(4)),
                    out_da: out_da.unwrap_or(out),
                }
                .for_kernel(&self.interp)?,
                &push,
                groups(pixels, 64)?,
            )
        })
    }

    /// `interpolate` on host slices: `(out [B, H, W, A], out_da [B, H, W, 2N])` for `rast` at
    /// `resolution` `[H, W]`. Waits for the device.
    #[allow(clippy::too_many_arguments)]
    pub fn interpolate(
        &mut self,
        ctx: &Context,
        attr: &[f32],
        layout: AttrLayout,
        rast: &[f32],
        tri: &[[u32; 3]],
        resolution: [u32; 2],
        rast_db: Option<&[f32]>,
        diff: &[u32],
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        let plan = Self::interpolate_plan(ctx, layout, rast.len(), tri, resolution)?;
        check_attr(attr, layout, &plan, rast_db, diff)?;
        let pixels = plan.pixels();
        let a = u64::from(layout.attr_count);
        let n = if rast_db.is_some() {
            diff.len() as u64
        } else {
            0
        };
        let at = layout_of(&[
            4 * attr.len() as u64,
            12 * tri.len() as u64,
            16 * pixels,
            16 * pixels,
            4 * diff.len() as u64,
        ]);
        let input = host_buffer(
            ctx,
            &mut self.host.inputs,
            "hard inputs",
            at[5],
            MemoryKind::Upload,
        )?;
        {
            let bytes = input
                .mapped_mut()
                .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
            put(bytes, at[0], attr);
            put(bytes, at[1], tri);
            put(bytes, at[2], rast);
            if let Some(d) = rast_db {
                put(bytes, at[3], d);
            }
            put(bytes, at[4], diff);
        }
        let out_at = layout_of(&[4 * a * pixels, 8 * n * pixels]);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "hard outputs",
            out_at[2],
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made above");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            self.submit(ctx, |s, rec| {
                s.record_interpolate(
                    rec,
                    &plan,
                    layout,
                    input.range(at[0], (4 * attr.len() as u64).max(4)),
                    input.range(at[1], (12 * tri.len() as u64).max(4)),
                    input.range(at[2], 16 * pixels),
                    rast_db.map(|_| input.range(at[3], 16 * pixels)),
                    (
                        input.range(at[4], (4 * diff.len() as u64).max(4)),
                        diff.len() as u32,
                    ),
                    output.range(out_at[0], (4 * a * pixels).max(4)),
                    (n > 0).then(|| output.range(out_at[1], 8 * n * pixels)),
                )
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut out = vec![0.0f32; (a * pixels) as usize];
            let mut out_da = vec![0.0f32; (2 * n * pixels) as usize];
            get(bytes, out_at[0], &mut out);
            get(bytes, out_at[1], &mut out_da);
            Ok((out, out_da))
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }

    /// Records `interpolate`'s backward over caller buffers, after
    /// [`HardRasterizer::record_visible_tiles`] (grow 0) and [`HardRasterizer::read_slots`] for
    /// the same `rast` (with `ranges` `(0, T)` per minibatch item): the gradients of `attr` (its
    /// rows, over [`vertex_lists`] with `layout.per_item`), of `rast` and of `rast_db` (with
    /// `dda`, the upstream gradient of `out_da`).
    #[allow(clippy::too_many_arguments)]
    pub fn record_interpolate_grad(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        layout: AttrLayout,
        bufs: InterpolateGradBuffers<'_>,
        lists: (BufferRange<'_>, BufferRange<'_>),
        grad_attr: BufferRange<'_>,
        grad_rast: BufferRange<'_>,
        grad_rast_db: BufferRange<'_>,
    ) -> Result<()> {
        let ctx = rec.context();
        let pixels = plan.pixels();
        let a = layout.attr_count;
        let n = if bufs.rast_db.is_some() && bufs.dda.is_some() {
            bufs.diff.1
        } else {
            0
        };
        if u64::from(a) * 64 * (1 + u64::from(n))
            > ctx.info().shader_loop_limit().unwrap_or(u64::MAX)
        {
            return Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                what: "interpolate backward: the attributes of one tile".into(),
                need: u64::from(a) * 64 * (1 + u64::from(n)),
                max: ctx.info().shader_loop_limit().unwrap_or(u64::MAX),
                device: ctx.info().name.clone(),
                hint: "interpolate fewer attributes at once",
            });
        }
        let push = self.grad_scratch(ctx, plan, 3 * a, 0, "interpolate backward")?;
        let push = HardPush {
            instanced: u32::from(layout.per_item),
            attr_count: a,
            diff_count: n,
            ..push
        };
        let rows = if layout.per_item {
            plan.ranges.len() as u32
        } else {
            1
        } * layout.vertex_count;
        grad_rast.require(16 * pixels, "the gradient of rast")?;
        grad_rast_db.require(16 * pixels, "the gradient of rast_db")?;
        let g = &self.grads;
        let items = u64::from(push.items);
        rec.pass("hard interpolate backward", |rec| {
            rec.dispatch(
                &self.interp_pixel_grad,
                &specs::HardInterpPixelGradBindings {
                    attr: bufs.attr,
                    tri: bufs.tri,
                    rast: bufs.rast.sub(0, 16 * pixels),
                    diff: bufs.diff.0,
                    dy: bufs.dy,
                    dda: bufs.dda.unwrap_or(bufs.dy),
                    grad_rast: grad_rast.sub(0, 16 * pixels),
                    grad_rast_db: grad_rast_db.sub(0, 16 * pixels),
                }
                .for_kernel(&self.interp_pixel_grad)?,
                &push,
                groups(pixels, 64)?,
            )?;
            if push.slots > 0 {
                rec.dispatch(
                    &self.interp_grad,
                    &specs::HardInterpGradBindings {
                        ranges: bufs.ranges,
                        rast: bufs.rast.sub(0, 16 * pixels),
                        rast_db: bufs.rast_db.unwrap_or(bufs.rast).sub(0, 16 * pixels),
                        diff: bufs.diff.0,
                        dy: bufs.dy,
                        dda: bufs.dda.unwrap_or(bufs.dy),
                        boxes: g.boxes.as_ref().expect("made").range(0, 16 * items),
                        offsets: g.offsets.as_ref().expect("made").range(0, 4 * items),
                        partials: g
                            .partials
                            .as_ref()
                            .expect("reserved")
                            .range(0, 12 * u64::from(a) * u64::from(push.slots)),
                    }
                    .for_kernel(&self.interp_grad)?,
                    &push,
                    groups(u64::from(push.slots), 64)?,
                )?;
            }
            self.record_reduce_gather(rec, &push, rows, lists, grad_attr)
        })
    }

    /// The backward of [`HardRasterizer::interpolate`] on host slices (`dy [B, H, W, A]`, `dda
    /// [B, H, W, 2N]`). Waits for the device.
    #[allow(clippy::too_many_arguments)]
    pub fn interpolate_grad(
        &mut self,
        ctx: &Context,
        attr: &[f32],
        layout: AttrLayout,
        rast: &[f32],
        tri: &[[u32; 3]],
        resolution: [u32; 2],
        rast_db: Option<&[f32]>,
        diff: &[u32],
        dy: &[f32],
        dda: Option<&[f32]>,
    ) -> Result<InterpolateGrads32> {
        let plan = Self::interpolate_plan(ctx, layout, rast.len(), tri, resolution)?;
        check_attr(attr, layout, &plan, rast_db, diff)?;
        let pixels = plan.pixels();
        let a = u64::from(layout.attr_count);
        let n = diff.len() as u64;
        if dy.len() as u64 != a * pixels {
            return Err(Error::Input(format!(
                "interpolate backward: the output's gradient holds {} floats, not {}",
                dy.len(),
                a * pixels
            )));
        }
        let dda = dda.filter(|_| rast_db.is_some() && n > 0);
        if let Some(d) = dda {
            if d.len() as u64 != 2 * n * pixels {
                return Err(Error::Input(format!(
                    "interpolate backward: the derivatives' gradient holds {} floats, not {}",
                    d.len(),
                    2 * n * pixels
                )));
            }
        }
        let (row_offsets, row_entries) = vertex_lists(&plan, tri, layout.per_item);
        let at = layout_of(&[
            4 * attr.len() as u64,
            12 * tri.len() as u64,
            8 * plan.ranges.len() as u64,
            16 * pixels,
            16 * pixels,
            4 * n,
            4 * a * pixels,
            8 * n * pixels,
            4 * row_offsets.len() as u64,
            4 * row_entries.len() as u64,
        ]);
        let input = host_buffer(
            ctx,
            &mut self.host.inputs,
            "hard inputs",
            at[10],
            MemoryKind::Upload,
        )?;
        {
            let bytes = input
                .mapped_mut()
                .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
            put(bytes, at[0], attr);
            put(bytes, at[1], tri);
            put(bytes, at[2], &plan.ranges);
            put(bytes, at[3], rast);
            if let Some(d) = rast_db {
                put(bytes, at[4], d);
            }
            put(bytes, at[5], diff);
            put(bytes, at[6], dy);
            if let Some(d) = dda {
                put(bytes, at[7], d);
            }
            put(bytes, at[8], &row_offsets);
            put(bytes, at[9], &row_entries);
        }
        let out_at = layout_of(&[4 * attr.len() as u64, 16 * pixels, 16 * pixels]);
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "hard outputs",
            out_at[3],
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made above");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            let rast_r = input.range(at[3], 16 * pixels);
            let ranges = input.range(at[2], 8 * plan.ranges.len() as u64);
            self.submit(ctx, |s, rec| {
                s.record_visible_tiles(rec, &plan, rast_r, ranges, 0)
            })?;
            self.read_slots(ctx)?;
            let bufs = InterpolateGradBuffers {
                attr: input.range(at[0], (4 * attr.len() as u64).max(4)),
                tri: input.range(at[1], (12 * tri.len() as u64).max(4)),
                ranges,
                rast: rast_r,
                rast_db: rast_db.map(|_| input.range(at[4], 16 * pixels)),
                diff: (input.range(at[5], (4 * n).max(4)), n as u32),
                dy: input.range(at[6], (4 * a * pixels).max(4)),
                dda: dda.map(|_| input.range(at[7], 8 * n * pixels)),
            };
            let lists = (
                input.range(at[8], 4 * row_offsets.len() as u64),
                input.range(at[9], (4 * row_entries.len() as u64).max(4)),
            );
            self.submit(ctx, |s, rec| {
                s.record_interpolate_grad(
                    rec,
                    &plan,
                    layout,
                    bufs,
                    lists,
                    output.range(out_at[0], (4 * attr.len() as u64).max(4)),
                    output.range(out_at[1], 16 * pixels),
                    output.range(out_at[2], 16 * pixels),
                )
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut g = InterpolateGrads32 {
                attr: vec![0.0; attr.len()],
                rast: vec![0.0; (4 * pixels) as usize],
                rast_db: vec![0.0; (4 * pixels) as usize],
            };
            get(bytes, out_at[0], &mut g.attr);
            get(bytes, out_at[1], &mut g.rast);
            get(bytes, out_at[2], &mut g.rast_db);
            Ok(g)
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }
}

/// The caller buffers `interpolate`'s backward reads.
#[derive(Clone, Copy)]
pub struct InterpolateGradBuffers<'a> {
    /// f32 attributes.
    pub attr: BufferRange<'a>,
    /// u32 triangles.
    pub tri: BufferRange<'a>,
    /// `(0, T)` per minibatch item.
    pub ranges: BufferRange<'a>,
    /// `[B, H, W, 4]`.
    pub rast: BufferRange<'a>,
    /// `[B, H, W, 4]`, when derivatives were asked for.
    pub rast_db: Option<BufferRange<'a>>,
    /// The differentiated attributes' indices (u32) and their count.
    pub diff: (BufferRange<'a>, u32),
    /// The output's gradient, A f32 a pixel.
    pub dy: BufferRange<'a>,
    /// The derivatives' gradient, 2N f32 a pixel.
    pub dda: Option<BufferRange<'a>>,
}

/// Checks `interpolate`'s arrays against its layout and plan.
fn check_attr(
    attr: &[f32],
    layout: AttrLayout,
    plan: &HardPlan,
    rast_db: Option<&[f32]>,
    diff: &[u32],
) -> Result<()> {
    let sets = if layout.per_item {
        plan.ranges.len()
    } else {
        1
    };
    let need = sets * layout.vertex_count as usize * layout.attr_count as usize;
    if attr.len() != need || layout.attr_count == 0 {
        return Err(Error::Input(format!(
            "interpolate: attr holds {} floats, the layout needs {need} ({sets} × {} × {})",
            attr.len(),
            layout.vertex_count,
            layout.attr_count
        )));
    }
    if let Some(i) = attr.iter().position(|v| !v.is_finite()) {
        return Err(Error::Input(format!(
            "interpolate: attribute {} of vertex row {} is not finite",
            i % layout.attr_count as usize,
            i / layout.attr_count as usize
        )));
    }
    if let Some(d) = rast_db {
        if d.len() as u64 != 4 * plan.pixels() {
            return Err(Error::Input(format!(
                "interpolate: rast_db holds {} floats, rast {}",
                d.len(),
                4 * plan.pixels()
            )));
        }
    }
    if let Some(&j) = diff.iter().find(|&&j| j >= layout.attr_count) {
        return Err(Error::Input(format!(
            "interpolate: diff_attrs names attribute {j} of {}",
            layout.attr_count
        )));
    }
    Ok(())
}
