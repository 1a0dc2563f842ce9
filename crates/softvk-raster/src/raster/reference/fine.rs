//! The fine pass of the f64 forward, once per pixel ([`shade_pixel`]): one loop over the faces,
//! each visible one folded into running aggregates for alpha ([`AlphaAccum`]), softmax colour
//! ([`SoftmaxAccum`]) and hard colour ([`HardAccum`]), whose final state ([`PixelAux`]) is what
//! the backward reads.

use super::color::FaceColors;
use super::coverage::{barycentric, clip_barycentric, coverage, depth, inside_closed};
use super::setup::{FaceSetup, outside_bbox};
use crate::raster::settings::{Alpha, RasterSettings, Rgb};

/// Running alpha aggregate over the non-ignored faces.
///
/// The product keeps its factors `1 − D` that are exactly 0 (a face whose coverage rounds to
/// 1, as every pixel well inside a face does at SoftRas's σ) as a count, and multiplies only the
/// others. The alpha is the same; but the backward's `∂A/∂D_j = Π_{k≠j}(1 − D_k)` then comes
/// out exactly, from the count and the product, for every j, without re-running the faces
/// (dividing the full product by `1 − D_j` would give 0/0).
#[derive(Clone, Copy, Debug)]
pub struct AlphaAccum {
    mode: Alpha,
    /// Prod: `Π(1 − D)` over the non-zero factors; sum: `Σ D`; hard: 1 once any `D > 0.5`.
    acc: f64,
    /// Prod: how many factors `1 − D` were exactly 0.
    zeros: u32,
}

impl AlphaAccum {
    /// Empty aggregate.
    pub fn new(mode: Alpha) -> AlphaAccum {
        let acc = if mode == Alpha::Prod { 1.0 } else { 0.0 };
        AlphaAccum {
            mode,
            acc,
            zeros: 0,
        }
    }

    /// Adds one face's coverage.
    pub fn add(&mut self, d: f64) {
        match self.mode {
            Alpha::Prod => {
                let factor = 1.0 - d;
                if factor == 0.0 {
                    self.zeros += 1;
                } else {
                    self.acc *= factor;
                }
            }
            Alpha::Sum => self.acc += d,
            Alpha::Hard => {
                if d > 0.5 {
                    self.acc = 1.0;
                }
            }
        }
    }

    /// The pixel's alpha; `face_count` is the mesh's F for the sum mode.
    pub fn resolve(&self, face_count: usize) -> f64 {
        match self.mode {
            Alpha::Prod if self.zeros > 0 => 1.0,
            Alpha::Prod => 1.0 - self.acc,
            Alpha::Sum => self.acc / face_count as f64,
            Alpha::Hard => self.acc,
        }
    }
}

/// Running softmax colour aggregate
/// `I = (Σ_j D_j e^{z̄_j/γ} C_j + e^{ε/γ} C_b) / (Σ_j D_j e^{z̄_j/γ} + e^{ε/γ})`.
///
/// Numerator and denominator are kept scaled by `e^{−max/γ}`, `max` the largest exponent seen
/// (starting with the background's ε), so every `exp` has a non-positive argument and nothing
/// overflows even for γ = 1e-6. SoftRas starts its scaled sum at `e^{ε/γ}` instead of 1, which
/// weights the background by `e^{2ε/γ}`; the SPEC's `e^{ε/γ}` is used here.
#[derive(Clone, Copy, Debug)]
pub struct SoftmaxAccum {
    max: f64,
    sum: f64,
    rgb: [f64; 3],
}

impl SoftmaxAccum {
    /// The background term alone.
    pub fn new(background: [f64; 3], eps: f64) -> SoftmaxAccum {
        SoftmaxAccum {
            max: eps,
            sum: 1.0,
            rgb: background,
        }
    }

