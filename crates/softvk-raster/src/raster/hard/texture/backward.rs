//! The backward: a lookup's gradients to its texels, `uv`, `uv_da` and bias
//! ([`sample_backward`]), the level's gradient in the footprint, and the mip pyramid's gradient
//! carried up to the base ([`MipStack::pyramid_backward`]).

use super::bilinear::{bilinear, bilinear_backward};
use super::forward::{mip_levels, nearest_texel};
use super::{Filter, LevelInput, MipStack, Mode, add_texel};
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

/// The backward of [`sample`](super::sample) for one pixel with output gradient `dy` (`C` values):
/// adds the texels' gradients into `tex_grad` (one vector a level, laid out as the stack's levels)
/// and returns the pixel's own. The exact derivative of the forward, piecewise: at a texel centre's
/// kink, at a level's integer `λ` and where the footprint is isotropic (where nvdiffrast's
/// expression is 0/0 and it takes no gradient, as here) the side taken is the forward's.
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

/// dλ/d`uv_da` of [`level_of_detail`](super::level_of_detail), zero where it is not finite (an
/// isotropic or empty footprint), as nvdiffrast takes it.
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
