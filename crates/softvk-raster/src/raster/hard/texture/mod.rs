//! The f64 twin of nvdiffrast's `texture` and `texture_construct_mip` for 2D textures, forward
//! ([`sample`]) and backward ([`sample_backward`], [`MipStack::pyramid_backward`]), and, in
//! [`cube`], for cube maps (`boundary_mode='cube'`): the reference the texture kernels will be
//! held to.
//!
//! nvdiffrast's behaviour, as its documentation and source show it (softvk's code is its own):
//!
//! - **Layout.** A texture is `[B, H, W, C]` (any `C`), `B` 1 (shared by every minibatch item)
//!   or the minibatch's; `uv` is `[B, h, w, 2]`, `u` across the width and `v` down the rows, the
//!   texture's texel `(x, y)` covering `[x/W, (x+1)/W) × [y/H, (y+1)/H)`.
//! - **Boundaries** ([`Boundary`]). `wrap` takes `u − ⌊u⌋` (and `v`'s) before anything else,
//!   then wraps the taps of linear filtering around the edge; `clamp` clamps the nearest texel,
//!   and for linear filtering the texel-space coordinate to the edge texels' centres; `zero`
//!   reads zero for every tap outside the texture.
//! - **Filters** ([`Filter`]). `nearest` reads texel `⌊u W⌋, ⌊v H⌋` of the base level;
//!   `linear` blends the four texels around `(u W − ½, v H − ½)` of the base level; the mipmap
//!   modes first pick a level `λ` (below): `linear-mipmap-nearest` blends on level `⌊λ⌋` (the
//!   floor, not the nearest integer), `linear-mipmap-linear` also on `⌊λ⌋ + 1` and mixes the
//!   two by `λ − ⌊λ⌋`. `auto` is `linear-mipmap-linear` when `uv_da` or `mip_level_bias` is
//!   given, else `linear`; a mipmap mode with `max_mip_level = 0` is `linear`.
//! - **The level.** From `uv_da = (du/dX, du/dY, dv/dX, dv/dY)` in texels of the base level
//!   (`s = u W`, `t = v H`): the footprint's major axis, squared, is
//!   `(A + B)/2 + √((A − B)²/4 + C²)` with `A = s_X² + t_X²`, `B = s_Y² + t_Y²`,
//!   `C = s_X s_Y + t_X t_Y`, and `λ = ½ log2` of it; without `uv_da`, `λ = 0`.
//!   `mip_level_bias` is added, and `λ` clamped to `[0, the last level]` (NaN to 0).
//! - **The mip stack** ([`MipStack::build`]). Each level halves each extent above 1 (an extent
//!   of 1 stays 1), averaging 2 × 2 texels (2 × 1 where the level above is one texel high or
//!   wide), until both extents are 1 or `max_mip_level` levels are built; an odd extent above 1
//!   cannot be halved and is an error, as in nvdiffrast (resize the texture, or limit
//!   `max_mip_level`). A cube map's stack halves each face apart ([`MipStack::cube`]).

use crate::error::{Error, Result};

mod backward;
mod bilinear;
pub mod cube;
mod forward;

#[cfg(test)]
mod tests;

pub use backward::{PixelGrad, level_gradient, sample_backward};
pub use cube::{
    CubeGrad, CubeLevelGrad, CubeLevelInput, cube_direction, cube_face, cube_face_derivatives,
    cube_level_gradient, cube_level_of_detail, sample_cube, sample_cube_backward,
};
pub use forward::{LevelInput, level_of_detail, sample};

/// How `uv` outside `[0, 1)` reads the texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Boundary {
    /// Repeat the texture.
    Wrap,
    /// Hold the edge texels.
    Clamp,
    /// Zero outside.
    Zero,
}

impl Boundary {
    /// nvdiffrast's name of the mode (`'wrap'`, `'clamp'`, `'zero'`; `'cube'` is a cube map's).
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "wrap" => Ok(Self::Wrap),
            "clamp" => Ok(Self::Clamp),
            "zero" => Ok(Self::Zero),
            "cube" => Err(Error::Input(
                "texture: boundary_mode 'cube' is a cube map's, looked up by direction \
                 (texture::sample_cube), not a 2D texture's boundary"
                    .into(),
            )),
            _ => Err(Error::Input(format!(
                "texture: boundary_mode must be 'wrap', 'clamp', 'zero' or 'cube', not {name:?}"
            ))),
        }
    }
}

/// How texels are filtered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    /// The base level's texel under `uv`.
    Nearest,
    /// Bilinear on the base level.
    Linear,
    /// Bilinear on level `⌊λ⌋`.
    LinearMipmapNearest,
    /// Bilinear on levels `⌊λ⌋` and `⌊λ⌋ + 1`, mixed by `λ`'s fraction.
    LinearMipmapLinear,
}

impl Filter {
    /// nvdiffrast's name of the mode; `'auto'` as nvdiffrast resolves it (`has_level_input`:
    /// `uv_da` or `mip_level_bias` is given), and a mipmap mode with `max_mip_level = 0` is
    /// `Linear`. A mipmap mode needs `uv_da` or `mip_level_bias`.
    pub fn parse(name: &str, has_level_input: bool, max_mip_level: Option<u32>) -> Result<Self> {
        let filter = match name {
            "auto" if has_level_input => Self::LinearMipmapLinear,
            "auto" | "linear" => Self::Linear,
            "nearest" => Self::Nearest,
            "linear-mipmap-nearest" => Self::LinearMipmapNearest,
            "linear-mipmap-linear" => Self::LinearMipmapLinear,
            _ => {
                return Err(Error::Input(format!(
                    "texture: filter_mode must be 'auto', 'nearest', 'linear', \
                     'linear-mipmap-nearest' or 'linear-mipmap-linear', not {name:?}"
                )));
            }
        };
        if filter.uses_mips() && !has_level_input {
            return Err(Error::Input(format!(
                "texture: filter_mode {name:?} needs uv_da or mip_level_bias"
            )));
        }
        Ok(if filter.uses_mips() && max_mip_level == Some(0) {
            Self::Linear
        } else {
            filter
        })
    }

