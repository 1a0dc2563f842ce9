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

pub mod cube;

pub use cube::{
    CubeGrad, CubeLevelGrad, CubeLevelInput, cube_direction, cube_face, cube_face_derivatives,
    cube_level_gradient, cube_level_of_detail, sample_cube, sample_cube_backward,
};

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

/// What picks one pixel's mip level: `uv_da` (`du/dX, du/dY, dv/dX, dv/dY`) and the bias.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LevelInput {
    /// The pixel's `uv` derivatives, `(du/dX, du/dY, dv/dX, dv/dY)`.
    pub uv_da: Option<[f64; 4]>,
    /// The pixel's `mip_level_bias`.
    pub bias: Option<f64>,
}

/// The mip level `λ` (unclamped) for the base level's `width × height` texels.
pub fn level_of_detail(input: LevelInput, width: usize, height: usize) -> f64 {
    let mut level = 0.0;
    if let Some([ux, uy, vx, vy]) = input.uv_da {
        let (sx, sy) = (ux * width as f64, uy * width as f64);
        let (tx, ty) = (vx * height as f64, vy * height as f64);
        let a = sx * sx + tx * tx;
        let b = sy * sy + ty * ty;
        let c = sx * sy + tx * ty;
        let major = 0.5 * (a + b) + (0.25 * (a - b) * (a - b) + c * c).sqrt();
        level = 0.5 * major.log2();
    }
    level + input.bias.unwrap_or(0.0)
}

/// The base level's texel `nearest` reads, by the boundary mode (`None`: zero).
fn nearest_texel(stack: &MipStack, uv: [f64; 2], boundary: Boundary) -> Option<(usize, usize)> {
    let base = &stack.levels[0];
    let (mut u, mut v) = (uv[0], uv[1]);
    if boundary == Boundary::Wrap {
        u -= u.floor();
        v -= v.floor();
    }
    let (w, h) = (base.width as f64, base.height as f64);
    let (x, y) = ((u * w).floor(), (v * h).floor());
    let outside = x < 0.0 || x >= w || y < 0.0 || y >= h;
    if !(x.is_finite() && y.is_finite()) || (boundary == Boundary::Zero && outside) {
        return None;
    }
    Some((
        x.clamp(0.0, w - 1.0) as usize,
        y.clamp(0.0, h - 1.0) as usize,
    ))
}

/// The mipmap modes' levels: `(λ unclamped, ⌊λ⌋, ⌊λ⌋ + 1 within the stack, λ's fraction)`,
/// the fraction 0 for `linear-mipmap-nearest` and where λ is clamped to 0.
fn mip_levels(stack: &MipStack, level: LevelInput, filter: Filter) -> (f64, usize, usize, f64) {
    let base = &stack.levels[0];
    let raw = level_of_detail(level, base.width, base.height);
    let (l0, l1, f) = pick_levels(stack, raw, filter);
    (raw, l0, l1, f)
}

/// The levels an unclamped `λ` picks: `(⌊λ⌋, ⌊λ⌋ + 1 within the stack, λ's fraction)`, `λ`
/// clamped to `[0, the last level]` (NaN to 0), the fraction 0 for `linear-mipmap-nearest`
/// and where λ is clamped to 0.
fn pick_levels(stack: &MipStack, raw: f64, filter: Filter) -> (usize, usize, f64) {
    let max = stack.max_level() as f64;
    // NaN clamps to 0 (a zero footprint gives −∞, which the clamp takes to 0 too).
    let lambda = if raw.is_nan() {
        0.0
    } else {
        raw.clamp(0.0, max)
    };
    let l0 = lambda.floor();
    if filter == Filter::LinearMipmapNearest || lambda <= 0.0 {
        return (l0 as usize, l0 as usize, 0.0);
    }
    (l0 as usize, (l0 + 1.0).min(max) as usize, lambda - l0)
}

