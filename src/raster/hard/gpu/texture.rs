//! `texture` and `texture_construct_mip` on the GPU: [`TextureSampler`], equal to the f64 twin
//! [`crate::raster::hard::texture`] (whose module docs give every rule) up to f32.
//!
//! A texture and its mip levels are one float array, the **stack** ([`TexLayout`]): level 0,
//! then each level below it, each `[items, height, width, channels]`. Over buffers the caller
//! owns:
//!
//! 1. **Mip levels** (`kernels/hard/hard_tex_mip.comp`, [`TextureSampler::record_construct_mip`]):
//!    each level from the one above, in place.
//! 2. **Forward** (`hard_tex.comp`, [`TextureSampler::record_sample`]): per lookup the filtered
//!    texels, the filter and boundary modes specialization constants.
//! 3. **Backward** ([`TextureSampler::record_sample_grad`]): per lookup the gradients to `uv`,
//!    `uv_da` and the bias, and one entry per texel it read (`hard_tex_grad.comp`: the texel's
//!    index as the key, the weight its output gradient is scaled by); the entries sorted by
//!    texel (the stable [`RadixSort`]: each texel's entries stay in lookup order); each run's
//!    bounds (`hard_tex_runs.comp`); the runs summed in blocks of [`PARTIAL_BLOCK`] entries
//!    (`hard_tex_partials.comp`) and the blocks' parts per texel (`hard_tex_reduce.comp`), so
//!    that no loop is longer than a block or than one run's blocks; then, for a stack built
//!    from its base, each level's gradient carried into the level above it, from the last up
//!    (`hard_tex_mip_grad.comp`).
//!
//! A cube map ([`TexMode::Cube`]) is a stack of `6 B` items, the faces +x, −x, +y, −y, +z, −z
//! of each cube, `S × S` texels (twin: [`crate::raster::hard::texture::cube`]); its lookups'
//! `uv` are directions, three floats, and `uv_da` six. The kernels are the same, specialized.
//!
//! No float atomics anywhere: the same bits on every run, whatever the workgroup shape.

use bytemuck::{Pod, Zeroable};

use super::{HostBuffers, device_buffer, get, host_buffer, layout_of, put};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{
    Buffer, BufferRange, Context, MemoryKind, PassTime, Recorder, Timer, groups, specs,
};
use crate::primitives::sort::{RadixSort, SortScratch};
use crate::raster::hard::texture::{Boundary, Filter, Mode};

/// Sorted entries one partial sum of the backward covers (`PARTIAL_BLOCK` in
/// `kernels/include/texture.glsl`).
pub const PARTIAL_BLOCK: u64 = 256;

/// The largest texture extent (nvdiffrast's; a binding's size limits a texture long before).
pub const MAX_EXTENT: u32 = 1 << 16;

/// What a lookup does: a 2D texture's filter and boundary modes, or a cube map's filter
/// (nvdiffrast's `boundary_mode='cube'`: seamless across faces, `uv` a direction).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexMode {
    /// A 2D texture.
    Flat(Mode),
    /// A cube map.
    Cube(Filter),
}

impl TexMode {
    /// nvdiffrast's `boundary_mode` with a filter: `'cube'` a cube map, the others a 2D mode.
    pub fn parse(filter: Filter, boundary: &str) -> Result<Self> {
        if boundary == "cube" {
            return Ok(Self::Cube(filter));
        }
        Boundary::parse(boundary).map(|boundary| Self::Flat(Mode { filter, boundary }))
    }

    /// The filter mode.
    pub fn filter(&self) -> Filter {
        match *self {
            Self::Flat(m) => m.filter,
            Self::Cube(f) => f,
        }
    }

    /// Floats of a lookup's `uv`: 2, or a direction's 3.
    pub fn uv_floats(&self) -> u64 {
        if self.is_cube() { 3 } else { 2 }
    }

    /// Floats of a lookup's `uv_da`: 4, or a direction's 6.
    pub fn uv_da_floats(&self) -> u64 {
        if self.is_cube() { 6 } else { 4 }
    }

    fn is_cube(&self) -> bool {
        matches!(self, Self::Cube(_))
    }
}

impl From<Mode> for TexMode {
    fn from(mode: Mode) -> Self {
        Self::Flat(mode)
    }
}

/// Push constants of every texture kernel (`Push` in `kernels/include/texture.glsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
struct TexPush {
    width: u32,
    height: u32,
    channels: u32,
    tex_items: u32,
    levels: u32,
    points: u32,
    item_points: u32,
    has_uv_da: u32,
    has_bias: u32,
    level: u32,
    entries: u32,
    texels: u32,
}

/// A mip stack as the kernels address it: `items` textures (1: shared by every minibatch item)
/// of `height × width` texels of `channels` floats, and `levels` levels (the base included),
/// level `l` being `max(width >> l, 1) × max(height >> l, 1)`. A cube map's items are its
/// faces: `6 B` (6: one cube shared by every minibatch item) square faces, each halved apart.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexLayout {
    /// Textures in the stack.
    pub items: u32,
    /// The base level's width.
    pub width: u32,
    /// The base level's height.
    pub height: u32,
    /// Floats a texel.
    pub channels: u32,
    /// Levels, the base included.
    pub levels: u32,
}

