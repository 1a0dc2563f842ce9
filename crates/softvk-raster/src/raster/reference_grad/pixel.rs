//! Step 2 of the f64 backward, per pixel and face ([`pixel_face_grad`]): one face's share of a
//! pixel's gradient, from the pixel's upstream gradient and the forward's aggregates
//! ([`PixelUpstream`]) alone, through colour, depth, the clip, the coverage and the
//! barycentrics to the face's screen vertices.

use super::dot3;
use crate::raster::reference::{
    self, FaceColors, FaceSetup, PixelAux, barycentric, clip_barycentric, coverage, depth,
    dist2_point_segment, outside_bbox, surface_texel_index,
};
use crate::raster::settings::{Alpha, Dist, RasterSettings, Rgb};

/// What every face's contribution at one pixel needs: the pixel centre, its upstream gradient
/// and the forward's aggregates. Built once per pixel.
#[derive(Clone, Copy, Debug)]
pub struct PixelUpstream {
    /// Pixel centre x (screen).
    pub xp: f64,
    /// Pixel centre y (screen).
    pub yp: f64,
    /// dL/d(RGB) of the rendered pixel.
    pub d_rgb: [f64; 3],
    /// dL/d(alpha) of the rendered pixel.
    pub d_alpha: f64,
    /// `d_rgb · I`, I the pixel's colour.
    pub d_rgb_dot_color: f64,
    /// `1 / S`, S the softmax denominator.
    pub inv_softmax_sum: f64,
    /// The aggregates.
    pub aux: PixelAux,
    /// The mesh's face count F (alpha sum).
    pub face_count: usize,
}

impl PixelUpstream {
    /// From the rendered pixel's RGBA, its aux and its upstream gradient.
    pub fn new(
        (xp, yp): (f64, f64),
        rgba: [f64; 4],
        aux: PixelAux,
        d_rgba: [f64; 4],
        face_count: usize,
    ) -> PixelUpstream {
        let d_rgb = [d_rgba[0], d_rgba[1], d_rgba[2]];
        PixelUpstream {
            xp,
            yp,
            d_rgb,
            d_alpha: d_rgba[3],
            d_rgb_dot_color: dot3(d_rgb, [rgba[0], rgba[1], rgba[2]]),
            inv_softmax_sum: 1.0 / aux.softmax_sum,
            aux,
            face_count,
        }
    }

    /// No gradient reaches this pixel: every face's contribution is zero.
    pub fn is_zero(&self) -> bool {
        self.d_alpha == 0.0 && self.d_rgb == [0.0; 3]
    }

    /// `dL/dA · ∂A/∂D_j` for a face of coverage `d`, exactly: the prod's `Π_{k≠j}(1 − D_k)`
    /// comes from the count of zero factors and the product of the others, with the factor
    /// `1 − d` computed as the forward computes it.
    pub fn alpha_grad(&self, d: f64, mode: Alpha) -> f64 {
        match mode {
            Alpha::Prod => {
                let factor = 1.0 - d;
                let others = match (factor == 0.0, self.aux.alpha_zeros) {
                    // This face is the only zero factor: the others are all in the product.
                    (true, 1) => self.aux.alpha_acc,
                    (false, 0) => self.aux.alpha_acc / factor,
                    // Another zero factor remains.
                    _ => 0.0,
                };
                self.d_alpha * others
            }
            Alpha::Sum => self.d_alpha / self.face_count as f64,
            Alpha::Hard => 0.0,
        }
    }
}

/// What one face's colour sample at one pixel adds to its colour parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ColorSampleGrad {
    /// Surface: dL/d(lit texel `texel`) of the face's R² texels.
    Texel {
        /// Texel index within the face.
        texel: usize,
        /// dL/d(its lit RGB).
        rgb: [f64; 3],
    },
    /// Vertex: dL/d(lit colour) of each corner.
    Corners([[f64; 3]; 3]),
}

/// One (pixel, face) pair's contribution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelFaceGrad {
    /// dL/d(screen vertex `(x_s, y_s, z)`) of each corner.
    pub screen: [[f64; 3]; 3],
    /// dL/d(colour parameters), when the face contributes colour at this pixel.
    pub color: Option<ColorSampleGrad>,
}

/// `sigmoid'(x) = sigmoid(x) sigmoid(−x)`, without the cancellation of `D (1 − D)`.
fn sigmoid_grad(x: f64) -> f64 {
    let e = (-x.abs()).exp();
    e / ((1.0 + e) * (1.0 + e))
}

