//! Bilinear filtering on one level: the four taps around `uv` by each boundary mode, the
//! blend, and its backward to the texels and `uv`.

use super::{Boundary, Level, MipStack, add_texel};
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
pub(super) fn bilinear(
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

/// The backward of [`bilinear`] scaled by `scale`: texel gradients into `tex_grad`, and the
/// gradient to `uv` returned.
#[allow(clippy::too_many_arguments)]
pub(super) fn bilinear_backward(
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
