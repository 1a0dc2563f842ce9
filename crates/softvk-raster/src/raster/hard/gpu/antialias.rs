//! `antialias` on the GPU: nvdiffrast's analytic antialiasing, forward and backward, equal to
//! the f64 twin [`crate::raster::hard::antialias`] (whose module docs give every rule) up to f32.
//!
//! The topology ([`TopologyHash`]) is built on the host and handed to the kernels as a table:
//! per triangle and edge `k` (opposite vertex `k`), the vertex across it, or none
//! ([`HardRasterizer::antialias_topology`]). Then, over buffers the caller owns:
//!
//! 1. **Work list** (`kernels/raster/hard/hard_antialias_pairs.comp`): per pixel the decisions of its
//!    right pair and its next-row pair (triangle, edge, silhouette test, crossing, slack, clamp,
//!    `α`), as the twin's `find_edge_pairs` takes them, in f32 (scratch the rasterizer owns).
//! 2. **Forward** (`hard_antialias.comp`): per (pixel, channel) the colour plus the blends that
//!    target it, in the twin's global pair order ([`HardRasterizer::record_antialias`]).
//! 3. **Backward** ([`HardRasterizer::record_antialias_tiles`], then
//!    [`HardRasterizer::read_slots`], then [`HardRasterizer::record_antialias_grad`]): the colour
//!    gradient per (pixel, channel) in the same order (`hard_antialias_grad_color.comp`); the
//!    position gradient through the rasterizer backward's fixed-order reduction
//!    (`kernels/raster/include/hard_grads.glsl`) with boxes widened by one pixel, its slot kernel
//!    `hard_antialias_grad.comp`, then the reduce and the vertex lists' gather
//!    ([`super::vertex_lists`]), then `pos_gradient_boost` (f32, rounded once on the host) times
//!    each float (`hard_antialias_scale.comp`, skipped for a boost of 1).
//!
//! No float atomics anywhere: the same bits on every run, whatever the workgroup shape. The plan
//! ([`HardPlan::for_antialias`]) gives every minibatch item all the triangles (range table
//! `[0, T]` per item), so any id a `rast` holds has its item.

use std::sync::Arc;

use super::{
    AntialiasArgs, HardInputs, HardPlan, HardPush, HardRasterizer, device_buffer, get, host_buffer,
    layout_of, put, vertex_lists,
};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder, groups};
use crate::raster::hard::antialias::TopologyHash;
use crate::raster::hard::{Shape, Topology};
use crate::raster::specs;

/// No vertex across an edge (`AA_NO_VERTEX` in `kernels/raster/include/hard_antialias.glsl`).
const NO_VERTEX: u32 = u32::MAX;

/// Edge `k` of a triangle runs between these two of its vertices (the twin's `EDGE_ENDS`).
const EDGE_ENDS: [(usize, usize); 3] = [(1, 2), (2, 0), (0, 1)];

/// Floats per item in the position gradient's slots: three corners of (x, y, z, w).
const DIMS: u32 = 12;

/// The antialias kernels and their scratch (a field of [`HardRasterizer`]).
pub(super) struct AntialiasKernels {
    pairs: Arc<Kernel>,
    forward: Arc<Kernel>,
    grad_color: Arc<Kernel>,
    grad: Arc<Kernel>,
    scale: Arc<Kernel>,
    /// The work list: 16 bytes a pixel.
    work: Option<Buffer>,
    /// One f32: the boost of the position gradient.
    boost: Option<Buffer>,
}

impl AntialiasKernels {
    pub(super) fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            pairs: ctx.kernel(&specs::HARD_ANTIALIAS_PAIRS, &[])?,
            forward: ctx.kernel(&specs::HARD_ANTIALIAS, &[])?,
            grad_color: ctx.kernel(&specs::HARD_ANTIALIAS_GRAD_COLOR, &[])?,
            grad: ctx.kernel(&specs::HARD_ANTIALIAS_GRAD, &[])?,
            scale: ctx.kernel(&specs::HARD_ANTIALIAS_SCALE, &[])?,
            work: None,
            boost: None,
        })
    }
}

