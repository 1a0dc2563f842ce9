//! The forward lookup: a pixel's mip level from its footprint and bias, the levels it blends,
//! the nearest texel by each boundary mode, and [`sample`].

use super::bilinear::bilinear;
use super::{Boundary, Filter, MipStack, Mode};
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
pub(super) fn nearest_texel(
    stack: &MipStack,
    uv: [f64; 2],
    boundary: Boundary,
) -> Option<(usize, usize)> {
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
pub(super) fn mip_levels(
    stack: &MipStack,
    level: LevelInput,
    filter: Filter,
) -> (f64, usize, usize, f64) {
    let base = &stack.levels[0];
    let raw = level_of_detail(level, base.width, base.height);
    let (l0, l1, f) = pick_levels(stack, raw, filter);
    (raw, l0, l1, f)
}

/// The levels an unclamped `λ` picks: `(⌊λ⌋, ⌊λ⌋ + 1 within the stack, λ's fraction)`, `λ`
/// clamped to `[0, the last level]` (NaN to 0), the fraction 0 for `linear-mipmap-nearest`
/// and where λ is clamped to 0.
pub(super) fn pick_levels(stack: &MipStack, raw: f64, filter: Filter) -> (usize, usize, f64) {
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