/// One pixel's sample of minibatch item `item`: `C` values.
pub fn sample(
    stack: &MipStack,
    item: usize,
    uv: [f64; 2],
    level: LevelInput,
    mode: Mode,
) -> Vec<f64> {
    let Mode { filter, boundary } = mode;
    match filter {
        Filter::Nearest => nearest_texel(stack, uv, boundary).map_or_else(
            || vec![0.0; stack.channels],
            |(x, y)| stack.texel(0, item, x, y).to_vec(),
        ),
        Filter::Linear => bilinear(stack, item, 0, uv, boundary),
        Filter::LinearMipmapNearest | Filter::LinearMipmapLinear => {
            let (_, l0, l1, f) = mip_levels(stack, level, filter);
            let a = bilinear(stack, item, l0, uv, boundary);
            if f == 0.0 && l0 == l1 {
                return a;
            }
            let b = bilinear(stack, item, l1, uv, boundary);
            a.iter().zip(&b).map(|(a, b)| a + f * (b - a)).collect()
        }
    }
}

/// The four taps of bilinear filtering on one level, around `(u w − ½, v h − ½)`.
struct Taps {
    /// Texels `(x, y)` of the taps `00, 10, 01, 11` (`None`: outside, read as zero).
    texels: [Option<(usize, usize)>; 4],
    /// The weights' fractions along `s` and `t`.
    frac: [f64; 2],
    /// `ds/du` and `dt/dv`: zero where the clamp holds the coordinate.
    scale: [f64; 2],
}

impl Taps {
    /// The taps by the boundary mode: `wrap` wraps `uv` and the taps, `clamp` holds the
    /// coordinate within the edge texels' centres (on one, both taps of that axis are it, so
    /// that no gradient crosses the edge), `zero` leaves taps outside. `None` where `uv` is not
    /// finite (the sample is zero).
    fn new(level: &Level, uv: [f64; 2], boundary: Boundary) -> Option<Self> {
        let (w, h) = (level.width as f64, level.height as f64);
        let (mut u, mut v) = (uv[0], uv[1]);
        if boundary == Boundary::Wrap {
            u -= u.floor();
            v -= v.floor();
        }
        let (mut s, mut t) = (u * w - 0.5, v * h - 0.5);
        let mut scale = [w, h];
        let (mut hold_s, mut hold_t) = (false, false);
        if boundary == Boundary::Clamp {
            if !(0.0..=w - 1.0).contains(&s) {
                scale[0] = 0.0;
            }
            if !(0.0..=h - 1.0).contains(&t) {
                scale[1] = 0.0;
            }
            s = s.clamp(0.0, w - 1.0);
            t = t.clamp(0.0, h - 1.0);
            hold_s = s == 0.0 || s == w - 1.0;
            hold_t = t == 0.0 || t == h - 1.0;
        }
        if !(s.is_finite() && t.is_finite()) {
            return None;
        }
        let (s0, t0) = (s.floor(), t.floor());
        let xs = [s0 as i64, s0 as i64 + i64::from(!hold_s)];
        let ys = [t0 as i64, t0 as i64 + i64::from(!hold_t)];
        let (wi, hi) = (level.width as i64, level.height as i64);
        let tap = |x: i64, y: i64| -> Option<(usize, usize)> {
            let (x, y) = match boundary {
                Boundary::Wrap => (x.rem_euclid(wi), y.rem_euclid(hi)),
                _ => (x, y),
            };
            ((0..wi).contains(&x) && (0..hi).contains(&y)).then_some((x as usize, y as usize))
        };
        Some(Self {
            texels: [
                tap(xs[0], ys[0]),
                tap(xs[1], ys[0]),
                tap(xs[0], ys[1]),
                tap(xs[1], ys[1]),
            ],
            frac: [s - s0, t - t0],
            scale,
        })
    }

    /// Channel `k` of the four taps.
    fn values(&self, stack: &MipStack, level: usize, item: usize, k: usize) -> [f64; 4] {
        self.texels
            .map(|t| t.map_or(0.0, |(x, y)| stack.texel(level, item, x, y)[k]))
    }
}