impl TexLayout {
    /// A stack of `levels` levels (1: the base alone), checked: positive sizes, extents up to
    /// [`MAX_EXTENT`], no more levels than halving reaches 1 × 1.
    pub fn new(items: u32, height: u32, width: u32, channels: u32, levels: u32) -> Result<Self> {
        if items == 0 || height == 0 || width == 0 || channels == 0 {
            return Err(Error::Input(format!(
                "texture: tex must have a positive size in every dimension, not \
                 [{items}, {height}, {width}, {channels}]"
            )));
        }
        if height > MAX_EXTENT || width > MAX_EXTENT {
            return Err(Error::Input(format!(
                "texture: a {height}x{width} texture (height x width) is larger than \
                 {MAX_EXTENT} texels a side"
            )));
        }
        let full = 32 - height.max(width).leading_zeros();
        if levels == 0 || levels > full {
            return Err(Error::Input(format!(
                "texture: a {height}x{width} texture has 1 to {full} levels, not {levels}"
            )));
        }
        Ok(Self {
            items,
            width,
            height,
            channels,
            levels,
        })
    }

    /// The stack `texture_construct_mip` builds: levels down to 1 × 1, or `max_mip_level` of
    /// them below the base; an odd extent above 1 on the way cannot be halved and is an error,
    /// as in nvdiffrast (and the twin's `MipStack::build`).
    pub fn with_mips(
        items: u32,
        height: u32,
        width: u32,
        channels: u32,
        max_mip_level: Option<u32>,
    ) -> Result<Self> {
        let mut layout = Self::new(items, height, width, channels, 1)?;
        while layout.levels - 1 < max_mip_level.unwrap_or(u32::MAX) {
            let [w, h] = layout.level_size(layout.levels - 1);
            if w == 1 && h == 1 {
                break;
            }
            if (w > 1 && w % 2 == 1) || (h > 1 && h % 2 == 1) {
                return Err(Error::Input(format!(
                    "texture: cannot build mip level {} of a {height}x{width} texture (height x \
                     width): level {} is {h}x{w}, and an odd extent above 1 cannot be halved; \
                     resize the texture to powers of two or limit max_mip_level",
                    layout.levels,
                    layout.levels - 1
                )));
            }
            layout.levels += 1;
        }
        Ok(layout)
    }

    /// Level `level`'s `[width, height]`.
    pub fn level_size(&self, level: u32) -> [u32; 2] {
        [(self.width >> level).max(1), (self.height >> level).max(1)]
    }

    /// Texels of level `level`, over every item.
    pub fn level_texels(&self, level: u32) -> u64 {
        let [w, h] = self.level_size(level);
        u64::from(self.items) * u64::from(w) * u64::from(h)
    }

    /// Floats before level `level` in the stack.
    pub fn level_offset(&self, level: u32) -> u64 {
        (0..level).map(|l| self.level_texels(l)).sum::<u64>() * u64::from(self.channels)
    }

    /// Texels over every level.
    pub fn texels(&self) -> u64 {
        (0..self.levels).map(|l| self.level_texels(l)).sum()
    }

    /// Floats of the whole stack.
    pub fn floats(&self) -> u64 {
        self.texels() * u64::from(self.channels)
    }
}

/// What a lookup grid is: `batch × height × width` lookups (`uv [B, h, w, 2]`, a cube map's
/// `[B, h, w, 3]`), with `uv_da` (`[B, h, w, 4]`, a cube map's `[B, h, w, 6]`) and
/// `mip_level_bias` (`[B, h, w]`) bound or not.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lookups {
    /// Minibatch items B.
    pub batch: u32,
    /// Rows of the grid.
    pub height: u32,
    /// Columns of the grid.
    pub width: u32,
    /// Whether `uv_da` picks the mip level.
    pub uv_da: bool,
    /// Whether `mip_level_bias` is added to it.
    pub bias: bool,
}

impl Lookups {
    /// Lookups over the minibatch.
    pub fn points(&self) -> u64 {
        u64::from(self.batch) * u64::from(self.height) * u64::from(self.width)
    }
}

/// The caller buffers a lookup reads.
#[derive(Clone, Copy)]
pub struct TextureInputs<'a> {
    /// The stack, [`TexLayout::floats`] f32.
    pub stack: BufferRange<'a>,
    /// [`TexMode::uv_floats`] f32 a lookup.
    pub uv: BufferRange<'a>,
    /// [`TexMode::uv_da_floats`] f32 a lookup, when [`Lookups::uv_da`].
    pub uv_da: Option<BufferRange<'a>>,
    /// One f32 a lookup, when [`Lookups::bias`].
    pub bias: Option<BufferRange<'a>>,
}

