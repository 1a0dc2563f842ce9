//! The f64 twin of nvdiffrast's `texture` and `texture_construct_mip` for 2D textures, forward:
//! the reference the texture kernels will be held to. Cube maps and the backward come next.
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
//!   `C = s_X s_Y + t_X t_Y`, and `λ = ½ log2` of it; without `uv_da`, `λ = 0`. `mip_level_bias` is added, and `λ` clamped to
//!   `[0, the last level]`.
//! - **The mip stack** ([`MipStack::build`]). Each level halves each extent above 1 (an extent
//!   of 1 stays 1), averaging 2 × 2 texels (2 × 1 where the level above is one texel high or
//!   wide), until both extents are 1 or `max_mip_level` levels are built; an odd extent above 1
//!   cannot be halved and is an error, as in nvdiffrast (resize the texture, or limit
//!   `max_mip_level`).

use crate::error::{Error, Result};

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
                "texture: boundary_mode 'cube' (cube maps) is not supported yet".into(),
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

/// One pixel's sample of minibatch item `item`: `C` values.
pub fn sample(
    stack: &MipStack,
    item: usize,
    uv: [f64; 2],
    level: LevelInput,
    filter: Filter,
    boundary: Boundary,
) -> Vec<f64> {
    let c = stack.channels;
    let base = &stack.levels[0];
    match filter {
        Filter::Nearest => {
            let (mut u, mut v) = (uv[0], uv[1]);
            if boundary == Boundary::Wrap {
                u -= u.floor();
                v -= v.floor();
            }
            let (w, h) = (base.width as f64, base.height as f64);
            let (x, y) = ((u * w).floor(), (v * h).floor());
            if !(x.is_finite() && y.is_finite()) {
                return vec![0.0; c];
            }
            if boundary == Boundary::Zero && (x < 0.0 || x >= w || y < 0.0 || y >= h) {
                return vec![0.0; c];
            }
            let x = x.clamp(0.0, w - 1.0) as usize;
            let y = y.clamp(0.0, h - 1.0) as usize;
            stack.texel(0, item, x, y).to_vec()
        }
        Filter::Linear => bilinear(stack, item, 0, uv, boundary),
        Filter::LinearMipmapNearest | Filter::LinearMipmapLinear => {
            let max = stack.max_level() as f64;
            let lambda = level_of_detail(level, base.width, base.height);
            // NaN (a zero footprint without a bias gives −∞, which clamps to 0) clamps to 0.
            let lambda = if lambda.is_nan() {
                0.0
            } else {
                lambda.clamp(0.0, max)
            };
            let l0 = lambda.floor();
            let a = bilinear(stack, item, l0 as usize, uv, boundary);
            if filter == Filter::LinearMipmapNearest || lambda <= 0.0 {
                return a;
            }
            let l1 = (l0 + 1.0).min(max);
            let f = lambda - l0;
            let b = bilinear(stack, item, l1 as usize, uv, boundary);
            a.iter().zip(&b).map(|(a, b)| a + f * (b - a)).collect()
        }
    }
}

/// Bilinear filtering on `level`: the four taps around `(u w − ½, v h − ½)`, weights by the
/// fraction, each tap by the boundary mode.
fn bilinear(
    stack: &MipStack,
    item: usize,
    level: usize,
    uv: [f64; 2],
    boundary: Boundary,
) -> Vec<f64> {
    let c = stack.channels;
    let l = &stack.levels[level];
    let (w, h) = (l.width as f64, l.height as f64);
    let (mut u, mut v) = (uv[0], uv[1]);
    if boundary == Boundary::Wrap {
        u -= u.floor();
        v -= v.floor();
    }
    let (mut s, mut t) = (u * w - 0.5, v * h - 0.5);
    let (mut hold_s, mut hold_t) = (false, false);
    if boundary == Boundary::Clamp {
        s = s.clamp(0.0, w - 1.0);
        t = t.clamp(0.0, h - 1.0);
        // On an edge texel's centre both taps are that texel (no gradient across the edge).
        hold_s = s == 0.0 || s == w - 1.0;
        hold_t = t == 0.0 || t == h - 1.0;
    }
    if !(s.is_finite() && t.is_finite()) {
        return vec![0.0; c];
    }
    let (s0, t0) = (s.floor(), t.floor());
    let (fs, ft) = (s - s0, t - t0);
    let xs = [s0 as i64, s0 as i64 + i64::from(!hold_s)];
    let ys = [t0 as i64, t0 as i64 + i64::from(!hold_t)];
    let (wi, hi) = (l.width as i64, l.height as i64);
    let tap = |x: i64, y: i64| -> Option<(usize, usize)> {
        let (x, y) = match boundary {
            Boundary::Wrap => (x.rem_euclid(wi), y.rem_euclid(hi)),
            _ => (x, y),
        };
        ((0..wi).contains(&x) && (0..hi).contains(&y)).then_some((x as usize, y as usize))
    };
    let read = |x: i64, y: i64, k: usize| {
        tap(x, y).map_or(0.0, |(x, y)| stack.texel(level, item, x, y)[k])
    };
    (0..c)
        .map(|k| {
            let top = read(xs[0], ys[0], k) + fs * (read(xs[1], ys[0], k) - read(xs[0], ys[0], k));
            let bottom =
                read(xs[0], ys[1], k) + fs * (read(xs[1], ys[1], k) - read(xs[0], ys[1], k));
            top + ft * (bottom - top)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2 × 2 texture of one channel: texels 1, 2 (top row), 3, 4.
    fn quad() -> MipStack {
        MipStack::base(1, 2, 2, 1, vec![1.0, 2.0, 3.0, 4.0]).unwrap()
    }

    fn one(stack: &MipStack, uv: [f64; 2], filter: Filter, boundary: Boundary) -> f64 {
        sample(stack, 0, uv, LevelInput::default(), filter, boundary)[0]
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
            sample(&s, 0, uv, level, filter, Boundary::Clamp)[0]
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
            sample(&s, 0, uv, zero, Filter::LinearMipmapLinear, Boundary::Clamp)[0],
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

    #[test]
    fn a_shared_texture_serves_every_minibatch_item() {
        let t = quad();
        let a = sample(
            &t,
            0,
            [0.4, 0.6],
            LevelInput::default(),
            Filter::Linear,
            Boundary::Wrap,
        );
        let b = sample(
            &t,
            3,
            [0.4, 0.6],
            LevelInput::default(),
            Filter::Linear,
            Boundary::Wrap,
        );
        assert_eq!(a, b);
    }
}
