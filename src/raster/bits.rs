//! The bit twin of the forward's fine pass: `raster_fine.glsl`'s `shade_face` and `pixel_finish`
//! (and `raster.glsl`'s functions they call, and the 2 × 2 downsampling) evaluated in f32,
//! operation for operation, with softmax's `exp`, the sigmoid, reciprocals and divisions from
//! [`crate::fmath`]. Given the face setups and lit colours a forward left on the device, it gives
//! the device's image and aux byte for byte (`tests/raster_bits.rs`): the device's result is the
//! IEEE evaluation of the written operations, which every conformant device reproduces. The f64
//! twin ([`super::reference`]) stays the accuracy reference.

use super::fine::{PixelAux, RasterPush};
use super::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};
use super::setup::{FACE_FINITE, FACE_FRONT, GpuFaceSetup};
use crate::fmath;

const CLIP_SUM_FLOOR: f32 = 1e-5;
const TEXEL_TIE_ULPS: f32 = 8.0;
const FLT_EPSILON: f32 = 1.192_092_9e-7;

type V2 = [f32; 2];
type V3 = [f32; 3];

/// What the fine pass reads besides the setups: one batch's lit colours (`GpuScene::colors`:
/// RGB and an unused float each) and the faces that index them (vertex colours).
pub struct FineInputs<'a> {
    /// The face setups of every view, view-major (`GpuScene::read_setups`).
    pub setups: &'a [GpuFaceSetup],
    /// The lit colours as the device holds them.
    pub colors: &'a [[f32; 4]],
    /// The batch's faces (one mesh's; vertex colours only).
    pub faces: &'a [[u32; 3]],
    /// Faces per view.
    pub face_count: u32,
    /// Vertices per mesh (vertex colours).
    pub vertex_count: u32,
    /// Texels per face edge (surface colours).
    pub texture_res: u32,
}

/// `Face` of `raster.glsl`: a setup with its reciprocals.
struct Face {
    v: [V3; 3],
    inv: [V2; 3],
    bbox: [f32; 4],
    flags: u32,
    mesh: u32,
    inv_z: V3,
    inv_len2: V3,
}

fn face_of(s: &GpuFaceSetup) -> Face {
    let v = [0, 1, 2].map(|k| [s.v[k][0], s.v[k][1], s.v[k][2]]);
    let mut inv_z = [0.0; 3];
    let mut inv_len2 = [0.0; 3];
    for k in 0..3 {
        let j = if k == 2 { 0 } else { k + 1 };
        let e = [v[j][0] - v[k][0], v[j][1] - v[k][1]];
        let len2 = e[0] * e[0] + e[1] * e[1];
        inv_z[k] = fmath::rcp(v[k][2]);
        inv_len2[k] = if len2 > 0.0 { fmath::rcp(len2) } else { 0.0 };
    }
    Face {
        v,
        inv: [0, 1, 2].map(|k| [s.inv[k][0], s.inv[k][1]]),
        bbox: s.bbox,
        flags: s.flags,
        mesh: s.mesh,
        inv_z,
        inv_len2,
    }
}

/// GLSL's `clamp(x, 0, 1)`, defined as `min(max(x, 0), 1)`.
#[allow(clippy::manual_clamp)]
fn clamp01(x: f32) -> f32 {
    x.max(0.0).min(1.0)
}

fn barycentric(f: &Face, p: V2) -> V3 {
    [
        f.inv[0][0] * (p[0] - f.v[1][0]) + f.inv[0][1] * (p[1] - f.v[1][1]),
        f.inv[1][0] * (p[0] - f.v[2][0]) + f.inv[1][1] * (p[1] - f.v[2][1]),
        f.inv[2][0] * (p[0] - f.v[0][0]) + f.inv[2][1] * (p[1] - f.v[0][1]),
    ]
}

fn strictly_inside(w: V3) -> bool {
    w.iter().all(|&x| x > 0.0 && x < 1.0)
}

fn inside_closed(w: V3) -> bool {
    w.iter().all(|&x| (0.0..=1.0).contains(&x))
}