/// The caller buffers the backward writes.
#[derive(Clone, Copy)]
pub struct TextureGradOutputs<'a> {
    /// Every level's texel gradients, laid out as the stack.
    pub stack: BufferRange<'a>,
    /// [`TexMode::uv_floats`] f32 a lookup.
    pub uv: BufferRange<'a>,
    /// [`TexMode::uv_da_floats`] f32 a lookup, when [`Lookups::uv_da`].
    pub uv_da: Option<BufferRange<'a>>,
    /// One f32 a lookup, when [`Lookups::bias`].
    pub bias: Option<BufferRange<'a>>,
}

/// A stack handed to the host entry points: its base alone, the mip levels built on the device;
/// every level, built from the base before (nvdiffrast's `texture_construct_mip`); or every
/// level given by the caller. The first two carry the levels' gradients into the base's, as
/// nvdiffrast does through its mip stack; a given stack's levels keep their own.
#[derive(Clone, Copy, Debug)]
pub enum Levels<'a> {
    /// Level 0, [`TexLayout::level_texels`]`(0) × channels` f32.
    Build(&'a [f32]),
    /// Every level, [`TexLayout::floats`] f32, the mip levels built from level 0.
    Built(&'a [f32]),
    /// Every level, [`TexLayout::floats`] f32, each the caller's own.
    Given(&'a [f32]),
}

impl<'a> Levels<'a> {
    /// The floats handed over.
    fn floats(&self) -> &'a [f32] {
        match *self {
            Levels::Build(t) | Levels::Built(t) | Levels::Given(t) => t,
        }
    }
}

/// One call's lookups on host slices.
#[derive(Clone, Copy, Debug)]
pub struct Lookup<'a> {
    /// The grid, and which level inputs it has.
    pub grid: Lookups,
    /// `[B, h, w, 2]` (a cube map's `[B, h, w, 3]`).
    pub uv: &'a [f32],
    /// `[B, h, w, 4]` (a cube map's `[B, h, w, 6]`).
    pub uv_da: Option<&'a [f32]>,
    /// `[B, h, w]`.
    pub bias: Option<&'a [f32]>,
}

/// The gradients [`TextureSampler::sample_grad`] returns.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TextureGrads32 {
    /// Every level's texel gradients, laid out as the stack; but for [`Levels::Given`], level 0
    /// holds the texture's whole gradient (the levels' carried through the pyramid).
    pub stack: Vec<f32>,
    /// To `uv`.
    pub uv: Vec<f32>,
    /// To `uv_da` (empty without it).
    pub uv_da: Vec<f32>,
    /// To `mip_level_bias` (empty without it).
    pub bias: Vec<f32>,
}

/// The backward's scratch, grown to the largest call so far.
#[derive(Default)]
struct GradScratch {
    keys: Option<Buffer>,
    values: Option<Buffer>,
    weights: Option<Buffer>,
    partials: Option<Buffer>,
    runs: Option<Buffer>,
    sort: Option<SortScratch>,
}

/// nvdiffrast's `texture` and `texture_construct_mip` on the device.
pub struct TextureSampler {
    sort: RadixSort,
    scratch: GradScratch,
    stack: Option<Buffer>,
    host: HostBuffers,
    timer: Option<Timer>,
    timings: Vec<PassTime>,
}

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

/// Texel entries a lookup gives the backward (`TAPS` in `kernels/include/texture.glsl`).
fn taps(filter: Filter) -> u64 {
    match filter {
        Filter::Nearest => 1,
        Filter::Linear | Filter::LinearMipmapNearest => 4,
        Filter::LinearMipmapLinear => 8,
    }
}

/// The push constants of a call, checked: the grid against the stack, the sizes against the
/// kernels' 32-bit indices and the device's bindings.
fn push_for(ctx: &Context, layout: &TexLayout, mode: TexMode, grid: &Lookups) -> Result<TexPush> {
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
    /// Builds the sort's pipelines; the texture kernels come from the context's cache, one per
    /// mode, when first recorded.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            sort: RadixSort::new(ctx)?,
            scratch: GradScratch::default(),
            stack: None,
            host: HostBuffers::default(),
            timer: None,
            timings: Vec::new(),
        })
    }

    /// Times every pass of the host entry points from now on (for `softvk bench`).
    pub fn time_passes(&mut self, ctx: &Context) -> Result<()> {
        self.timer = Some(Timer::new(ctx, 16)?);
        Ok(())
    }

    /// The pass times the host entry points recorded since the last call, in order.
    pub fn take_timings(&mut self) -> Vec<PassTime> {
        std::mem::take(&mut self.timings)
    }

    /// Submits what `f` records and waits, timed when [`TextureSampler::time_passes`] asked.
    fn submit(
        &mut self,
        ctx: &Context,
        f: impl FnOnce(&mut Self, &mut Recorder<'_>) -> Result<()>,
    ) -> Result<()> {
        let mut timer = self.timer.take();
        let result = ctx.submit_and_wait_timed(timer.as_mut(), |rec| f(self, rec));
        let times = match (&result, &timer) {
            (Ok(()), Some(t)) => t.results(ctx),
            _ => Ok(Vec::new()),
        };
        self.timer = timer;
        result?;
        self.timings.extend(times?);
        Ok(())
    }

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