/// Nearest edge of the face to `p` as the forward's [`reference::euclidean_dist2`] picks it:
/// `(d², i, j, t)` with the nearest point `v_i + t (v_j − v_i)`.
pub(super) fn nearest_edge(v: &[[f64; 3]; 3], p: [f64; 2]) -> (f64, usize, usize, f64) {
    let mut best = (f64::INFINITY, 0, 1, 0.0);
    for (i, j) in [(0, 1), (1, 2), (2, 0)] {
        let (a, b) = ([v[i][0], v[i][1]], [v[j][0], v[j][1]]);
        let d2 = dist2_point_segment(p, a, b);
        if d2 < best.0 {
            let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
            let len2 = ex * ex + ey * ey;
            let t = if len2 > 0.0 {
                (((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            best = (d2, i, j, t);
        }
    }
    best
}

/// Index of the smallest barycentric (the first on ties), as `min` picks it.
pub(super) fn argmin3(w: &[f64; 3]) -> usize {
    let mut k = 0;
    for i in 1..3 {
        if w[i] < w[k] {
            k = i;
        }
    }
    k
}

/// Adds `dL/d(screen xy)` from `dL/dw` for `w_k = n_k / det`, `n_k` the sub-determinant of the
/// pixel with the edge opposite vertex k, `det` the clamped determinant (constant where the
/// clamp holds it).
fn barycentric_grad(
    face: &FaceSetup,
    w: &[f64; 3],
    d_w: &[f64; 3],
    xp: f64,
    yp: f64,
) -> [[f64; 2]; 3] {
    let v = &face.v;
    let det_raw = reference::screen_det(v);
    let det = reference::clamp_det(det_raw);
    let clamped = det != det_raw;
    let d_det = if clamped {
        0.0
    } else {
        -(d_w[0] * w[0] + d_w[1] * w[1] + d_w[2] * w[2]) / det
    };
    let mut g = [[0.0; 2]; 3];
    for k in 0..3 {
        let (a, b) = ((k + 1) % 3, (k + 2) % 3);
        let d_n = d_w[k] / det;
        // n_k = (y_a − y_b) x_p + (x_b − x_a) y_p + x_a y_b − x_b y_a.
        g[a][0] += d_n * (v[b][1] - yp);
        g[a][1] += d_n * (xp - v[b][0]);
        g[b][0] += d_n * (yp - v[a][1]);
        g[b][1] += d_n * (v[a][0] - xp);
        // det = Σ_k x_k (y_a − y_b).
        g[k][0] += d_det * (v[a][1] - v[b][1]);
        g[k][1] += d_det * (v[b][0] - v[a][0]);
    }
    g
}

/// One face's contribution to one pixel's gradient, from the pixel's [`PixelUpstream`] alone:
/// `None` where the face does not touch the pixel (ignored, as in the forward).
pub fn pixel_face_grad(
    face: &FaceSetup,
    j: usize,
    colors: &FaceColors,
    up: &PixelUpstream,
    s: &RasterSettings,
) -> Option<PixelFaceGrad> {
    let (xp, yp) = (up.xp, up.yp);
    if !face.finite || outside_bbox(&face.bbox, xp, yp) {
        return None;
    }
    let w = barycentric(face, xp, yp);
    let d = coverage(face, &w, xp, yp, s.dist, s.sigma, s.cutoff())?;
    let w_clip = clip_barycentric(w);
    let z = depth(face, &w_clip);
    let colored = z >= s.near && z <= s.far && (s.double_sided || face.front);

    // dL/dD, dL/dC and dL/dz of this face at this pixel.
    let mut d_cov = up.alpha_grad(d, s.alpha);
    let mut d_color = [0.0; 3];
    let mut d_z = 0.0;
    if colored {
        match s.rgb {
            Rgb::Softmax => {
                let c = colors.sample(j, &w_clip);
                let z_norm = (s.far - z) / (s.far - s.near);
                let e = ((z_norm - up.aux.softmax_max) / s.gamma).exp();
                let weight = d * e;
                // dL/dw_j = d_rgb · (C_j − I) / S.
                let q = (dot3(up.d_rgb, c) - up.d_rgb_dot_color) * up.inv_softmax_sum;
                d_color = up.d_rgb.map(|g| g * weight * up.inv_softmax_sum);
                d_cov += q * e;
                d_z = -q * weight / (s.gamma * (s.far - s.near));
            }
            Rgb::Hard => {
                if up.aux.hard_face == j as u32 {
                    d_color = up.d_rgb;
                }
            }
        }
    }

    let mut screen = [[0.0; 3]; 3];
    // Through w̃: depth and (vertex mode) colour.
    let mut d_wc = [0.0; 3];
    if d_z != 0.0 {
        let d_inv = -z * z * d_z;
        for k in 0..3 {
            let zk = face.v[k][2];
            d_wc[k] += d_inv / zk;
            screen[k][2] -= d_inv * w_clip[k] / (zk * zk);
        }
    }
    let color = colored.then(|| match colors {
        FaceColors::Surface { res, .. } => ColorSampleGrad::Texel {
            texel: surface_texel_index(&w_clip, *res),
            rgb: d_color,
        },
        FaceColors::Vertex { faces, colors } => {
            let c = faces[j].map(|v| colors[v as usize]);
            for k in 0..3 {
                d_wc[k] += dot3(d_color, c[k]);
            }
            ColorSampleGrad::Corners(std::array::from_fn(|k| d_color.map(|g| g * w_clip[k])))
        }
    });

    // Clip: c = clamp(w, 0, 1), w̃ = c / max(Σc, floor).
    let clamped = w.map(|x| x.clamp(0.0, 1.0));
    let raw_sum = clamped[0] + clamped[1] + clamped[2];
    let sum = raw_sum.max(reference::CLIP_SUM_FLOOR);
    let renorm = if raw_sum >= reference::CLIP_SUM_FLOOR {
        d_wc[0] * w_clip[0] + d_wc[1] * w_clip[1] + d_wc[2] * w_clip[2]
    } else {
        0.0
    };
    let mut d_w: [f64; 3] = std::array::from_fn(|k| {
        if w[k] > 0.0 && w[k] < 1.0 {
            (d_wc[k] - renorm) / sum
        } else {
            0.0
        }
    });

    // Coverage.
    let mut d_xy_cov = [[0.0; 2]; 3];
    if d_cov != 0.0 {
        match s.dist {
            Dist::Hard => {}
            Dist::Barycentric => {
                let k = argmin3(&w);
                let m = w[k];
                let x = m * m.abs() / s.sigma;
                d_w[k] += d_cov * sigmoid_grad(x) * 2.0 * m.abs() / s.sigma;
            }
            Dist::Euclidean => {
                let (d2, a, b, t) = nearest_edge(&face.v, [xp, yp]);
                let sign = if w.iter().all(|&x| x > 0.0 && x < 1.0) {
                    1.0
                } else {
                    -1.0
                };
                let d_d2 = d_cov * sigmoid_grad(sign * d2 / s.sigma) * sign / s.sigma;
                let r = [
                    face.v[a][0] + t * (face.v[b][0] - face.v[a][0]) - xp,
                    face.v[a][1] + t * (face.v[b][1] - face.v[a][1]) - yp,
                ];
                for i in 0..2 {
                    d_xy_cov[a][i] += d_d2 * 2.0 * (1.0 - t) * r[i];
                    d_xy_cov[b][i] += d_d2 * 2.0 * t * r[i];
                }
            }
        }
    }
    let d_xy = barycentric_grad(face, &w, &d_w, xp, yp);
    for k in 0..3 {
        screen[k][0] += d_xy[k][0] + d_xy_cov[k][0];
        screen[k][1] += d_xy[k][1] + d_xy_cov[k][1];
    }
    Some(PixelFaceGrad { screen, color })
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::super::forward_view;
    use super::super::tests::settings;
    use super::*;
    use crate::camera::Camera;
    use crate::lighting::Lighting;
    use crate::raster::reference::MeshF64;

    /// Deep inside a face at SoftRas's σ its coverage is exactly 1, so `Π(1 − D)` is 0 and
    /// `∂A/∂D_j = Π/(1 − D_j)` would be 0/0. The zero count keeps every face's derivative exact.
    #[test]
    fn prod_alpha_derivative_is_exact_where_coverage_rounds_to_one() {
        // A large face covering the pixel, a second one whose edge passes near it.
        let mesh = MeshF64 {
            positions: vec![
                DVec3::new(-2.0, -2.0, 0.0),
                DVec3::new(0.0, 2.0, 0.0),
                DVec3::new(2.0, -2.0, 0.0),
                DVec3::new(-1.0, 0.0005, -0.1),
                DVec3::new(0.0, 1.0, -0.1),
                DVec3::new(1.0, 0.0005, -0.1),
            ],
            faces: vec![[0, 1, 2], [3, 4, 5]],
            texture_res: 1,
            textures: vec![[1.0; 3]; 2],
            vertex_colors: None,
        };
        let s = RasterSettings {
            sigma: 1e-5,
            ..settings(1, 1)
        };
        let colors = FaceColors::of(&mesh, &Lighting::unlit(), s.color_mode);
        let fwd = forward_view(&mesh, &Camera::default(), &colors, &s);
        let aux = fwd.aux[0];
        let t = s.cutoff();
        let d: Vec<f64> = fwd
            .faces
            .iter()
            .map(|f| {
                let w = barycentric(f, 0.0, 0.0);
                coverage(f, &w, 0.0, 0.0, s.dist, s.sigma, t).unwrap()
            })
            .collect();
        assert_eq!(d[0], 1.0);
        assert!(d[1] > 0.1 && d[1] < 0.9, "{d:?}");
        assert_eq!(aux.alpha_zeros, 1);
        let up = PixelUpstream::new((0.0, 0.0), fwd.image[0], aux, [0.0, 0.0, 0.0, 1.0], 2);
        assert_eq!(up.alpha_grad(d[0], Alpha::Prod), 1.0 - d[1]);
        assert_eq!(up.alpha_grad(d[1], Alpha::Prod), 0.0);
        // What dividing the full product would give.
        let naive = (1.0 - fwd.image[0][3]) / (1.0 - d[0]);
        assert!(naive.is_nan());
    }
}