    /// Adds face colour `color` with coverage `d` at normalized depth `z_norm = (far−z)/(far−near)`.
    pub fn add(&mut self, z_norm: f64, d: f64, color: [f64; 3], gamma: f64) {
        if z_norm > self.max {
            let rescale = ((self.max - z_norm) / gamma).exp();
            self.sum *= rescale;
            self.rgb = self.rgb.map(|c| c * rescale);
            self.max = z_norm;
        }
        let weight = d * ((z_norm - self.max) / gamma).exp();
        self.sum += weight;
        for (c, f) in self.rgb.iter_mut().zip(color) {
            *c += weight * f;
        }
    }

    /// The aggregated colour. The sum is positive: it holds the largest term, `D·e⁰`, with
    /// `D > ε_d` for any counted face, or the background's 1.
    pub fn resolve(&self) -> [f64; 3] {
        self.rgb.map(|c| c / self.sum)
    }

    /// The running maximum of `z̄` (at least the background's ε).
    pub fn max(&self) -> f64 {
        self.max
    }

    /// The denominator, scaled by `e^{−max/γ}`.
    pub fn sum(&self) -> f64 {
        self.sum
    }
}

/// Running hard colour: the nearest face whose pixel is inside (ties keep the first).
#[derive(Clone, Copy, Debug)]
pub struct HardAccum {
    depth: f64,
    rgb: [f64; 3],
    face: u32,
}

/// [`HardAccum::face`] and [`PixelAux::hard_face`] of the background.
pub const NO_FACE: u32 = u32::MAX;

impl HardAccum {
    /// Background only.
    pub fn new(background: [f64; 3]) -> HardAccum {
        HardAccum {
            depth: f64::INFINITY,
            rgb: background,
            face: NO_FACE,
        }
    }

    /// Offers face `face` at depth `z`; kept if strictly nearer than all before.
    pub fn add(&mut self, z: f64, color: [f64; 3], face: u32) {
        if z < self.depth {
            self.depth = z;
            self.rgb = color;
            self.face = face;
        }
    }

    /// The winning colour, or the background.
    pub fn resolve(&self) -> [f64; 3] {
        self.rgb
    }

    /// The winning face, or [`NO_FACE`].
    pub fn face(&self) -> u32 {
        self.face
    }
}

/// What the backward pass needs of a pixel's forward besides its colour: the running
/// aggregates' final state, so that the backward visits each face once, independently of the
/// others, and never re-runs the forward. One per *rendered* pixel (2× with anti-aliasing).
///
/// The f64 twin of the GPU's `PixelAux` (`raster_brute.comp`, [`crate::raster::fine::PixelAux`])
/// extended by `alpha_zeros`; the GPU keeps the softmax maximum as the depth whose `z̄` it is,
/// `softmax_max = (far − softmax_ref_depth) / (far − near)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelAux {
    /// Softmax: the running maximum of `z̄` (at least the background's ε).
    pub softmax_max: f64,
    /// Softmax: the denominator `S = Σ_j D_j e^{(z̄_j − max)/γ} + e^{(ε − max)/γ}`.
    pub softmax_sum: f64,
    /// Alpha prod: `Π(1 − D_j)` over the factors that are not exactly 0; sum: `Σ D_j`; hard: 0
    /// or 1.
    pub alpha_acc: f64,
    /// Alpha prod: the number of factors `1 − D_j` that are exactly 0.
    pub alpha_zeros: u32,
    /// Hard colour: the face whose colour the pixel shows, or [`NO_FACE`].
    pub hard_face: u32,
}

/// The fine pass for one pixel centre: every face, in order, into the running aggregates.
///
/// `cull` skips faces whose grown box excludes the pixel, as SoftRas's `check_border` and the
/// GPU binning do; since the box is conservative this changes nothing (a test checks), it only
/// makes the oracle fast enough for real meshes.
pub fn shade_pixel(
    faces: &[FaceSetup],
    colors: &FaceColors,
    xp: f64,
    yp: f64,
    s: &RasterSettings,
    cull: bool,
) -> [f64; 4] {
    shade_pixel_aux(faces, colors, xp, yp, s, cull).0
}

