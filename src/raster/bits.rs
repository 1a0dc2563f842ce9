//! The bit twins of the device's forward and backward, in f32 operation for operation, with
//! softmax's `exp`, the sigmoid, square roots, reciprocals and divisions from [`crate::fmath`]:
//!
//! - [`face_setups`]: the projection and face set-up (`vertex_project.comp`, `face_setup.comp`)
//!   from the world positions and the views;
//! - [`host_lit_colors`] and [`GpuLightTwin`]: the lit colours, as the renderer's host f64
//!   lighting rounds them, or as the lighting kernels (`light_forward.comp`; backward
//!   `light_backward.comp`, `light_gather.comp`) compute them;
//! - [`FineTwin`]: the fine pass (`raster_fine.glsl`'s `shade_face` and `pixel_finish`, the
//!   `raster.glsl` functions they call, and the 2 × 2 downsampling): the device's image and aux;
//! - [`FineTwin::backward`]: the backward (`raster_grad.glsl`'s per-pixel chain, summed in the
//!   order of `grad_brute.comp` or of the tiled `grad_tiled.comp` ([`SumOrder`]), reduced as
//!   `grad_reduce.comp` and `grad_reduce_texels.comp` do, then `grad_world.comp` and
//!   `grad_gather.comp`): the device's gradients.
//!
//! `tests/raster_bits.rs` checks each against the device byte for byte, from the mesh, the
//! cameras and the lighting. The device's result is then the IEEE evaluation of the written
//! operations (every float operation of every kernel is `NoContraction`), which every
//! conformant device reproduces. The f64 twins ([`super::reference`], [`super::reference_grad`])
//! stay the accuracy references.

mod face_setup;
mod lighting;

pub use face_setup::{face_setups, to_screen};
pub use lighting::{GpuLightTwin, host_lit_colors};

use super::fine::{PixelAux, RasterPush};
use super::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};
use super::setup::{FACE_FINITE, FACE_FRONT, GpuFaceSetup};
use crate::fmath;

const MIN_DET: f32 = 1e-10;
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
    det: f32,
    inv_z: V3,
    inv_len2: V3,
    inv_det: f32,
}

/// `face_reciprocals` of `raster.glsl`: 1 / z_k, 1 / |edge k|² (0 for a zero-length edge)
/// and 1 / the clamped determinant of a face with screen vertices `v` and determinant `det`.
fn reciprocals(v: &[V3; 3], det: f32) -> (V3, V3, f32) {
    let mut inv_z = [0.0; 3];
    let mut inv_len2 = [0.0; 3];
    for k in 0..3 {
        let j = if k == 2 { 0 } else { k + 1 };
        let e = [v[j][0] - v[k][0], v[j][1] - v[k][1]];
        let len2 = e[0] * e[0] + e[1] * e[1];
        inv_z[k] = fmath::rcp(v[k][2]);
        inv_len2[k] = if len2 > 0.0 { fmath::rcp(len2) } else { 0.0 };
    }
    let inv_det = fmath::rcp(if det > 0.0 {
        det.max(MIN_DET)
    } else {
        det.min(-MIN_DET)
    });
    (inv_z, inv_len2, inv_det)
}

