//! `texture` and `texture_construct_mip` on the GPU: [`TextureSampler`], equal to the f64 twin
//! [`crate::raster::hard::texture`] (whose module docs give every rule) up to f32.
//!
//! A texture and its mip levels are one float array, the **stack** ([`TexLayout`]): level 0,
//! then each level below it, each `[items, height, width, channels]`. Over buffers the caller
//! owns:
//!
//! 1. **Mip levels** (`kernels/raster/hard/hard_tex_mip.comp`, [`TextureSampler::record_construct_mip`]):
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

mod host;
mod record;
use bytemuck::{Pod, Zeroable};

use super::HostBuffers;
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, PassTime, Recorder, Timer};
use crate::primitives::sort::{RadixSort, SortScratch};
use crate::raster::hard::texture::{Boundary, Filter, Mode};

/// Sorted entries one partial sum of the backward covers (`PARTIAL_BLOCK` in
/// `kernels/raster/include/texture.glsl`).
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

/// Push constants of every texture kernel (`Push` in `kernels/raster/include/texture.glsl`).
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
}