/// Bilinear filtering on `level`.
fn bilinear(
    stack: &MipStack,
    item: usize,
    level: usize,
    uv: [f64; 2],
    boundary: Boundary,
) -> Vec<f64> {
    let Some(taps) = Taps::new(&stack.levels[level], uv, boundary) else {
        return vec![0.0; stack.channels];
    };
    let [fs, ft] = taps.frac;
    (0..stack.channels)
        .map(|k| {
            let [a00, a10, a01, a11] = taps.values(stack, level, item, k);
            let top = a00 + fs * (a10 - a00);
            let bottom = a01 + fs * (a11 - a01);
            top + ft * (bottom - top)
        })
        .collect()
}

/// One pixel's gradients to its own inputs (`texture`'s backward, besides the texels').
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelGrad {
    /// To `uv`.
    pub uv: [f64; 2],
    /// To `uv_da` (linear-mipmap-linear only: the level's fraction is its one dependence).
    pub uv_da: [f64; 4],
    /// To `mip_level_bias` (linear-mipmap-linear only).
    pub bias: f64,
}

/// The backward of [`sample`] for one pixel with output gradient `dy` (`C` values): adds the
/// texels' gradients into `tex_grad` (one vector a level, laid out as the stack's levels) and
/// returns the pixel's own. The exact derivative of the forward, piecewise: at a texel
/// centre's kink, at a level's integer `λ` and where the footprint is isotropic (where
/// nvdiffrast's expression is 0/0 and it takes no gradient, as here) the side taken is the
/// forward's.
pub fn sample_backward(
    stack: &MipStack,
    item: usize,
    uv: [f64; 2],
    level: LevelInput,
    mode: Mode,
    dy: &[f64],
    tex_grad: &mut [Vec<f64>],
) -> PixelGrad {
    let Mode { filter, boundary } = mode;
    let mut grad = PixelGrad::default();
    match filter {
        Filter::Nearest => {
            if let Some((x, y)) = nearest_texel(stack, uv, boundary) {
                add_texel(stack, tex_grad, 0, item, x, y, dy, 1.0);
            }
        }
        Filter::Linear => {
            grad.uv = bilinear_backward(stack, item, 0, uv, boundary, dy, 1.0, tex_grad);
        }
        Filter::LinearMipmapNearest | Filter::LinearMipmapLinear => {
            let (raw, l0, l1, f) = mip_levels(stack, level, filter);
            if f == 0.0 && l0 == l1 {
                grad.uv = bilinear_backward(stack, item, l0, uv, boundary, dy, 1.0, tex_grad);
                return grad;
            }
            let g0 = bilinear_backward(stack, item, l0, uv, boundary, dy, 1.0 - f, tex_grad);
            let g1 = bilinear_backward(stack, item, l1, uv, boundary, dy, f, tex_grad);
            grad.uv = [g0[0] + g1[0], g0[1] + g1[1]];
            // Through the fraction: d/dλ = Σ dy (b − a), where λ is not clamped.
            if raw > 0.0 && raw < stack.max_level() as f64 {
                let a = bilinear(stack, item, l0, uv, boundary);
                let b = bilinear(stack, item, l1, uv, boundary);
                let dl: f64 = dy
                    .iter()
                    .zip(a.iter().zip(&b))
                    .map(|(d, (a, b))| d * (b - a))
                    .sum();
                if level.bias.is_some() {
                    grad.bias = dl;
                }
                if let Some(da) = level.uv_da {
                    let base = &stack.levels[0];
                    grad.uv_da = level_gradient(da, base.width, base.height).map(|d| dl * d);
                }
            }
        }
    }
    grad
}