fn face_of(s: &GpuFaceSetup) -> Face {
    let v = [0, 1, 2].map(|k| [s.v[k][0], s.v[k][1], s.v[k][2]]);
    let (inv_z, inv_len2, inv_det) = reciprocals(&v, s.det);
    Face {
        v,
        inv: [0, 1, 2].map(|k| [s.inv[k][0], s.inv[k][1]]),
        bbox: s.bbox,
        flags: s.flags,
        mesh: s.mesh,
        det: s.det,
        inv_z,
        inv_len2,
        inv_det,
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
        fmath::div_rn(2.0 * col as f32 + 1.0 - w, s),
        fmath::div_rn(2.0 * (h - 1.0 - row as f32) + 1.0 - h, s),
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

/// One (pixel, face) contribution (`FaceGrad` of `raster_grad.glsl`).
struct PairGrad {
    screen: [V3; 3],
    color: [V3; 3],
    texel: u32,
    colored: bool,
}

/// `Upstream` of `raster_grad.glsl`: what the backward reads of one rendered pixel.
struct Upstream {
    p: V2,
    d_rgb: V3,
    d_alpha: f32,
    d_dot: f32,
    inv_sum: f32,
    ref_depth: f32,
    alpha_acc: f32,
    alpha_zeros: u32,
    hard_face: u32,
}

/// `acc += x`, component by component.
fn add3(acc: &mut V3, x: V3) {
    *acc = [acc[0] + x[0], acc[1] + x[1], acc[2] + x[2]];
}

fn dot3(a: V3, b: V3) -> f32 {
    fmath::dot3(a, b)
}

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

/// The gradients the device's backward writes (`GradIo::positions` and `GradIo::colors`): before
/// the host adds the lighting's share (exactly zero with an unlit lighting).
pub struct BackwardTwin {
    /// dL/d(world position) per vertex.
    pub positions: Vec<V3>,
    /// dL/d(lit colour) per texel slot (surface colours, face after face) or per vertex.
    pub colors: Vec<V3>,
}

impl FineTwin<'_> {
    fn upstream(
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
    fn pixel_face_grad(&self, f: &Face, j: u32, u: &Upstream) -> Option<PairGrad> {
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
                (-sm < pc.cutoff, fmath::sigmoid(sm * inv_sigma))
            }
            Dist::Euclidean => {
                let inside = strictly_inside(w);
                let d = fmath::sigmoid((if inside { d2 } else { -d2 }) * inv_sigma);
                (inside || d2 < pc.cutoff, d)
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

    /// The backward of views `0..views.len()` for `d_image` (output resolution, view-major),
    /// given the forward's rendered images and aux of each view ([`FineTwin::rendered`]:
    /// `rendered[v]`), the world positions (one mesh) and the views: each face's per-pixel terms
    /// summed into partials in `order` (the device's backward kernel for that method), the
    /// partials reduced in unit order (`grad_reduce.comp`, `grad_reduce_texels.comp`), then
    /// `grad_world.comp` and `grad_gather.comp`. The results are what the device writes to
    /// `GradIo::positions` and `GradIo::colors` (dL/d(lit colour)): with [`Lighting::unlit`]
    /// exactly what [`Renderer::backward`] returns, the host's f64 lighting share being zero.
    ///
    /// [`Lighting::unlit`]: crate::lighting::Lighting::unlit
    /// [`Renderer::backward`]: super::gpu::Renderer::backward
    pub fn backward(
        &self,
        views: &[super::setup::GpuView],
        positions: &[[f32; 3]],
        d_image: &[[f32; 4]],
        rendered: &[(Vec<[f32; 4]>, Vec<PixelAux>)],
        order: SumOrder,
    ) -> BackwardTwin {
        let pc = &self.push;
        let nf = pc.face_count as usize;
        let vertex_colors = self.settings.color_mode == ColorMode::Vertex;
        let slots = if vertex_colors {
            3
        } else {
            (pc.texture_res * pc.texture_res) as usize
        };
        // Per (view, face): the screen corners (and vertex colours) after `grad_reduce.comp`;
        // per (face, texel): the texel gradients after `grad_reduce_texels.comp`, one running
        // sum over the views in order and each view's units in order.
        let mut screen = vec![[[0.0f32; 3]; 3]; views.len() * nf];
        let mut colors = vec![
            [0.0f32; 3];
            if vertex_colors {
                views.len() * nf * slots
            } else {
                0
            }
        ];
        let mut texels = vec![[0.0f32; 3]; if vertex_colors { 0 } else { nf * slots }];
        for (v, (images, aux)) in rendered.iter().enumerate() {
            let setups = &self.inputs.setups[v * nf..(v + 1) * nf];
            for (j, setup) in setups.iter().enumerate() {
                let f = face_of(setup);
                // The pair's contribution at rendered pixel (col, row), where it has one.
                let pair = |col: u32, row: u32| -> Option<PairGrad> {
                    let id = (row * pc.width + col) as usize;
                    let u = self.upstream(v as u32, col, row, d_image, images[id], &aux[id]);
                    if u.d_alpha == 0.0 && (self.alpha_only || u.d_rgb == [0.0; 3]) {
                        return None;
                    }
                    self.pixel_face_grad(&f, j as u32, &u)
                };
                let units = match order {
                    SumOrder::Brute { band_rows } => self.brute_units(&f, slots, band_rows, pair),
                    SumOrder::Tiled { tile } => self.tiled_units(slots, tile, pair),
                };
                let item = v * nf + j;
                for unit in &units {
                    for (s, x) in screen[item].iter_mut().zip(unit.screen) {
                        add3(s, x);
                    }
                    if vertex_colors {
                        for (s, &x) in colors[item * slots..(item + 1) * slots]
                            .iter_mut()
                            .zip(&unit.colors)
                        {
                            add3(s, x);
                        }
                    } else {
                        let face_texels = &mut texels[j * slots..(j + 1) * slots];
                        for (t, s) in face_texels.iter_mut().enumerate() {
                            if unit.written[t] {
                                add3(s, unit.colors[t]);
                            }
                        }
                    }
                }
            }
        }
        // grad_world.comp: each corner's screen gradient to world space.
        let faces = self.inputs.faces;
        let mut corner_world = vec![[[0.0f32; 3]; 3]; views.len() * nf];
        for (v, view) in views.iter().enumerate() {
            for j in 0..nf {
                for c in 0..3 {
                    let g = screen[v * nf + j][c];
                    if g == [0.0; 3] {
                        continue;
                    }
                    let p = positions[faces[j][c] as usize];
                    corner_world[v * nf + j][c] = world_grad(view, p, g);
                }
            }
        }
        // grad_gather.comp: per vertex, its views in order, its (face, corner) slots in order.
        let nv = pc.vertex_count as usize;
        let adjacency = super::reference_grad::VertexFaces::new(faces, nv);
        let mut out_pos = vec![[0.0f32; 3]; nv];
        let mut out_col = if vertex_colors {
            vec![[0.0f32; 3]; nv]
        } else {
            texels
        };
        for vtx in 0..nv {
            let (b, e) = (
                adjacency.offsets[vtx] as usize,
                adjacency.offsets[vtx + 1] as usize,
            );
            for v in 0..views.len() {
                for &slot in &adjacency.slots[b..e] {
                    let (face, corner) = ((slot / 3) as usize, (slot % 3) as usize);
                    let w = corner_world[v * nf + face][corner];
                    add3(&mut out_pos[vtx], w);
                    if vertex_colors {
                        let c = colors[(v * nf + face) * slots + corner];
                        add3(&mut out_col[vtx], c);
                    }
                }
            }
        }
        BackwardTwin {
            positions: out_pos,
            colors: out_col,
        }
    }

    /// `grad_brute.comp`'s units of one (view, face): bands of `band_rows` rows from the top,
    /// each the running sum of its pixels' contributions in row-major order.
    fn brute_units(
        &self,
        f: &Face,
        slots: usize,
        band_rows: u32,
        pair: impl Fn(u32, u32) -> Option<PairGrad>,
    ) -> Vec<Partial> {
        let pc = &self.push;
        let vertex_colors = self.settings.color_mode == ColorMode::Vertex;
        let mut units = Vec::new();
        let mut row0 = 0;
        while row0 < pc.height {
            let mut unit = Partial::new(slots);
            if f.flags & FACE_FINITE != 0 {
                for row in row0..(row0 + band_rows).min(pc.height) {
                    for col in 0..pc.width {
                        let Some(g) = pair(col, row) else { continue };
                        for (acc, x) in unit.screen.iter_mut().zip(g.screen) {
                            add3(acc, x);
                        }
                        if g.colored {
                            if vertex_colors {
                                for (acc, x) in unit.colors.iter_mut().zip(g.color) {
                                    add3(acc, x);
                                }
                            } else {
                                add3(&mut unit.colors[g.texel as usize], g.color[0]);
                                unit.written[g.texel as usize] = true;
                            }
                        }
                    }
                }
            }
            units.push(unit);
            row0 += band_rows;
        }
        units
    }

    /// `grad_tiled.comp`'s units of one (view, face): one per `tile × tile` tile, tiles in
    /// row-major order (the order binning's scatter gives a face's entries). A tile's partial
    /// adds, one 2 × 2 quad after another in [`morton_pixel`]'s order, each quad's sum
    /// `(v0 + v1) + (v2 + v3)` of its pixels' contributions, a pixel with none adding -0.0;
    /// a texel slot adds its pixels' contributions one at a time in the same order. That order
    /// is the pixels', not the subgroup's or the workgroup's: the same bits at any subgroup
    /// size and workgroup shape. Every tile is a unit here, where the device has units only for
    /// the tiles binning gave the face: a tile without any contribution sums to +0.0, and adding
    /// +0.0 to a running sum that starts at +0.0 changes no bit (such a sum is never -0.0).
    fn tiled_units(
        &self,
        slots: usize,
        tile: u32,
        pair: impl Fn(u32, u32) -> Option<PairGrad>,
    ) -> Vec<Partial> {
        const NEG_ZERO: f32 = -0.0;
        let pc = &self.push;
        let vertex_colors = self.settings.color_mode == ColorMode::Vertex;
        let alpha_only = self.alpha_only;
        // With an alpha-only upstream the device adds only x and y of each corner.
        let axes = if alpha_only { 2 } else { 3 };
        let quad_sum = |v: [f32; 4]| (v[0] + v[1]) + (v[2] + v[3]);
        let mut units = Vec::new();
        for ty in 0..pc.height.div_ceil(tile) {
            for tx in 0..pc.width.div_ceil(tile) {
                let mut unit = Partial::new(slots);
                for quad in 0..tile * tile / 4 {
                    let g: [Option<PairGrad>; 4] = std::array::from_fn(|k| {
                        let (x, y) = morton_pixel(4 * quad + k as u32, tile);
                        let (col, row) = (tx * tile + x, ty * tile + y);
                        (col < pc.width && row < pc.height)
                            .then(|| pair(col, row))
                            .flatten()
                    });
                    for c in 0..3 {
                        for a in 0..axes {
                            let v = g
                                .each_ref()
                                .map(|g| g.as_ref().map_or(NEG_ZERO, |g| g.screen[c][a]));
                            unit.screen[c][a] += quad_sum(v);
                        }
                    }
                    if alpha_only {
                        continue;
                    }
                    fn colored(g: &Option<PairGrad>) -> Option<&PairGrad> {
                        g.as_ref().filter(|g| g.colored)
                    }
                    if vertex_colors {
                        for c in 0..3 {
                            for a in 0..3 {
                                let v = g
                                    .each_ref()
                                    .map(|g| colored(g).map_or(NEG_ZERO, |g| g.color[c][a]));
                                unit.colors[c][a] += quad_sum(v);
                            }
                        }
                    } else {
                        for g in g.iter().filter_map(colored) {
                            add3(&mut unit.colors[g.texel as usize], g.color[0]);
                            unit.written[g.texel as usize] = true;
                        }
                    }
                }
                units.push(unit);
            }
        }
        units
    }
}

/// One unit's partial gradient (a band of a face, or a (face, tile) entry): the screen corners,
/// the colour slots (3 vertex colours or R² texels) and which texel slots were written.
struct Partial {
    screen: [V3; 3],
    colors: Vec<V3>,
    written: Vec<bool>,
}

impl Partial {
    fn new(slots: usize) -> Self {
        Self {
            screen: [[0.0; 3]; 3],
            colors: vec![[0.0; 3]; slots],
            written: vec![false; slots],
        }
    }
}

/// `morton_pixel` of `subgroup_face.glsl`: where pixel `i` of a `size`-wide tile lies in the
/// tiled backward's order (8 × 8 blocks row-major; in a block the Z order of its 64 pixels).
pub fn morton_pixel(i: u32, size: u32) -> (u32, u32) {
    let block = i >> 6;
    let m = i & 63;
    let per_row = size / 8;
    let x = (m & 1) | ((m >> 1) & 2) | ((m >> 2) & 4);
    let y = ((m >> 1) & 1) | ((m >> 2) & 2) | ((m >> 3) & 4);
    ((block % per_row) * 8 + x, (block / per_row) * 8 + y)
}

/// The order in which a backward sums each face's per-pixel terms: the device's backward
/// kernel for each [`Method`](super::gpu::Method).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SumOrder {
    /// `grad_brute.comp` (`Method::Brute`): one unit per band of `band_rows` rows (the
    /// backward's band; the whole rendered height unless a driver's loop cap splits it), its
    /// pixels in row-major order.
    Brute {
        /// Rows per band.
        band_rows: u32,
    },
    /// `grad_tiled.comp` (`Method::Tiled`, the default): one unit per (face, tile), its pixels
    /// in [`morton_pixel`]'s order, summed a 2 × 2 quad at a time.
    Tiled {
        /// The forward's tile edge in pixels.
        tile: u32,
    },
}

/// `grad_world.comp` for a look-at view (perspective or orthographic).
fn world_grad(view: &super::setup::GpuView, p: V3, g: V3) -> V3 {
    use super::setup::PROJ_PERSPECTIVE;
    let row = |k: usize| [view.rows[k][0], view.rows[k][1], view.rows[k][2]];
    let rel = [p[0] - view.eye[0], p[1] - view.eye[1], p[2] - view.eye[2]];
    let pcam = [dot3(row(0), rel), dot3(row(1), rel), dot3(row(2), rel)];
    let d_cam = if view.projection == PROJ_PERSPECTIVE {
        let k_xy = fmath::rcp(pcam[2] * view.param);
        [
            g[0] * k_xy,
            g[1] * k_xy,
            g[2] - fmath::div((g[0] * pcam[0] + g[1] * pcam[1]) * k_xy, pcam[2]),
        ]
    } else {
        [g[0] * view.param, g[1] * view.param, g[2]]
    };
    let (r0, r1, r2) = (row(0), row(1), row(2));
    [0, 1, 2].map(|a| (r0[a] * d_cam[0] + r1[a] * d_cam[1]) + r2[a] * d_cam[2])
}
