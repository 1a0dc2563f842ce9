//! The backward's per-pixel chain (`raster_grad.glsl`): what the backward reads of one
//! rendered pixel and one (pixel, face) pair's contribution to the screen corners, the colours
//! and the texel.

use super::{
    CLIP_SUM_FLOOR, Face, FineTwin, MIN_DET, PairGrad, Upstream, V2, barycentric, clamp01,
    covered_arg, depth_in_range, dot3, inside_closed, pixel_center, strictly_inside,
    surface_texel_index,
};
use crate::fmath;
use crate::raster::fine::PixelAux;
use crate::raster::settings::{Alpha, ColorMode, Dist, Rgb};
use crate::raster::setup::{FACE_FINITE, FACE_FRONT};
/// The nearest edge as `nearest_edge` finds it: (d², a, e, ea, eb, t).
fn nearest_edge(f: &Face, p: V2) -> (f32, V2, V2, usize, usize, f32) {
    let mut best = (f32::INFINITY, [0.0; 2], [0.0; 2], 0, 1, 0.0);
    for i in 0..3 {
        let j = if i == 2 { 0 } else { i + 1 };
        let va = [f.v[i][0], f.v[i][1]];
        let ve = [f.v[j][0] - va[0], f.v[j][1] - va[1]];
        let ti = clamp01(((p[0] - va[0]) * ve[0] + (p[1] - va[1]) * ve[1]) * f.inv_len2[i]);
        let dx = va[0] + ti * ve[0] - p[0];
        let dy = va[1] + ti * ve[1] - p[1];
        let d2 = dx * dx + dy * dy;
        if d2 < best.0 {
            best = (d2, va, ve, i, j, ti);
        }
    }
    best
}

