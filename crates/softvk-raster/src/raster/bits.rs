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

mod backward;
mod face_setup;
mod forward;
mod lighting;
mod pixel_grad;

pub use backward::{BackwardTwin, SumOrder, morton_pixel};
pub use face_setup::{face_setups, to_screen};
pub use lighting::{GpuLightTwin, host_lit_colors};

use super::fine::RasterPush;
use super::settings::{ColorMode, Dist, RasterSettings};
use super::setup::GpuFaceSetup;
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

/// `covered_arg`: the sigmoid's argument `x` where the face covers the pixel, 0 where it is
/// ignored (an ignored pair's D is never used; the kernels compute it anyway, and from its own
/// argument it can be subnormal, which costs a microcode assist per vector operation on x86).
pub(super) fn covered_arg(covered: bool, x: f32) -> f32 {
    if covered { x } else { 0.0 }
}

/// `coverage`: whether the face covers the pixel (false where it is ignored), and the coverage D.
fn coverage(f: &Face, w: V3, p: V2, dist: Dist, inv_sigma: f32, t: f32) -> (bool, f32) {
    match dist {
        Dist::Hard => (inside_closed(w), 1.0),
        Dist::Barycentric => {
            let m = w[0].min(w[1]).min(w[2]);
            let s = m * m.abs();
            let covered = -s < t;
            (covered, fmath::sigmoid(covered_arg(covered, s * inv_sigma)))
        }
        Dist::Euclidean => {
            let d2 = euclidean_dist2(f, p);
            let inside = strictly_inside(w);
            let covered = inside || d2 < t;
            let x = (if inside { d2 } else { -d2 }) * inv_sigma;
            (covered, fmath::sigmoid(covered_arg(covered, x)))
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