    /// Whether the mode picks a mip level.
    pub fn uses_mips(self) -> bool {
        matches!(self, Self::LinearMipmapNearest | Self::LinearMipmapLinear)
    }
}

/// The filter and boundary modes of a lookup.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mode {
    /// How texels are filtered.
    pub filter: Filter,
    /// How `uv` outside the texture reads it.
    pub boundary: Boundary,
}

/// One level of a texture: `[items, height, width, channels]`, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    /// Texels across.
    pub width: usize,
    /// Texels down.
    pub height: usize,
    /// `items × height × width × channels` values.
    pub texels: Vec<f64>,
}

/// A texture and its mip levels (level 0 the texture itself).
#[derive(Clone, Debug, PartialEq)]
pub struct MipStack {
    /// Minibatch items the texture holds (1: shared).
    pub items: usize,
    /// Values a texel.
    pub channels: usize,
    /// Level 0 (the texture), then each mip level.
    pub levels: Vec<Level>,
}

impl MipStack {
    /// The texture alone, no mip levels: what `nearest` and `linear` read.
    pub fn base(
        items: usize,
        height: usize,
        width: usize,
        channels: usize,
        texels: Vec<f64>,
    ) -> Result<Self> {
        if items == 0 || height == 0 || width == 0 || channels == 0 {
            return Err(Error::Input(format!(
                "texture: tex must have a positive size in every dimension, not \
                 [{items}, {height}, {width}, {channels}]"
            )));
        }
        if texels.len() != items * height * width * channels {
            return Err(Error::Input(format!(
                "texture: tex holds {} values where [{items}, {height}, {width}, {channels}] \
                 needs {}",
                texels.len(),
                items * height * width * channels
            )));
        }
        Ok(Self {
            items,
            channels,
            levels: vec![Level {
                width,
                height,
                texels,
            }],
        })
    }

    /// nvdiffrast's `texture_construct_mip`: the base and its mip levels, at most
    /// `max_mip_level` of them (`None`: down to 1 × 1). An odd extent above 1 on the way is an
    /// error.
    pub fn build(mut self, max_mip_level: Option<u32>) -> Result<Self> {
        self.levels.truncate(1);
        let (w0, h0) = (self.levels[0].width, self.levels[0].height);
        while self.levels.len() - 1 < max_mip_level.map_or(usize::MAX, |m| m as usize) {
            let last = self.levels.last().expect("the base");
            let (w, h) = (last.width, last.height);
            if w == 1 && h == 1 {
                break;
            }
            if (w > 1 && w % 2 == 1) || (h > 1 && h % 2 == 1) {
                return Err(Error::Input(format!(
                    "texture: cannot build mip level {} of a {h0}x{w0} texture (height x width): \
                     level {} is {h}x{w}, and an odd extent above 1 cannot be halved; resize \
                     the texture to powers of two or limit max_mip_level",
                    self.levels.len(),
                    self.levels.len() - 1
                )));
            }
            let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
            let c = self.channels;
            let mut texels = Vec::with_capacity(self.items * nh * nw * c);
            for item in 0..self.items {
                let at =
                    |x: usize, y: usize, k: usize| last.texels[((item * h + y) * w + x) * c + k];
                for y in 0..nh {
                    for x in 0..nw {
                        for k in 0..c {
                            texels.push(if w == 1 || h == 1 {
                                // One texel wide or high: the two along the other extent.
                                let (a, b) = if h == 1 {
                                    (at(2 * x, 0, k), at(2 * x + 1, 0, k))
                                } else {
                                    (at(0, 2 * y, k), at(0, 2 * y + 1, k))
                                };
                                0.5 * (a + b)
                            } else {
                                0.25 * (at(2 * x, 2 * y, k)
                                    + at(2 * x + 1, 2 * y, k)
                                    + at(2 * x, 2 * y + 1, k)
                                    + at(2 * x + 1, 2 * y + 1, k))
                            });
                        }
                    }
                }
            }
            self.levels.push(Level {
                width: nw,
                height: nh,
                texels,
            });
        }
        Ok(self)
    }

    /// The last level's index.
    pub fn max_level(&self) -> usize {
        self.levels.len() - 1
    }

    fn texel(&self, level: usize, item: usize, x: usize, y: usize) -> &[f64] {
        let l = &self.levels[level];
        let item = if self.items == 1 { 0 } else { item };
        let o = ((item * l.height + y) * l.width + x) * self.channels;
        &l.texels[o..o + self.channels]
    }
}

/// Adds `scale · dy` into texel `(x, y)` of `level` in `tex_grad`.
#[allow(clippy::too_many_arguments)]
fn add_texel(
    stack: &MipStack,
    tex_grad: &mut [Vec<f64>],
    level: usize,
    item: usize,
    x: usize,
    y: usize,
    dy: &[f64],
    scale: f64,
) {
    let l = &stack.levels[level];
    let item = if stack.items == 1 { 0 } else { item };
    let o = ((item * l.height + y) * l.width + x) * stack.channels;
    for (g, d) in tex_grad[level][o..o + stack.channels].iter_mut().zip(dy) {
        *g += scale * d;
    }
}
