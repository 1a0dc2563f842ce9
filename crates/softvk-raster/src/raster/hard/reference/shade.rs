//! The rasterizer's per-pixel function ([`shade`]): barycentrics, `z/w` and their pixel
//! derivatives from homogeneous 2D edge functions, on f64 for the forward and on duals for the
//! backward.

use super::super::dual::Dual;
/// The arithmetic the per-pixel function needs: f64 for the forward, [`Dual`] for the
/// backward.
pub trait Scalar:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Mul<f64, Output = Self>
    + std::ops::Div<Output = Self>
{
    /// A constant.
    fn of(c: f64) -> Self;
    /// The value.
    fn value(self) -> f64;
    /// Clamped to `[lo, hi]`.
    fn clamp_to(self, lo: f64, hi: f64) -> Self;
    /// The larger of `self` and `c`.
    fn at_least(self, c: f64) -> Self;
}

impl Scalar for f64 {
    fn of(c: f64) -> Self {
        c
    }
    fn value(self) -> f64 {
        self
    }
    fn clamp_to(self, lo: f64, hi: f64) -> Self {
        self.clamp(lo, hi)
    }
    fn at_least(self, c: f64) -> Self {
        self.max(c)
    }
}

impl<const N: usize> Scalar for Dual<N> {
    fn of(c: f64) -> Self {
        Dual::constant(c)
    }
    fn value(self) -> f64 {
        self.value
    }
    fn clamp_to(self, lo: f64, hi: f64) -> Self {
        self.clamp(lo, hi)
    }
    fn at_least(self, c: f64) -> Self {
        self.max_constant(c)
    }
}

/// What a drawn pixel reports, for the triangle `p` (clip space) at NDC `f`: the
/// perspective-correct barycentrics of vertices 0 and 1, clamped (each to [0, 1], their sum
/// to at most 1); `z/w` unclamped; and `(du/dX, du/dY, dv/dX, dv/dY)` per pixel (from the
/// clamped u, v, as nvdiffrast).
#[derive(Clone, Copy, Debug)]
pub struct Shaded<T> {
    /// u, v.
    pub uv: [T; 2],
    /// z/w before the output's clamp.
    pub zw: f64,
    /// The pixel derivatives.
    pub db: [T; 4],
}

/// The per-pixel function of the rasterizer (and its backward, on duals). Homogeneous 2D edge
/// functions of the pixel centre: `p_k' = (x_k − f_x w_k, y_k − f_y w_k)`, `a_0 = p_1' × p_2'`,
/// `a_1 = p_2' × p_0'`, `a_2 = p_0' × p_1'`; `u = a_0 / Σa`, `v = a_1 / Σa`,
/// `z/w = Σ z_k a_k / Σ w_k a_k`. The pixel derivatives follow from `∂a_k/∂f_x` and `∂a_k/∂f_y`
/// (which do not depend on the pixel) and `∂f/∂X = 2/W`, `∂f/∂Y = 2/H`.
pub fn shade<T: Scalar>(
    xyw: [[T; 3]; 3],
    z: [f64; 3],
    f: [f64; 2],
    width: u32,
    height: u32,
) -> Shaded<T> {
    let rel: [[T; 2]; 3] =
        std::array::from_fn(|k| [xyw[k][0] - xyw[k][2] * f[0], xyw[k][1] - xyw[k][2] * f[1]]);
    let area = |i: usize, j: usize| rel[i][0] * rel[j][1] - rel[i][1] * rel[j][0];
    let a = [area(1, 2), area(2, 0), area(0, 1)];
    let at = a[0] + a[1] + a[2];
    let iw = T::of(1.0) / at;
    let wsum = a[0] * xyw[0][2] + a[1] * xyw[1][2] + a[2] * xyw[2][2];
    let zsum = a[0].value() * z[0] + a[1].value() * z[1] + a[2].value() * z[2];
    let zw = zsum / wsum.value();
    let u0 = (a[0] * iw).clamp_to(0.0, 1.0);
    let v0 = (a[1] * iw).clamp_to(0.0, 1.0);
    let scale = T::of(1.0) / (u0 + v0).at_least(1.0);
    let (u, v) = (u0 * scale, v0 * scale);
    // ∂a_k/∂f: a_0 = p_1' × p_2' with ∂p_k'/∂f_x = (−w_k, 0), ∂p_k'/∂f_y = (0, −w_k).
    let dadf = |i: usize, j: usize| {
        [
            xyw[i][1] * xyw[j][2] - xyw[i][2] * xyw[j][1],
            xyw[i][2] * xyw[j][0] - xyw[i][0] * xyw[j][2],
        ]
    };
    let da = [dadf(1, 2), dadf(2, 0), dadf(0, 1)];
    let dat = [
        da[0][0] + da[1][0] + da[2][0],
        da[0][1] + da[1][1] + da[2][1],
    ];
    let sx = T::of(2.0 / f64::from(width)) * iw;
    let sy = T::of(2.0 / f64::from(height)) * iw;
    let db = [
        sx * (da[0][0] - u * dat[0]),
        sy * (da[0][1] - u * dat[1]),
        sx * (da[1][0] - v * dat[0]),
        sy * (da[1][1] - v * dat[1]),
    ];
    Shaded { uv: [u, v], zw, db }
}