fn dist2_point_segment(p: V2, a: V2, b: V2, inv_len2: f32) -> f32 {
    let ex = b[0] - a[0];
    let ey = b[1] - a[1];
    let t = clamp01(((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) * inv_len2);
    let dx = a[0] + t * ex - p[0];
    let dy = a[1] + t * ey - p[1];
    dx * dx + dy * dy
}

fn euclidean_dist2(f: &Face, p: V2) -> f32 {
    let xy = |k: usize| [f.v[k][0], f.v[k][1]];
    dist2_point_segment(p, xy(0), xy(1), f.inv_len2[0])
        .min(dist2_point_segment(p, xy(1), xy(2), f.inv_len2[1]))
        .min(dist2_point_segment(p, xy(2), xy(0), f.inv_len2[2]))
}

/// `coverage`: the coverage D, or `None` where the face is ignored at this pixel.
fn coverage(f: &Face, w: V3, p: V2, dist: Dist, inv_sigma: f32, t: f32) -> (bool, f32) {
    match dist {
        Dist::Hard => (inside_closed(w), 1.0),
        Dist::Barycentric => {
            let m = w[0].min(w[1]).min(w[2]);
            let s = m * m.abs();
            (-s < t, fmath::sigmoid(s * inv_sigma))
        }
        Dist::Euclidean => {
            let d2 = euclidean_dist2(f, p);
            let inside = strictly_inside(w);
            let d = fmath::sigmoid((if inside { d2 } else { -d2 }) * inv_sigma);
            (inside || d2 < t, d)
        }
    }
}

fn clip_barycentric(w: V3) -> V3 {
    let c = w.map(clamp01);
    let inv = fmath::rcp((c[0] + c[1] + c[2]).max(CLIP_SUM_FLOOR));
    c.map(|x| x * inv)
}

fn depth_in_range(f: &Face, wc: V3, near: f32, far: f32) -> Option<f32> {
    let inv_z = wc[0] * f.inv_z[0] + wc[1] * f.inv_z[1] + wc[2] * f.inv_z[2];
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    if !(inv_z > 0.0) {
        return None;
    }
    let z = fmath::rcp(inv_z);
    (z >= near && z <= far).then_some(z)
}

fn surface_texel_index(wc: V3, res: u32) -> u32 {
    let r = res as f32;
    // GLSL's uint(x): truncation (x ≥ 0 here).
    let a = ((wc[0] * r) as u32).min(res - 1);
    let b = ((wc[1] * r) as u32).min(res - 1);
    let frac = (wc[0] + wc[1]) * r - a as f32 - b as f32;
    if frac <= 1.0 + TEXEL_TIE_ULPS * r * FLT_EPSILON {
        b * res + a
    } else {
        (res - 1 - b) * res + (res - 1 - a)
    }
}

fn pixel_center(col: u32, row: u32, width: u32, height: u32) -> V2 {
    let w = width as f32;
    let h = height as f32;
    let s = w.min(h);
    [
        fmath::div(2.0 * col as f32 + 1.0 - w, s),
        fmath::div(2.0 * (h - 1.0 - row as f32) + 1.0 - h, s),
    ]
}

/// The fine pass's running state of one pixel (`PixelState`).
struct State {
    acc: f32,
    zeros: u32,
    ref_depth: f32,
    sum: f32,
    rgb: V3,
    hard: Option<(f32, V3, u32, u32)>, // depth, clipped barycentrics, mesh, face
}

/// The fine pass in f32 for one view at one rendered size: what the device's brute-force and
/// tiled kernels write.
pub struct FineTwin<'a> {
    inputs: FineInputs<'a>,
    settings: RasterSettings,
    push: RasterPush,
    alpha_only: bool,
    cull: bool,
}

impl<'a> FineTwin<'a> {
    /// The twin of a forward with `settings` over `inputs`: `alpha_only` for a silhouette render,
    /// `cull` for the boxes' cull (the renderer's forward culls).
    pub fn new(
        inputs: FineInputs<'a>,
        settings: &RasterSettings,
        alpha_only: bool,
        cull: bool,
    ) -> Self {
        let scale = if settings.antialias { 2 } else { 1 };
        let push = RasterPush::new(
            settings,
            settings.width * scale,
            settings.height * scale,
            inputs.face_count,
            1,
            inputs.vertex_count,
            inputs.texture_res,
        );
        Self {
            inputs,
            settings: *settings,
            push,
            alpha_only,
            cull,
        }
    }

    fn color_at(&self, i: u32) -> V3 {
        let c = self.inputs.colors[i as usize];
        [c[0], c[1], c[2]]
    }

    fn sample_color(&self, mesh: u32, face: u32, wc: V3) -> V3 {
        let p = &self.push;
        match self.settings.color_mode {
            ColorMode::Vertex => {
                let f = self.inputs.faces[face as usize].map(|v| v + mesh * p.vertex_count);
                let [c0, c1, c2] = f.map(|v| self.color_at(v));
                [0, 1, 2].map(|k| wc[0] * c0[k] + wc[1] * c1[k] + wc[2] * c2[k])
            }
            ColorMode::Surface => {
                let r2 = p.texture_res * p.texture_res;
                let t = (mesh * p.face_count + face) * r2 + surface_texel_index(wc, p.texture_res);
                self.color_at(t)
            }
        }
    }

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
                if z < s.ref_depth {
                    let rescale = fmath::exp((z - s.ref_depth) * pc.inv_gamma_range);
                    s.sum *= rescale;
                    s.rgb = s.rgb.map(|c| c * rescale);
                    s.ref_depth = z;
                }
                let weight = d * fmath::exp((s.ref_depth - z) * pc.inv_gamma_range);
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

    /// Every output pixel of view `view` (after the 2 × 2 average with anti-aliasing) and every
    /// rendered pixel's aux, row-major.
    pub fn view(&self, view: u32) -> (Vec<[f32; 4]>, Vec<PixelAux>) {
        let (w, h) = (self.push.width, self.push.height);
        let rendered: Vec<([f32; 4], PixelAux)> = (0..h)
            .flat_map(|row| (0..w).map(move |col| (col, row)))
            .map(|(col, row)| self.pixel(view, col, row))
            .collect();
        let aux = rendered.iter().map(|r| r.1).collect();
        let images = if self.settings.antialias {
            let (ow, oh) = (w / 2, h / 2);
            (0..oh)
                .flat_map(|row| (0..ow).map(move |col| (col, row)))
                .map(|(col, row)| {
                    let at =
                        |dc: u32, dr: u32| rendered[((2 * row + dr) * w + 2 * col + dc) as usize].0;
                    let (a, b, c, d) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
                    [0, 1, 2, 3].map(|k| (((a[k] + b[k]) + c[k]) + d[k]) * 0.25)
                })
                .collect()
        } else {
            rendered.iter().map(|r| r.0).collect()
        };
        (images, aux)
    }
}