impl HardPlan {
    /// The plan `antialias` runs over: `shape`'s image, vertices and triangles, `channels`
    /// colour channels, every minibatch item drawing all the triangles (the range table is
    /// `[0, T]` per item, whatever ranges a [`Topology::Ranged`] gives: antialias reads the ids
    /// in `rast`, and any of them must have its item). Instanced as `shape` is.
    pub fn for_antialias(ctx: &Context, shape: &Shape, channels: u32) -> Result<Self> {
        if channels == 0 {
            return Err(Error::Input("antialias: color has no channels".into()));
        }
        let batch = shape.batch();
        let topology = match shape.topology {
            Topology::Instanced { batch } => Topology::Instanced { batch },
            Topology::Ranged(_) => {
                Topology::Ranged(vec![[0, shape.triangle_count]; batch as usize])
            }
        };
        let mut plan = HardPlan::new(
            ctx,
            &Shape {
                topology,
                ..shape.clone()
            },
        )?;
        let floats = plan.pixels() * u64::from(channels);
        let limit = u64::from(ctx.info().limits.max_storage_buffer_range);
        if 4 * floats > limit {
            return Err(Error::DeviceLimit {
                kind: LimitKind::StorageBinding,
                what: format!(
                    "antialias: color of {batch} × {}x{} pixels × {channels} channels",
                    shape.height, shape.width
                ),
                need: 4 * floats,
                max: limit,
                device: ctx.info().name.clone(),
                hint: "antialias fewer minibatch items or channels at once",
            });
        }
        plan.push.channels = channels;
        Ok(plan)
    }
}

/// The shape of an antialias call's arrays, as a rasterization's.
fn args_shape(args: &AntialiasArgs<'_>) -> Shape {
    Shape {
        width: args.width,
        height: args.height,
        vertex_count: args.vertex_count,
        triangle_count: args.tri.len() as u32,
        topology: if args.instanced {
            Topology::Instanced { batch: args.batch }
        } else {
            Topology::Ranged(vec![[0, args.tri.len() as u32]; args.batch as usize])
        },
    }
}

/// The twin's checks of an antialias call's arrays (`AntialiasInput::validate` and the hash's
/// triangle count), with its messages.
fn check_args(args: &AntialiasArgs<'_>, topology: &TopologyHash) -> Result<()> {
    let (b, h, w, c) = (
        args.batch as usize,
        args.height as usize,
        args.width as usize,
        args.channels as usize,
    );
    if b == 0 || h == 0 || w == 0 || c == 0 {
        return Err(Error::Input(format!(
            "antialias: empty image shape (batch {b}, height {h}, width {w}, channels {c})"
        )));
    }
    let pixels = b * h * w;
    if args.color.len() != pixels * c {
        return Err(Error::Input(format!(
            "antialias: color has {} values, the shape needs {}",
            args.color.len(),
            pixels * c
        )));
    }
    if args.rast.len() != pixels * 4 {
        return Err(Error::Input(format!(
            "antialias: rast has {} values, the shape needs {}",
            args.rast.len(),
            pixels * 4
        )));
    }
    let vertices = args.vertex_count as usize;
    let sets = if args.instanced { b } else { 1 };
    if vertices == 0 || args.pos.len() != vertices * sets * 4 {
        return Err(Error::Input(format!(
            "antialias: pos has {} values, {vertices} vertices over {sets} sets need {}",
            args.pos.len(),
            vertices * sets * 4
        )));
    }
    if let Some((t, v)) = args
        .tri
        .iter()
        .enumerate()
        .find(|(_, v)| v.iter().any(|&i| i as usize >= vertices))
    {
        return Err(Error::Input(format!(
            "antialias: triangle {t} = {v:?} indexes past {vertices} vertices"
        )));
    }
    if topology.triangle_count() != args.tri.len() {
        return Err(Error::Input(format!(
            "antialias: topology hash built from {} triangles, tri has {}",
            topology.triangle_count(),
            args.tri.len()
        )));
    }
    Ok(())
}

impl HardRasterizer {
    /// The kernels' view of `topology`: per triangle of `tri` and edge `k` (the one opposite
    /// vertex `k`), the vertex across it as [`TopologyHash::opposite_vertex`] answers, or
    /// `u32::MAX` for none (an edge that is always a silhouette edge; so is one whose answer is
    /// not among the `vertex_count` vertices, as in the twin). `3 T` words.
    pub fn antialias_topology(
        topology: &TopologyHash,
        tri: &[[u32; 3]],
        vertex_count: u32,
    ) -> Result<Vec<u32>> {
        if topology.triangle_count() != tri.len() {
            return Err(Error::Input(format!(
                "antialias: topology hash built from {} triangles, tri has {}",
                topology.triangle_count(),
                tri.len()
            )));
        }
        Ok(tri
            .iter()
            .flat_map(|v| {
                EDGE_ENDS.iter().enumerate().map(|(own, &(i, j))| {
                    match topology.opposite_vertex(v[i], v[j], v[own]) {
                        Some(o) if o < vertex_count => o,
                        _ => NO_VERTEX,
                    }
                })
            })
            .collect())
    }