impl FineTwin<'_> {
    pub(super) fn upstream(
        &self,
        view: u32,
        col: u32,
        row: u32,
        d_image: &[[f32; 4]],
        rgba: [f32; 4],
        aux: &PixelAux,
    ) -> Upstream {
        let pc = &self.push;
        let g = if self.settings.antialias {
            let (ow, oh) = (pc.width / 2, pc.height / 2);
            d_image[(view * ow * oh + (row / 2) * ow + col / 2) as usize].map(|x| x * 0.25)
        } else {
            d_image[(view * pc.width * pc.height + row * pc.width + col) as usize]
        };
        Upstream {
            p: pixel_center(col, row, pc.width, pc.height),
            d_rgb: [g[0], g[1], g[2]],
            d_alpha: g[3],
            d_dot: dot3([g[0], g[1], g[2]], [rgba[0], rgba[1], rgba[2]]),
            inv_sum: fmath::rcp(aux.softmax_sum),
            ref_depth: aux.softmax_ref_depth,
            alpha_acc: aux.alpha_acc,
            alpha_zeros: aux.alpha_zeros,
            hard_face: aux.hard_face,
        }
    }

    fn alpha_grad(&self, u: &Upstream, d: f32) -> f32 {
        match self.settings.alpha {
            Alpha::Prod => {
                let factor = 1.0 - d;
                let others = if factor == 0.0 {
                    if u.alpha_zeros == 1 { u.alpha_acc } else { 0.0 }
                } else if u.alpha_zeros == 0 {
                    fmath::div(u.alpha_acc, factor)
                } else {
                    0.0
                };
                u.d_alpha * others
            }
            Alpha::Sum => fmath::div(u.d_alpha, self.push.face_count as f32),
            Alpha::Hard => 0.0,
        }
    }

    /// `pixel_face_grad`: the face's contribution at the pixel, or `None` where it does not
    /// touch it.
    pub(super) fn pixel_face_grad(&self, f: &Face, j: u32, u: &Upstream) -> Option<PairGrad> {
        let pc = &self.push;
        let s = &self.settings;
        let alpha_only = self.alpha_only;
        let p = u.p;
        let b = f.bbox;
        let outside = p[0] < b[0] || p[1] < b[1] || p[0] > b[2] || p[1] > b[3];
        let live = (f.flags & FACE_FINITE) != 0 && !outside;
        let w = barycentric(f, p);
        let (d2, ea_pos, edge, ea, eb, t) = if s.dist == Dist::Euclidean {
            nearest_edge(f, p)
        } else {
            (0.0, [0.0; 2], [0.0; 2], 0, 1, 0.0)
        };
        let inv_sigma = pc.inv_sigma;
        let (covered, d) = match s.dist {
            Dist::Hard => (inside_closed(w), 1.0),
            Dist::Barycentric => {
                let m = w[0].min(w[1]).min(w[2]);
                let sm = m * m.abs();
                let covered = -sm < pc.cutoff;
                (
                    covered,
                    fmath::sigmoid(covered_arg(covered, sm * inv_sigma)),
                )
            }
            Dist::Euclidean => {
                let inside = strictly_inside(w);
                let covered = inside || d2 < pc.cutoff;
                let x = (if inside { d2 } else { -d2 }) * inv_sigma;
                (covered, fmath::sigmoid(covered_arg(covered, x)))
            }
        };
        let hit = covered && live;
        if !hit {
            return None;
        }
        let c = w.map(clamp01);
        let inv_clip_sum = fmath::rcp((c[0] + c[1] + c[2]).max(CLIP_SUM_FLOOR));
        let wc = c.map(|x| x * inv_clip_sum);
        let depth = if alpha_only {
            None
        } else {
            depth_in_range(f, wc, pc.near, pc.far)
        };
        let z = depth.unwrap_or(0.0);
        let colored = depth.is_some() && (s.double_sided || (f.flags & FACE_FRONT) != 0);
        let mut g = PairGrad {
            screen: [[0.0; 3]; 3],
            color: [[0.0; 3]; 3],
            texel: 0,
            colored,
        };

        let mut d_cov = self.alpha_grad(u, d);
        let mut d_color = [0.0; 3];
        let mut d_z = 0.0;
        if !alpha_only {
            let cs = self.sample_color(f.mesh, j, wc);
            match s.rgb {
                Rgb::Softmax => {
                    let e = fmath::exp((u.ref_depth - z) * pc.inv_gamma_range);
                    let weight = d * e;
                    let q = (dot3(u.d_rgb, cs) - u.d_dot) * u.inv_sum;
                    if colored {
                        d_color = u.d_rgb.map(|x| x * (weight * u.inv_sum));
                        d_cov += q * e;
                        d_z = -q * weight * pc.inv_gamma_range;
                    }
                }
                Rgb::Hard => {
                    if colored && u.hard_face == j {
                        d_color = u.d_rgb;
                    }
                }
            }
        }

        let mut d_w = [0.0f32; 3];
        if !alpha_only {
            let mut d_wc = [0.0f32; 3];
            let depth = d_z != 0.0;
            let d_inv = -z * z * d_z;
            for k in 0..3 {
                let izk = f.inv_z[k];
                if depth {
                    d_wc[k] += d_inv * izk;
                    g.screen[k][2] -= d_inv * wc[k] * (izk * izk);
                }
            }
            match s.color_mode {
                ColorMode::Vertex => {
                    let vi = self.inputs.faces[j as usize].map(|v| v + f.mesh * pc.vertex_count);
                    for k in 0..3 {
                        let ck = self.color_at(vi[k]);
                        if colored {
                            d_wc[k] += dot3(d_color, ck);
                            g.color[k] = d_color.map(|x| x * wc[k]);
                        }
                    }
                }
                ColorMode::Surface => {
                    g.texel = surface_texel_index(wc, pc.texture_res);
                    if colored {
                        g.color[0] = d_color;
                    }
                }
            }
            let raw_sum = c[0] + c[1] + c[2];
            let renorm = if raw_sum >= CLIP_SUM_FLOOR {
                dot3(d_wc, wc)
            } else {
                0.0
            };
            for k in 0..3 {
                d_w[k] = if w[k] > 0.0 && w[k] < 1.0 {
                    (d_wc[k] - renorm) * inv_clip_sum
                } else {
                    0.0
                };
            }
        }

        let mut d_xy_cov = [[0.0f32; 2]; 3];
        let cov = alpha_only || d_cov != 0.0;
        match s.dist {
            Dist::Barycentric => {
                let mut k = 0;
                if w[1] < w[k] {
                    k = 1;
                }
                if w[2] < w[k] {
                    k = 2;
                }
                let m = w[k];
                let x = m * m.abs() * inv_sigma;
                let add = d_cov * fmath::sigmoid_grad(x) * 2.0 * m.abs() * inv_sigma;
                if cov {
                    d_w[k] += add;
                }
            }
            Dist::Euclidean => {
                let sgn: f32 = if strictly_inside(w) { 1.0 } else { -1.0 };
                let d_d2 = d_cov * fmath::sigmoid_grad(sgn * d2 * inv_sigma) * sgn * inv_sigma;
                let r = [
                    ea_pos[0] + t * edge[0] - p[0],
                    ea_pos[1] + t * edge[1] - p[1],
                ];
                let to_a = r.map(|x| d_d2 * 2.0 * (1.0 - t) * x);
                let to_b = r.map(|x| d_d2 * 2.0 * t * x);
                if cov {
                    d_xy_cov[ea] = to_a;
                    d_xy_cov[eb] = to_b;
                }
            }
            Dist::Hard => {}
        }

        let mut d_xy = [[0.0f32; 2]; 3];
        if !alpha_only || s.dist == Dist::Barycentric {
            let clamped = if f.det > 0.0 {
                f.det < MIN_DET
            } else {
                f.det > -MIN_DET
            };
            let d_det = if clamped {
                0.0
            } else {
                -dot3(d_w, w) * f.inv_det
            };
            for k in 0..3 {
                let ia = if k == 2 { 0 } else { k + 1 };
                let ib = if k == 0 { 2 } else { k - 1 };
                let va = [f.v[ia][0], f.v[ia][1]];
                let vb = [f.v[ib][0], f.v[ib][1]];
                let d_n = d_w[k] * f.inv_det;
                d_xy[ia][0] += d_n * (vb[1] - p[1]);
                d_xy[ia][1] += d_n * (p[0] - vb[0]);
                d_xy[ib][0] += d_n * (p[1] - va[1]);
                d_xy[ib][1] += d_n * (va[0] - p[0]);
                d_xy[k][0] += d_det * (va[1] - vb[1]);
                d_xy[k][1] += d_det * (vb[0] - va[0]);
            }
        }
        for k in 0..3 {
            g.screen[k][0] += d_xy[k][0] + d_xy_cov[k][0];
            g.screen[k][1] += d_xy[k][1] + d_xy_cov[k][1];
        }
        Some(g)
    }
}