/// dλ/d`uv_da` of [`level_of_detail`], zero where it is not finite (an isotropic or empty
/// footprint), as nvdiffrast takes it.
pub fn level_gradient(uv_da: [f64; 4], width: usize, height: usize) -> [f64; 4] {
    let (ws, hs) = (width as f64, height as f64);
    let [ux, uy, vx, vy] = uv_da;
    let (sx, sy, tx, ty) = (ux * ws, uy * ws, vx * hs, vy * hs);
    let a = sx * sx + tx * tx;
    let b = sy * sy + ty * ty;
    let c = sx * sy + tx * ty;
    let root = (0.25 * (a - b) * (a - b) + c * c).sqrt();
    let major = 0.5 * (a + b) + root;
    // λ = ½ log2 M: dλ/dM = 1 / (2 M ln 2); M's derivatives in A, B and C.
    let k = 1.0 / (2.0 * major * std::f64::consts::LN_2);
    let (da, db, dc) = (
        k * (0.5 + 0.5 * (a - b) / (2.0 * root)),
        k * (0.5 - 0.5 * (a - b) / (2.0 * root)),
        k * c / root,
    );
    let g = [
        ws * (2.0 * sx * da + sy * dc),
        ws * (2.0 * sy * db + sx * dc),
        hs * (2.0 * tx * da + ty * dc),
        hs * (2.0 * ty * db + tx * dc),
    ];
    if g.iter().all(|v| v.is_finite()) {
        g
    } else {
        [0.0; 4]
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

/// The backward of [`bilinear`] scaled by `scale`: texel gradients into `tex_grad`, and the
/// gradient to `uv` returned.
#[allow(clippy::too_many_arguments)]
fn bilinear_backward(
    stack: &MipStack,
    item: usize,
    level: usize,
    uv: [f64; 2],
    boundary: Boundary,
    dy: &[f64],
    scale: f64,
    tex_grad: &mut [Vec<f64>],
) -> [f64; 2] {
    let Some(taps) = Taps::new(&stack.levels[level], uv, boundary) else {
        return [0.0; 2];
    };
    let [fs, ft] = taps.frac;
    let (mut dfs, mut dft) = (0.0, 0.0);
    for (k, d) in dy.iter().enumerate() {
        let [a00, a10, a01, a11] = taps.values(stack, level, item, k);
        dfs += d * ((a10 - a00) * (1.0 - ft) + (a11 - a01) * ft);
        dft += d * ((a01 + fs * (a11 - a01)) - (a00 + fs * (a10 - a00)));
    }
    let weights = [
        (1.0 - fs) * (1.0 - ft),
        fs * (1.0 - ft),
        (1.0 - fs) * ft,
        fs * ft,
    ];
    for (tap, weight) in taps.texels.iter().zip(weights) {
        if let Some((x, y)) = *tap {
            add_texel(stack, tex_grad, level, item, x, y, dy, scale * weight);
        }
    }
    [scale * dfs * taps.scale[0], scale * dft * taps.scale[1]]
}

impl MipStack {
    /// Gradients of zero for every texel of every level (what [`sample_backward`] adds into).
    pub fn zero_grads(&self) -> Vec<Vec<f64>> {
        self.levels
            .iter()
            .map(|l| vec![0.0; l.texels.len()])
            .collect()
    }

    /// The backward of [`MipStack::build`]: the levels' texel gradients carried down to the
    /// base (each level's into the 2 × 2, or 2 × 1, texels it averaged), last level first.
    pub fn pyramid_backward(&self, mut grads: Vec<Vec<f64>>) -> Vec<f64> {
        let c = self.channels;
        for level in (1..self.levels.len()).rev() {
            let (lo, hi) = grads.split_at_mut(level);
            let (above, this) = (&self.levels[level - 1], &self.levels[level]);
            let (w, h) = (above.width, above.height);
            let parent = &mut lo[level - 1];
            for item in 0..self.items {
                for y in 0..this.height {
                    for x in 0..this.width {
                        for k in 0..c {
                            let g = hi[0][((item * this.height + y) * this.width + x) * c + k];
                            let mut add = |px: usize, py: usize, share: f64| {
                                parent[((item * h + py) * w + px) * c + k] += share * g;
                            };
                            if h == 1 {
                                add(2 * x, 0, 0.5);
                                add(2 * x + 1, 0, 0.5);
                            } else if w == 1 {
                                add(0, 2 * y, 0.5);
                                add(0, 2 * y + 1, 0.5);
                            } else {
                                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                                    add(2 * x + dx, 2 * y + dy, 0.25);
                                }
                            }
                        }
                    }
                }
            }
        }
        grads.swap_remove(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2 × 2 texture of one channel: texels 1, 2 (top row), 3, 4.
    fn quad() -> MipStack {
        MipStack::base(1, 2, 2, 1, vec![1.0, 2.0, 3.0, 4.0]).unwrap()
    }

    fn one(stack: &MipStack, uv: [f64; 2], filter: Filter, boundary: Boundary) -> f64 {
        sample(
            stack,
            0,
            uv,
            LevelInput::default(),
            Mode { filter, boundary },
        )[0]
    }

    #[test]
    fn nearest_reads_the_texel_under_uv_by_each_boundary() {
        let t = quad();
        assert_eq!(one(&t, [0.2, 0.2], Filter::Nearest, Boundary::Wrap), 1.0);
        assert_eq!(one(&t, [0.7, 0.2], Filter::Nearest, Boundary::Wrap), 2.0);
        assert_eq!(one(&t, [0.2, 0.7], Filter::Nearest, Boundary::Clamp), 3.0);
        // Wrap: u = −0.2 is u = 0.8; clamp holds the edge; zero reads nothing.
        assert_eq!(one(&t, [-0.2, 0.7], Filter::Nearest, Boundary::Wrap), 4.0);
        assert_eq!(one(&t, [-0.2, 0.7], Filter::Nearest, Boundary::Clamp), 3.0);
        assert_eq!(one(&t, [-0.2, 0.7], Filter::Nearest, Boundary::Zero), 0.0);
        assert_eq!(one(&t, [1.0, 0.7], Filter::Nearest, Boundary::Zero), 0.0);
        assert_eq!(one(&t, [1.0, 0.7], Filter::Nearest, Boundary::Clamp), 4.0);
        assert_eq!(
            one(&t, [f64::NAN, 0.7], Filter::Nearest, Boundary::Clamp),
            0.0
        );
    }

    #[test]
    fn linear_blends_the_four_texels_around_uv_by_each_boundary() {
        let t = quad();
        // At a texel centre, the texel; at the texture's centre, the mean.
        assert_eq!(one(&t, [0.25, 0.25], Filter::Linear, Boundary::Clamp), 1.0);
        assert_eq!(one(&t, [0.5, 0.5], Filter::Linear, Boundary::Clamp), 2.5);
        // Halfway between the centres of texels 1 and 2: 1.5; a quarter of the way: 1.25.
        assert!((one(&t, [0.5, 0.25], Filter::Linear, Boundary::Wrap) - 1.5).abs() < 1e-15);
        assert!((one(&t, [0.375, 0.25], Filter::Linear, Boundary::Wrap) - 1.25).abs() < 1e-15);
        // u = 0 lies halfway between texel 2 (wrapped from the left) and texel 1.
        assert!((one(&t, [0.0, 0.25], Filter::Linear, Boundary::Wrap) - 1.5).abs() < 1e-15);
        // Clamp holds the edge texel's centre; zero blends the outside's zeros in.
        assert_eq!(one(&t, [0.0, 0.25], Filter::Linear, Boundary::Clamp), 1.0);
        assert!((one(&t, [0.0, 0.25], Filter::Linear, Boundary::Zero) - 0.5).abs() < 1e-15);
        assert_eq!(one(&t, [-1.0, 0.25], Filter::Linear, Boundary::Zero), 0.0);
        // Wrap is periodic in u and v.
        let a = one(&t, [0.3, 0.6], Filter::Linear, Boundary::Wrap);
        let b = one(&t, [2.3, -1.4], Filter::Linear, Boundary::Wrap);
        assert!((a - b).abs() < 1e-12, "{a} {b}");
    }

    #[test]
    fn the_mip_stack_halves_each_extent_and_refuses_odd_ones() {
        // 4 wide, 2 high: 2 × 1, then 1 × 1 (the last from two texels side by side).
        let texels: Vec<f64> = (0..8).map(f64::from).collect();
        let s = MipStack::base(1, 2, 4, 1, texels)
            .unwrap()
            .build(None)
            .unwrap();
        assert_eq!(s.max_level(), 2);
        assert_eq!((s.levels[1].width, s.levels[1].height), (2, 1));
        assert_eq!(
            s.levels[1].texels,
            [(0.0 + 1.0 + 4.0 + 5.0) / 4.0, (2.0 + 3.0 + 6.0 + 7.0) / 4.0]
        );
        assert_eq!(s.levels[2].texels, [(2.5 + 4.5) / 2.0]);
        // max_mip_level limits the levels; an odd extent above 1 is an error unless not reached.
        let t = MipStack::base(1, 2, 4, 1, vec![0.0; 8]).unwrap();
        assert_eq!(t.clone().build(Some(1)).unwrap().max_level(), 1);
        let odd = MipStack::base(1, 6, 6, 1, vec![0.0; 36]).unwrap();
        assert_eq!(odd.clone().build(Some(1)).unwrap().levels[1].width, 3);
        let err = odd.build(None).unwrap_err().to_string();
        assert!(err.contains("odd extent"), "{err}");
        // Every channel and item averaged apart.
        let two = MipStack::base(2, 2, 2, 2, (0..16).map(f64::from).collect()).unwrap();
        let two = two.build(None).unwrap();
        assert_eq!(two.levels[1].texels, [3.0, 4.0, 11.0, 12.0]);
    }

    #[test]
    fn the_level_follows_the_footprint_and_the_bias() {
        // Two texels a pixel along u: level 1; a footprint rotated 45°, the same length: 1.
        let d = LevelInput {
            uv_da: Some([2.0 / 8.0, 0.0, 0.0, 2.0 / 8.0]),
            bias: None,
        };
        assert!((level_of_detail(d, 8, 8) - 1.0).abs() < 1e-15);
        let r = 2.0 / 8.0 / 2f64.sqrt();
        let d = LevelInput {
            uv_da: Some([r, -r, r, r]),
            bias: Some(0.5),
        };
        assert!((level_of_detail(d, 8, 8) - 1.5).abs() < 1e-14);
        // Anisotropic: the major axis decides (4 texels along Y, 1 along X).
        let d = LevelInput {
            uv_da: Some([1.0 / 8.0, 0.0, 0.0, 4.0 / 8.0]),
            bias: None,
        };
        assert!((level_of_detail(d, 8, 8) - 2.0).abs() < 1e-15);
        // The bias alone.
        let d = LevelInput {
            uv_da: None,
            bias: Some(-0.25),
        };
        assert_eq!(level_of_detail(d, 8, 8), -0.25);
    }

    #[test]
    fn mipmap_modes_read_the_levels_the_level_picks() {
        let texels: Vec<f64> = (0..16).map(|i| f64::from(i * i)).collect();
        let s = MipStack::base(1, 4, 4, 1, texels)
            .unwrap()
            .build(None)
            .unwrap();
        let uv = [0.3, 0.55];
        let at = |level: usize| bilinear(&s, 0, level, uv, Boundary::Clamp)[0];
        let with = |bias: f64, filter: Filter| {
            let level = LevelInput {
                uv_da: None,
                bias: Some(bias),
            };
            sample(
                &s,
                0,
                uv,
                level,
                Mode {
                    filter,
                    boundary: Boundary::Clamp,
                },
            )[0]
        };
        // λ = 1.5: the floor's level alone, or the two mixed halfway.
        assert_eq!(with(1.5, Filter::LinearMipmapNearest), at(1));
        assert!((with(1.5, Filter::LinearMipmapLinear) - 0.5 * (at(1) + at(2))).abs() < 1e-12);
        // Clamped to [0, the last level]; magnification reads level 0.
        assert_eq!(with(7.0, Filter::LinearMipmapLinear), at(2));
        assert_eq!(with(-3.0, Filter::LinearMipmapLinear), at(0));
        // A zero footprint (log2 0 = −∞) is magnification.
        let zero = LevelInput {
            uv_da: Some([0.0; 4]),
            bias: None,
        };
        assert_eq!(
            sample(
                &s,
                0,
                uv,
                zero,
                Mode {
                    filter: Filter::LinearMipmapLinear,
                    boundary: Boundary::Clamp
                }
            )[0],
            at(0)
        );
        // Linear never reads the levels.
        assert_eq!(with(1.5, Filter::Linear), at(0));
    }

    #[test]
    fn modes_parse_as_nvdiffrast_names_them() {
        assert_eq!(Filter::parse("auto", false, None).unwrap(), Filter::Linear);
        assert_eq!(
            Filter::parse("auto", true, None).unwrap(),
            Filter::LinearMipmapLinear
        );
        assert_eq!(
            Filter::parse("linear-mipmap-linear", true, Some(0)).unwrap(),
            Filter::Linear
        );
        assert!(Filter::parse("linear-mipmap-nearest", false, None).is_err());
        assert!(Filter::parse("cubic", false, None).is_err());
        assert_eq!(Boundary::parse("zero").unwrap(), Boundary::Zero);
        assert!(Boundary::parse("cube").is_err());
        assert!(Boundary::parse("mirror").is_err());
        assert!(MipStack::base(1, 2, 2, 1, vec![0.0; 3]).is_err());
        assert!(MipStack::base(1, 0, 2, 1, vec![]).is_err());
    }

    /// A deterministic pseudo-random stream in [0, 1).
    pub(super) fn stream(seed: u64) -> impl FnMut() -> f64 {
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Whether `x` lies within `margin` of an integer (a kink of the piecewise forward).
    pub(super) fn near_integer(x: f64, margin: f64) -> bool {
        (x - x.round()).abs() < margin
    }

    /// Every gradient of one pixel against central differences of the forward, per component,
    /// on an 8 × 4 texture of 3 channels and its mip stack, in every filter and boundary mode,
    /// away from the kinks (counted: the draws skipped).
    #[test]
    fn the_backward_matches_central_differences_in_every_mode() {
        let mut rnd = stream(7);
        let (w, h, c) = (8usize, 4usize, 3usize);
        let base: Vec<f64> = (0..w * h * c).map(|_| rnd()).collect();
        let stack_of = |texels: Vec<f64>, filter: Filter| {
            let s = MipStack::base(1, h, w, c, texels).unwrap();
            if filter.uses_mips() {
                s.build(None).unwrap()
            } else {
                s
            }
        };
        let eps = 1e-6;
        let bound = |analytic: f64, numeric: f64| {
            (analytic - numeric).abs() <= 1e-6 * (1.0 + numeric.abs())
        };
        let (mut checked, mut skipped) = (0, 0);
        for filter in [
            Filter::Nearest,
            Filter::Linear,
            Filter::LinearMipmapNearest,
            Filter::LinearMipmapLinear,
        ] {
            for boundary in [Boundary::Wrap, Boundary::Clamp, Boundary::Zero] {
                let stack = stack_of(base.clone(), filter);
                for _ in 0..12 {
                    let uv = [rnd() * 1.6 - 0.3, rnd() * 1.6 - 0.3];
                    let level = LevelInput {
                        uv_da: Some([
                            (rnd() - 0.3) * 0.6,
                            (rnd() - 0.5) * 0.2,
                            (rnd() - 0.5) * 0.2,
                            (rnd() - 0.3) * 0.9,
                        ]),
                        bias: Some(rnd() - 0.5),
                    };
                    let dy: Vec<f64> = (0..c).map(|_| rnd() - 0.5).collect();
                    // The kinks: texel-centre fractions at every level, integer λ, the clamp.
                    let lambda = level_of_detail(level, w, h);
                    let kinked = (0..stack.levels.len()).any(|l| {
                        let lw = stack.levels[l].width as f64;
                        let lh = stack.levels[l].height as f64;
                        let (u, v) = (uv[0] - uv[0].floor(), uv[1] - uv[1].floor());
                        near_integer(uv[0] * lw - 0.5, 1e-3)
                            || near_integer(uv[1] * lh - 0.5, 1e-3)
                            || near_integer(u * lw, 1e-3)
                            || near_integer(v * lh, 1e-3)
                            || near_integer(uv[0] * lw, 1e-3)
                            || near_integer(uv[1] * lh, 1e-3)
                    }) || near_integer(lambda, 1e-3)
                        || near_integer(lambda - stack.max_level() as f64, 1e-3);
                    if kinked {
                        skipped += 1;
                        continue;
                    }
                    let loss = |stack: &MipStack, uv: [f64; 2], level: LevelInput| -> f64 {
                        sample(stack, 0, uv, level, Mode { filter, boundary })
                            .iter()
                            .zip(&dy)
                            .map(|(a, b)| a * b)
                            .sum()
                    };
                    let mut tex_grad = stack.zero_grads();
                    let g = sample_backward(
                        &stack,
                        0,
                        uv,
                        level,
                        Mode { filter, boundary },
                        &dy,
                        &mut tex_grad,
                    );
                    let what = format!("{filter:?} {boundary:?} uv {uv:?}");
                    for k in 0..2 {
                        let (mut a, mut b) = (uv, uv);
                        a[k] += eps;
                        b[k] -= eps;
                        let n = (loss(&stack, a, level) - loss(&stack, b, level)) / (2.0 * eps);
                        assert!(
                            bound(g.uv[k], n),
                            "{what}: d/duv[{k}] {} numeric {n}",
                            g.uv[k]
                        );
                    }
                    for k in 0..4 {
                        let (mut a, mut b) = (level, level);
                        a.uv_da.as_mut().unwrap()[k] += eps;
                        b.uv_da.as_mut().unwrap()[k] -= eps;
                        let n = (loss(&stack, uv, a) - loss(&stack, uv, b)) / (2.0 * eps);
                        assert!(
                            bound(g.uv_da[k], n),
                            "{what}: d/duv_da[{k}] {} numeric {n}",
                            g.uv_da[k]
                        );
                    }
                    let (mut a, mut b) = (level, level);
                    a.bias = a.bias.map(|x| x + eps);
                    b.bias = b.bias.map(|x| x - eps);
                    let n = (loss(&stack, uv, a) - loss(&stack, uv, b)) / (2.0 * eps);
                    assert!(bound(g.bias, n), "{what}: d/dbias {} numeric {n}", g.bias);
                    // The base texture's texels, through the pyramid (the stack rebuilt each time).
                    let to_base = stack.pyramid_backward(tex_grad);
                    for i in 0..base.len() {
                        let (mut a, mut b) = (base.clone(), base.clone());
                        a[i] += eps;
                        b[i] -= eps;
                        let n = (loss(&stack_of(a, filter), uv, level)
                            - loss(&stack_of(b, filter), uv, level))
                            / (2.0 * eps);
                        assert!(
                            bound(to_base[i], n),
                            "{what}: d/dtex[{i}] {} numeric {n}",
                            to_base[i]
                        );
                    }
                    checked += 1;
                }
            }
        }
        assert!(
            checked >= 100 && skipped * 4 < checked,
            "{checked} checked, {skipped} skipped"
        );
    }

    /// The level's gradient is zero where the footprint is isotropic (0/0), as nvdiffrast's.
    #[test]
    fn an_isotropic_footprint_gives_the_level_no_gradient() {
        assert_eq!(level_gradient([0.25, 0.0, 0.0, 0.25], 8, 8), [0.0; 4]);
        assert_eq!(level_gradient([0.0; 4], 8, 8), [0.0; 4]);
        assert!(
            level_gradient([0.25, 0.0, 0.0, 0.5], 8, 8)
                .iter()
                .any(|g| *g != 0.0)
        );
    }

    #[test]
    fn a_shared_texture_serves_every_minibatch_item() {
        let t = quad();
        let mode = Mode {
            filter: Filter::Linear,
            boundary: Boundary::Wrap,
        };
        let at = |item| sample(&t, item, [0.4, 0.6], LevelInput::default(), mode);
        let (a, b) = (at(0), at(3));
        assert_eq!(a, b);
    }
}