    fn check_antialias(
        plan: &HardPlan,
        inputs: &HardInputs<'_>,
        opposites: &BufferRange<'_>,
        color: &BufferRange<'_>,
        rast: &BufferRange<'_>,
    ) -> Result<()> {
        Self::check_inputs(plan, inputs)?;
        let pixels = plan.pixels();
        opposites.require(
            12 * u64::from(plan.shape.triangle_count).max(1),
            "antialias topology",
        )?;
        color.require(
            4 * pixels * u64::from(plan.push.channels),
            "antialias color",
        )?;
        rast.require(16 * pixels, "rast")
    }

    /// Records step 1, the work list of `plan` ([`HardPlan::for_antialias`]) into the scratch.
    fn record_antialias_pairs(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        inputs: HardInputs<'_>,
        opposites: BufferRange<'_>,
        rast: BufferRange<'_>,
    ) -> Result<()> {
        let ctx = rec.context();
        let pixels = plan.pixels();
        device_buffer(ctx, &mut self.aa.work, "antialias work list", 16 * pixels)?;
        let k = &self.aa;
        let work = k.work.as_ref().expect("made above").range(0, 16 * pixels);
        rec.dispatch(
            &k.pairs,
            &specs::HardAntialiasPairsBindings {
                pos: inputs.pos,
                tri: inputs.tri,
                opposites: opposites.sub(0, 12 * u64::from(plan.shape.triangle_count).max(1)),
                rast: rast.sub(0, 16 * pixels),
                pairs: work,
            }
            .for_kernel(&k.pairs)?,
            &plan.push,
            groups(pixels, 64)?,
        )
    }

    /// Records the forward over `plan` ([`HardPlan::for_antialias`]): into `out`
    /// (`[B, H, W, C]` f32) `color` with its silhouette pairs blended, given `rast` (16 bytes a
    /// pixel) and the topology table of [`HardRasterizer::antialias_topology`] in `opposites`.
    #[allow(clippy::too_many_arguments)]
    pub fn record_antialias(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        inputs: HardInputs<'_>,
        opposites: BufferRange<'_>,
        color: BufferRange<'_>,
        rast: BufferRange<'_>,
        out: BufferRange<'_>,
    ) -> Result<()> {
        Self::check_antialias(plan, &inputs, &opposites, &color, &rast)?;
        let floats = plan.pixels() * u64::from(plan.push.channels);
        out.require(4 * floats, "antialias output")?;
        rec.pass("hard antialias", |rec| {
            self.record_antialias_pairs(rec, plan, inputs, opposites, rast)?;
            let k = &self.aa;
            let work = k.work.as_ref().expect("made").range(0, 16 * plan.pixels());
            rec.dispatch(
                &k.forward,
                &specs::HardAntialiasBindings {
                    color: color.sub(0, 4 * floats),
                    pairs: work,
                    out: out.sub(0, 4 * floats),
                }
                .for_kernel(&k.forward)?,
                &plan.push,
                groups(floats, 64)?,
            )
        })
    }

    /// The backward's first step: the visible tiles of `plan`'s items over `rast`, their boxes
    /// widened by one pixel (a pair's first pixel may lie one left of or below its triangle's).
    /// Submit it, then call [`HardRasterizer::read_slots`], then
    /// [`HardRasterizer::record_antialias_grad`].
    pub fn record_antialias_tiles(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        rast: BufferRange<'_>,
        ranges: BufferRange<'_>,
    ) -> Result<()> {
        self.record_visible_tiles(rec, plan, rast, ranges, 1)
    }

