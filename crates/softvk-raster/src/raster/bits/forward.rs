//! The fine pass's twin: [`FineTwin`]'s per-face shading and per-pixel finish, and every
//! pixel of a view before and after the 2 × 2 downsampling.

use super::{
    Face, FineTwin, V2, V3, barycentric, clip_barycentric, coverage, depth_in_range, face_of,
    inside_closed, pixel_center,
};
use crate::fmath;
use crate::raster::fine::PixelAux;
use crate::raster::settings::{Alpha, Rgb};
use crate::raster::setup::{FACE_FINITE, FACE_FRONT};
/// The fine pass's running state of one pixel (`PixelState`).
struct State {
    acc: f32,
    zeros: u32,
    ref_depth: f32,
    sum: f32,
    rgb: V3,
    hard: Option<(f32, V3, u32, u32)>, // depth, clipped barycentrics, mesh, face
}

impl FineTwin<'_> {
    fn shade_face(&self, s: &mut State, f: &Face, j: u32, p: V2) {
        let pc = &self.push;
        let b = f.bbox;
        let outside = p[0] < b[0] || p[1] < b[1] || p[0] > b[2] || p[1] > b[3];
        let live = (f.flags & FACE_FINITE) != 0 && !(self.cull && outside);
        let w = barycentric(f, p);
        let (covered, d) = coverage(f, w, p, self.settings.dist, pc.inv_sigma, pc.cutoff);
        if !(covered && live) {
            return;
        }
        match self.settings.alpha {
            Alpha::Prod => {
                let factor = 1.0 - d;
                if factor == 0.0 {
                    s.zeros += 1;
                } else {
                    s.acc *= factor;
                }
            }
            Alpha::Sum => s.acc += d,
            Alpha::Hard => {
                if d > 0.5 {
                    s.acc = 1.0;
                }
            }
        }
        if self.alpha_only {
            return;
        }
        let wc = clip_barycentric(w);
        let Some(z) = depth_in_range(f, wc, pc.near, pc.far) else {
            return;
        };
        if !(self.settings.double_sided || (f.flags & FACE_FRONT) != 0) {
            return;
        }
        match self.settings.rgb {
            Rgb::Softmax => {
                let color = self.sample_color(f.mesh, j, wc);
                let e = fmath::exp(-(z - s.ref_depth).abs() * pc.inv_gamma_range);
                let weight = if z < s.ref_depth {
                    s.sum *= e;
                    s.rgb = s.rgb.map(|c| c * e);
                    s.ref_depth = z;
                    d
                } else {
                    d * e
                };
                s.sum += weight;
                s.rgb = [0, 1, 2].map(|k| s.rgb[k] + weight * color[k]);
            }
            Rgb::Hard => {
                let wins = inside_closed(w) && s.hard.is_none_or(|(depth, ..)| z < depth);
                if wins {
                    s.hard = Some((z, wc, f.mesh, j));
                }
            }
        }
    }

    /// Image RGBA and aux of rendered pixel (`col`, `row`) of view `view`.
    pub fn pixel(&self, view: u32, col: u32, row: u32) -> ([f32; 4], PixelAux) {
        let pc = &self.push;
        let mut s = State {
            acc: if self.settings.alpha == Alpha::Prod {
                1.0
            } else {
                0.0
            },
            zeros: 0,
            ref_depth: pc.background_depth,
            sum: 1.0,
            rgb: [pc.background[0], pc.background[1], pc.background[2]],
            hard: None,
        };
        let p = pixel_center(col, row, pc.width, pc.height);
        let n = pc.face_count as usize;
        let setups = &self.inputs.setups[view as usize * n..(view as usize + 1) * n];
        for (j, setup) in setups.iter().enumerate() {
            self.shade_face(&mut s, &face_of(setup), j as u32, p);
        }
        let rgb = match self.settings.rgb {
            Rgb::Softmax => {
                let inv = fmath::rcp(s.sum);
                s.rgb.map(|c| c * inv)
            }
            Rgb::Hard => match s.hard {
                Some((_, wc, mesh, face)) => self.sample_color(mesh, face, wc),
                None => [pc.background[0], pc.background[1], pc.background[2]],
            },
        };
        let alpha = match self.settings.alpha {
            Alpha::Prod => {
                if s.zeros > 0 {
                    1.0
                } else {
                    1.0 - s.acc
                }
            }
            Alpha::Sum => fmath::div(s.acc, pc.face_count as f32),
            Alpha::Hard => s.acc,
        };
        let aux = PixelAux {
            softmax_ref_depth: s.ref_depth,
            softmax_sum: s.sum,
            alpha_acc: s.acc,
            alpha_zeros: s.zeros,
            hard_face: s.hard.map_or(u32::MAX, |h| h.3),
            pad: [0; 3],
        };
        ([rgb[0], rgb[1], rgb[2], alpha], aux)
    }

    /// Every rendered pixel of view `view`: RGBA (before any 2 × 2 average) and aux, row-major.
    pub fn rendered(&self, view: u32) -> (Vec<[f32; 4]>, Vec<PixelAux>) {
        let (w, h) = (self.push.width, self.push.height);
        (0..h)
            .flat_map(|row| (0..w).map(move |col| (col, row)))
            .map(|(col, row)| self.pixel(view, col, row))
            .unzip()
    }

    /// Every output pixel of view `view` (after the 2 × 2 average with anti-aliasing) and every
    /// rendered pixel's aux, row-major.
    pub fn view(&self, view: u32) -> (Vec<[f32; 4]>, Vec<PixelAux>) {
        let (w, h) = (self.push.width, self.push.height);
        let (rendered, aux) = self.rendered(view);
        let images = if self.settings.antialias {
            let (ow, oh) = (w / 2, h / 2);
            (0..oh)
                .flat_map(|row| (0..ow).map(move |col| (col, row)))
                .map(|(col, row)| {
                    let at =
                        |dc: u32, dr: u32| rendered[((2 * row + dr) * w + 2 * col + dc) as usize];
                    let (a, b, c, d) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
                    [0, 1, 2, 3].map(|k| (((a[k] + b[k]) + c[k]) + d[k]) * 0.25)
                })
                .collect()
        } else {
            rendered
        };
        (images, aux)
    }
}