/// [`shade_pixel`], also returning the aggregates' final state that the backward reads.
pub fn shade_pixel_aux(
    faces: &[FaceSetup],
    colors: &FaceColors,
    xp: f64,
    yp: f64,
    s: &RasterSettings,
    cull: bool,
) -> ([f64; 4], PixelAux) {
    let t = s.cutoff();
    let mut alpha = AlphaAccum::new(s.alpha);
    let mut soft = SoftmaxAccum::new(s.background, s.eps);
    let mut hard = HardAccum::new(s.background);
    for (j, face) in faces.iter().enumerate() {
        if !face.finite || (cull && outside_bbox(&face.bbox, xp, yp)) {
            continue;
        }
        let w = barycentric(face, xp, yp);
        let Some(d) = coverage(face, &w, xp, yp, s.dist, s.sigma, t) else {
            continue;
        };
        // Alpha counts every non-ignored face, whatever its depth or facing.
        alpha.add(d);

        let w_clip = clip_barycentric(w);
        let z = depth(face, &w_clip);
        // Written so that a NaN depth is dropped too.
        if !(z >= s.near && z <= s.far) {
            continue;
        }
        if !(s.double_sided || face.front) {
            continue;
        }
        match s.rgb {
            Rgb::Softmax => {
                let z_norm = (s.far - z) / (s.far - s.near);
                soft.add(z_norm, d, colors.sample(j, &w_clip), s.gamma);
            }
            Rgb::Hard => {
                if inside_closed(&w) {
                    hard.add(z, colors.sample(j, &w_clip), j as u32);
                }
            }
        }
    }
    let rgb = match s.rgb {
        Rgb::Softmax => soft.resolve(),
        Rgb::Hard => hard.resolve(),
    };
    let aux = PixelAux {
        softmax_max: soft.max(),
        softmax_sum: soft.sum(),
        alpha_acc: alpha.acc,
        alpha_zeros: alpha.zeros,
        hard_face: hard.face(),
    };
    ([rgb[0], rgb[1], rgb[2], alpha.resolve(faces.len())], aux)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn softmax_matches_the_direct_formula() {
        // Direct evaluation with moderate γ, where the plain exponentials are representable.
        let (gamma, eps, bg) = (0.05, 1e-3, [0.1, 0.2, 0.3]);
        let terms = [
            (0.9, 0.7, [1.0, 0.0, 0.0]),
            (0.95, 0.2, [0.0, 1.0, 0.0]),
            (0.5, 0.99, [0.0, 0.0, 1.0]),
        ];
        let mut acc = SoftmaxAccum::new(bg, eps);
        let mut num = bg.map(|c| c * (eps / gamma).exp());
        let mut den = (eps / gamma).exp();
        for &(z, d, c) in &terms {
            acc.add(z, d, c, gamma);
            let e = d * (z / gamma).exp();
            den += e;
            for k in 0..3 {
                num[k] += e * c[k];
            }
        }
        let got = acc.resolve();
        for k in 0..3 {
            assert!((got[k] - num[k] / den).abs() < 1e-12);
        }
    }

    #[test]
    fn alpha_modes_aggregate_as_specified() {
        let mut a = AlphaAccum::new(Alpha::Prod);
        a.add(0.5);
        a.add(0.5);
        assert_eq!(a.resolve(10), 0.75);
        let mut a = AlphaAccum::new(Alpha::Sum);
        a.add(0.5);
        a.add(0.25);
        assert_eq!(a.resolve(3), 0.25);
        let mut a = AlphaAccum::new(Alpha::Hard);
        a.add(0.4);
        assert_eq!(a.resolve(1), 0.0);
        a.add(0.6);
        assert_eq!(a.resolve(1), 1.0);
    }
}