    /// Records the backward over `plan` ([`HardPlan::for_antialias`]), after
    /// [`HardRasterizer::record_antialias_tiles`] and [`HardRasterizer::read_slots`] for the same
    /// `rast`: given `dy = dL/d(output)` (`[B, H, W, C]` f32), into `grad_color` (same shape)
    /// and `grad_pos` (f32, [`Shape::pos_len`], the z components zero) times
    /// `pos_gradient_boost`, over the vertex lists of [`vertex_lists`] (`per_item` as the
    /// positions are instanced).
    #[allow(clippy::too_many_arguments)]
    pub fn record_antialias_grad(
        &mut self,
        rec: &mut Recorder<'_>,
        plan: &HardPlan,
        inputs: HardInputs<'_>,
        opposites: BufferRange<'_>,
        color: BufferRange<'_>,
        rast: BufferRange<'_>,
        dy: BufferRange<'_>,
        lists: (BufferRange<'_>, BufferRange<'_>),
        grad_color: BufferRange<'_>,
        grad_pos: BufferRange<'_>,
        pos_gradient_boost: f32,
    ) -> Result<()> {
        let ctx = rec.context();
        Self::check_antialias(plan, &inputs, &opposites, &color, &rast)?;
        let pixels = plan.pixels();
        let floats = pixels * u64::from(plan.push.channels);
        dy.require(4 * floats, "the gradient of the antialias output")?;
        grad_color.require(4 * floats, "the gradient of color")?;
        let push = self.grad_scratch(ctx, plan, DIMS, 1, "antialias backward")?;
        device_buffer(ctx, &mut self.aa.boost, "antialias boost", 4)?;
        let rows = plan.shape.pos_len() as u32 / 4;
        let (color, dy) = (color.sub(0, 4 * floats), dy.sub(0, 4 * floats));
        rec.pass("hard antialias backward", |rec| {
            self.record_antialias_pairs(rec, plan, inputs, opposites, rast)?;
            let k = &self.aa;
            let g = &self.grads;
            let work = k.work.as_ref().expect("made").range(0, 16 * pixels);
            rec.dispatch(
                &k.grad_color,
                &specs::HardAntialiasGradColorBindings {
                    dy,
                    pairs: work,
                    grad_color: grad_color.sub(0, 4 * floats),
                }
                .for_kernel(&k.grad_color)?,
                &push,
                groups(floats, 64)?,
            )?;
            if push.slots > 0 {
                let items = u64::from(push.items);
                rec.dispatch(
                    &k.grad,
                    &specs::HardAntialiasGradBindings {
                        pos: inputs.pos,
                        tri: inputs.tri,
                        rast: rast.sub(0, 16 * pixels),
                        color,
                        dy,
                        pairs: work,
                        boxes: g.boxes.as_ref().expect("made").range(0, 16 * items),
                        offsets: g.offsets.as_ref().expect("made").range(0, 4 * items),
                        partials: g
                            .partials
                            .as_ref()
                            .expect("reserved")
                            .range(0, 4 * u64::from(DIMS) * u64::from(push.slots)),
                    }
                    .for_kernel(&k.grad)?,
                    &push,
                    groups(u64::from(push.slots), 64)?,
                )?;
            }
            self.record_reduce_gather(rec, &push, rows, lists, grad_pos)?;
            if pos_gradient_boost != 1.0 {
                let boost = k.boost.as_ref().expect("made").range(0, 4);
                rec.fill(boost, pos_gradient_boost.to_bits());
                let floats = u64::from(rows) * u64::from(DIMS / 3);
                rec.dispatch(
                    &k.scale,
                    &specs::HardAntialiasScaleBindings {
                        boost,
                        grads: grad_pos.sub(0, 4 * floats),
                    }
                    .for_kernel(&k.scale)?,
                    &HardPush { rows, ..push },
                    groups(floats, 64)?,
                )?;
            }
            Ok(())
        })
    }

    /// Uploads what both host-slice entry points read: `(plan, buffer offsets)` of color,
    /// rast, pos, tri, the topology table, the range table, then `extra` parts the caller fills.
    fn antialias_upload(
        &mut self,
        ctx: &Context,
        args: &AntialiasArgs<'_>,
        topology: &TopologyHash,
        extra: &[u64],
    ) -> Result<(HardPlan, Vec<u64>)> {
        check_args(args, topology)?;
        let shape = args_shape(args);
        let plan = HardPlan::for_antialias(ctx, &shape, args.channels)?;
        let opposites = Self::antialias_topology(topology, args.tri, args.vertex_count)?;
        let mut parts = vec![
            4 * args.color.len() as u64,
            16 * plan.pixels(),
            4 * args.pos.len() as u64,
            12 * args.tri.len() as u64,
            4 * opposites.len() as u64,
            8 * plan.ranges.len() as u64,
        ];
        parts.extend_from_slice(extra);
        let at = layout_of(&parts);
        let input = host_buffer(
            ctx,
            &mut self.host.inputs,
            "hard inputs",
            *at.last().expect("non-empty"),
            MemoryKind::Upload,
        )?;
        let bytes = input
            .mapped_mut()
            .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
        put(bytes, at[0], args.color);
        put(bytes, at[1], args.rast);
        put(bytes, at[2], args.pos);
        put(bytes, at[3], args.tri);
        put(bytes, at[4], &opposites);
        put(bytes, at[5], &plan.ranges);
        Ok((plan, at))
    }

    /// `antialias`: the image with its silhouette edges blended by the coverage their geometry
    /// gives. Waits for the device.
    pub fn antialias(
        &mut self,
        ctx: &Context,
        args: &AntialiasArgs<'_>,
        topology: &TopologyHash,
    ) -> Result<Vec<f32>> {
        let (plan, at) = self.antialias_upload(ctx, args, topology, &[])?;
        let out_bytes = 4 * args.color.len() as u64;
        host_buffer(
            ctx,
            &mut self.host.outputs,
            "hard outputs",
            out_bytes,
            MemoryKind::Readback,
        )?;
        let input = self.host.inputs.take().expect("made above");
        let output = self.host.outputs.take().expect("made above");
        let result = (|| {
            let t = (args.tri.len() as u64).max(1);
            let inputs = HardInputs {
                pos: input.range(at[2], 4 * args.pos.len() as u64),
                tri: input.range(at[3], 12 * t),
                ranges: input.range(at[5], 8 * plan.ranges.len() as u64),
            };
            self.submit(ctx, |s, rec| {
                s.record_antialias(
                    rec,
                    &plan,
                    inputs,
                    input.range(at[4], 12 * t),
                    input.range(at[0], out_bytes),
                    input.range(at[1], 16 * plan.pixels()),
                    output.range(0, out_bytes),
                )
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut out = vec![0.0f32; args.color.len()];
            get(bytes, 0, &mut out);
            Ok(out)
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }

    /// The backward of [`HardRasterizer::antialias`]: `(grad_color, grad_pos)`, the latter
    /// times `pos_gradient_boost` (rounded to f32 once). Waits for the device.
    pub fn antialias_grad(
        &mut self,
        ctx: &Context,
        args: &AntialiasArgs<'_>,
        topology: &TopologyHash,
        dy: &[f32],
        pos_gradient_boost: f64,
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        if dy.len() != args.color.len() {
            return Err(Error::Input(format!(
                "antialias backward: dy has {} values, color has {}",
                dy.len(),
                args.color.len()
            )));
        }
        // The vertex lists need the plan; sizes first, then the lists, in a second upload part.
        check_args(args, topology)?;
        let lists_plan = HardPlan::for_antialias(ctx, &args_shape(args), args.channels)?;
        let (row_offsets, row_entries) = vertex_lists(&lists_plan, args.tri, args.instanced);
        let (plan, at) = self.antialias_upload(
            ctx,
            args,
            topology,
            &[
                4 * dy.len() as u64,
                4 * row_offsets.len() as u64,
                4 * row_entries.len() as u64,
            ],
        )?;
        {
            let bytes = self
                .host
                .inputs
                .as_mut()
                .expect("made above")
                .mapped_mut()
                .ok_or_else(|| Error::Misuse("upload memory is not host-mapped".into()))?;
            put(bytes, at[6], dy);
            put(bytes, at[7], &row_offsets);
            put(bytes, at[8], &row_entries);
        }
        let color_bytes = 4 * args.color.len() as u64;
        let pos_bytes = 4 * args.pos.len() as u64;
        let out_at = layout_of(&[color_bytes, pos_bytes]);
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
            let t = (args.tri.len() as u64).max(1);
            let inputs = HardInputs {
                pos: input.range(at[2], pos_bytes),
                tri: input.range(at[3], 12 * t),
                ranges: input.range(at[5], 8 * plan.ranges.len() as u64),
            };
            let rast = input.range(at[1], 16 * plan.pixels());
            self.submit(ctx, |s, rec| {
                s.record_antialias_tiles(rec, &plan, rast, inputs.ranges)
            })?;
            self.read_slots(ctx)?;
            self.submit(ctx, |s, rec| {
                s.record_antialias_grad(
                    rec,
                    &plan,
                    inputs,
                    input.range(at[4], 12 * t),
                    input.range(at[0], color_bytes),
                    rast,
                    input.range(at[6], color_bytes),
                    (
                        input.range(at[7], 4 * row_offsets.len() as u64),
                        input.range(at[8], 4 * (row_entries.len() as u64).max(1)),
                    ),
                    output.range(out_at[0], color_bytes),
                    output.range(out_at[1], pos_bytes),
                    pos_gradient_boost as f32,
                )
            })?;
            let bytes = output
                .mapped()
                .ok_or_else(|| Error::Misuse("readback memory is not host-mapped".into()))?;
            let mut grad_color = vec![0.0f32; args.color.len()];
            let mut grad_pos = vec![0.0f32; args.pos.len()];
            get(bytes, out_at[0], &mut grad_color);
            get(bytes, out_at[1], &mut grad_pos);
            Ok((grad_color, grad_pos))
        })();
        self.host.inputs = Some(input);
        self.host.outputs = Some(output);
        result
    }
}
