//! The f64 forward soft rasterizer (SPEC §2): the oracle the GPU kernels are diffed against.
//!
//! It is written the way the GLSL will be, so a shader can follow it loop for loop:
//! - a *setup* pass per face ([`setup_face`], SoftRas's `forward_soft_rasterize_inv` kernel):
//!   screen vertices, inverse barycentric matrix, facing, grown bounding box;
//! - a *fine* pass per pixel ([`shade_pixel`]): one loop over faces with running accumulators
//!   for alpha ([`AlphaAccum`]), softmax colour ([`SoftmaxAccum`]) and hard colour
//!   ([`HardAccum`]), each step a small function: [`barycentric`], [`coverage`],
//!   [`clip_barycentric`], [`depth`], [`FaceColors::sample`].
//!
//! Where the SPEC differs from SoftRas (non-square pixel centres, euclidean distance to the edges
//! as segments, the clip floor, the softmax background weight `e^{ε/γ}`, no √T cull for the
//! barycentric distance), the SPEC is followed; see each function.

use glam::DVec3;

use crate::camera::{Camera, pixel_center};
use crate::lighting::{Lighting, positions_f64};
use crate::mesh::{Mesh, MeshError, validate_parts};

/// SoftRas clamps the barycentric determinant away from 0 to ±1e-10.
pub const MIN_DET: f64 = 1e-10;

/// Floor of the clipped barycentric sum before renormalization.
pub const CLIP_SUM_FLOOR: f64 = 1e-5;

/// Slack, in ulp per unit of R, of the texel rule's tie test (see [`surface_texel_index`]): the
/// rounding of `(w̃0 + w̃1) R` is a few ulp of R, in f64 here and in f32 on the GPU.
pub const TEXEL_TIE_ULPS: f64 = 8.0;

/// Absolute padding of the grown bounding boxes, so float rounding in the distance or the
/// barycentrics can never make a touched pixel fall just outside (screen coordinates are O(1),
/// rounding O(1e-16)).
const BBOX_PAD: f64 = 1e-9;

use super::settings::{Alpha, ColorMode, Dist, RasterSettings, RenderError, Rgb};

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// A [`Mesh`] in f64: what the image depends on smoothly, in the precision the twin computes
/// in. [`render`] converts to it; the backward ([`crate::raster::reference_grad`]) differentiates
/// with respect to its positions and colours, and its tests perturb them without f32 rounding.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshF64 {
    /// World-space vertex positions.
    pub positions: Vec<DVec3>,
    /// Triangles as indices into `positions`.
    pub faces: Vec<[u32; 3]>,
    /// Texture resolution R.
    pub texture_res: u32,
    /// `faces.len() * R²` texels, face-major, as [`Mesh::textures`].
    pub textures: Vec<[f64; 3]>,
    /// Per-vertex colours (vertex colour mode); `None` means white.
    pub vertex_colors: Option<Vec<[f64; 3]>>,
}

impl MeshF64 {
    /// The same mesh, widened to f64.
    pub fn from_mesh(mesh: &Mesh) -> MeshF64 {
        let widen = |c: &[f32; 3]| c.map(f64::from);
        MeshF64 {
            positions: positions_f64(mesh),
            faces: mesh.faces.clone(),
            texture_res: mesh.texture_res,
            textures: mesh.textures.iter().map(widen).collect(),
            vertex_colors: mesh
                .vertex_colors
                .as_ref()
                .map(|cs| cs.iter().map(widen).collect()),
        }
    }

    /// [`Mesh::validate`]'s checks, by the same code.
    pub fn validate(&self) -> Result<(), MeshError> {
        validate_parts(
            &self.positions,
            &self.faces,
            self.texture_res,
            self.textures.len(),
            self.vertex_colors.as_ref().map(Vec::len),
        )
    }
}

/// Per-face data computed once before the pixel loop (SoftRas `faces_info`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceSetup {
    /// Screen-space vertices `(x_s, y_s, z)`.
    pub v: [[f64; 3]; 3],
    /// Rows of `M_j`, the inverse of `[[x], [y], [1, 1, 1]]` with the determinant clamped to
    /// ±[`MIN_DET`]: `w_k = inv[k] · (x_p, y_p, 1)`.
    pub inv: [[f64; 3]; 3],
    /// Front-facing in screen space (SPEC §1).
    pub front: bool,
    /// All screen coordinates finite. A vertex on the camera plane of a perspective camera has
    /// none; such a face is skipped entirely rather than poisoning pixels with NaN.
    pub finite: bool,
    /// `[x_min, y_min, x_max, y_max]` from [`face_screen_bbox_grown`].
    pub bbox: [f64; 4],
}

/// SPEC §1 facing: front when `(y2 - y0)(x1 - x0) < (y1 - y0)(x2 - x0)` (clockwise on a y-up
/// screen, which is what an outward face towards the camera projects to).
pub fn is_front_facing(v: &[[f64; 3]; 3]) -> bool {
    (v[2][1] - v[0][1]) * (v[1][0] - v[0][0]) < (v[1][1] - v[0][1]) * (v[2][0] - v[0][0])
}

/// The screen determinant of `[[x0, x1, x2], [y0, y1, y2], [1, 1, 1]]`, unclamped.
pub(crate) fn screen_det(v: &[[f64; 3]; 3]) -> f64 {
    v[2][0] * (v[0][1] - v[1][1]) + v[0][0] * (v[1][1] - v[2][1]) + v[1][0] * (v[2][1] - v[0][1])
}

/// SoftRas's clamp: positive determinants to at least `MIN_DET`, others (zero included) to at
/// most `-MIN_DET`.
pub(crate) fn clamp_det(det: f64) -> f64 {
    if det > 0.0 {
        det.max(MIN_DET)
    } else {
        det.min(-MIN_DET)
    }
}

/// Whether the screen determinant is at the level of its own rounding error, so that its sign
/// and size say nothing: `|det| ≤ 4 ε_mach Σ|x_i (y_j − y_k)|`. Such a face (collapsed,
/// collinear, or seen exactly edge-on) has barycentrics that are rounding noise divided by the
/// clamped determinant; they can fall inside [0, 1] anywhere along its supporting line.
pub fn is_numerically_degenerate(v: &[[f64; 3]; 3]) -> bool {
    let terms = (v[2][0] * (v[0][1] - v[1][1])).abs()
        + (v[0][0] * (v[1][1] - v[2][1])).abs()
        + (v[1][0] * (v[2][1] - v[0][1])).abs();
    screen_det(v).abs() <= 4.0 * f64::EPSILON * terms
}

/// Screen-space box `[x_min, y_min, x_max, y_max]` outside which the face is ignored at every
/// pixel, for the given distance function and σ. The GPU binning assigns faces to tiles by it,
/// so it must be conservative; a test checks it on random and adversarial triangles.
///
/// - Euclidean: the vertices' box grown by `√T`. Outside, a face counts only while `d² < T`,
///   i.e. within `√T` of the triangle; inside lies within the triangle, because with a clamped
///   determinant the barycentrics are `s·w` with `s = |det| / MIN_DET ≤ 1`, which keeps their
///   signs.
/// - Hard: the vertices' box (inside means all `w ∈ [0, 1]`, within the triangle as above).
/// - Barycentric: a face counts where `min_k w_k > −√T`. With exact barycentrics that region
///   is the triangle scaled about its centroid by `1 + 3√T` (its corners solve
///   `w_i = w_j = −√T`: `V_k + 3√T (V_k − centroid)`), which reaches farther than `√T` from a
///   large triangle, so the euclidean box would lose pixels (SoftRas's `check_border` does cut
///   them; the SPEC's rule does not, and this follows the SPEC). With a clamped determinant the
///   barycentrics are scaled by `s < 1` and the factor becomes `1 + 3√T / s`.
/// - A [numerically degenerate](is_numerically_degenerate) face gets the infinite box in every
///   mode: its coverage is not bounded by its vertices.
///
/// Every finite box is padded by 1e-9 against rounding.
pub fn face_screen_bbox_grown(v: &[[f64; 3]; 3], dist: Dist, t: f64) -> [f64; 4] {
    if is_numerically_degenerate(v) {
        return [
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::INFINITY,
        ];
    }
    let r = t.sqrt();
    let xs = [v[0][0], v[1][0], v[2][0]];
    let ys = [v[0][1], v[1][1], v[2][1]];
    let min = |a: [f64; 3]| a[0].min(a[1]).min(a[2]);
    let max = |a: [f64; 3]| a[0].max(a[1]).max(a[2]);
    let (x0, y0, x1, y1) = (min(xs), min(ys), max(xs), max(ys));
    match dist {
        Dist::Euclidean => pad([x0 - r, y0 - r, x1 + r, y1 + r]),
        Dist::Hard => pad([x0, y0, x1, y1]),
        Dist::Barycentric => {
            let s = (screen_det(v).abs() / MIN_DET).min(1.0);
            let k = 1.0 + 3.0 * r / s;
            let cx = (xs[0] + xs[1] + xs[2]) / 3.0;
            let cy = (ys[0] + ys[1] + ys[2]) / 3.0;
            pad([
                cx + k * (x0 - cx),
                cy + k * (y0 - cy),
                cx + k * (x1 - cx),
                cy + k * (y1 - cy),
            ])
        }
    }
}

fn pad(b: [f64; 4]) -> [f64; 4] {
    [
        b[0] - BBOX_PAD,
        b[1] - BBOX_PAD,
        b[2] + BBOX_PAD,
        b[3] + BBOX_PAD,
    ]
}

/// Whether a pixel centre lies outside a face's box (SoftRas `check_border`, strict).
pub fn outside_bbox(bbox: &[f64; 4], xp: f64, yp: f64) -> bool {
    xp < bbox[0] || yp < bbox[1] || xp > bbox[2] || yp > bbox[3]
}

/// The setup pass for one face, from its screen-space vertices.
pub fn setup_face(v: [[f64; 3]; 3], dist: Dist, t: f64) -> FaceSetup {
    let [p0, p1, p2] = v;
    let adj = [
        [p1[1] - p2[1], p2[0] - p1[0], p1[0] * p2[1] - p2[0] * p1[1]],
        [p2[1] - p0[1], p0[0] - p2[0], p2[0] * p0[1] - p0[0] * p2[1]],
        [p0[1] - p1[1], p1[0] - p0[0], p0[0] * p1[1] - p1[0] * p0[1]],
    ];
    let det = clamp_det(screen_det(&v));
    FaceSetup {
        v,
        inv: adj.map(|row| row.map(|a| a / det)),
        front: is_front_facing(&v),
        finite: v.iter().flatten().all(|c| c.is_finite()),
        bbox: face_screen_bbox_grown(&v, dist, t),
    }
}

/// Screen-space vertices of every face.
pub fn project_faces(mesh: &Mesh, camera: &Camera) -> Vec<[[f64; 3]; 3]> {
    project_faces_of(&positions_f64(mesh), &mesh.faces, camera)
}

/// [`project_faces`] of f64 positions.
pub fn project_faces_of(
    positions: &[DVec3],
    faces: &[[u32; 3]],
    camera: &Camera,
) -> Vec<[[f64; 3]; 3]> {
    let screen: Vec<[f64; 3]> = positions.iter().map(|&p| camera.to_screen(p)).collect();
    faces
        .iter()
        .map(|f| f.map(|i| screen[i as usize]))
        .collect()
}

/// `w = M_j (x_p, y_p, 1)`.
pub fn barycentric(face: &FaceSetup, xp: f64, yp: f64) -> [f64; 3] {
    face.inv.map(|row| row[0] * xp + row[1] * yp + row[2])
}

/// Strictly inside: the sign δ of the euclidean distance (SoftRas's test).
fn strictly_inside(w: &[f64; 3]) -> bool {
    w.iter().all(|&x| x > 0.0 && x < 1.0)
}

/// Inside with the edges (SoftRas `check_pixel_inside`): hard coverage and hard colour.
pub fn inside_closed(w: &[f64; 3]) -> bool {
    w.iter().all(|&x| (0.0..=1.0).contains(&x))
}

/// Squared distance from `p` to the segment `a b` (a degenerate segment is its point).
pub fn dist2_point_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
    let len2 = ex * ex + ey * ey;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (dx, dy) = (a[0] + t * ex - p[0], a[1] + t * ey - p[1]);
    dx * dx + dy * dy
}

/// Squared euclidean distance from the pixel centre to the triangle's boundary: the nearest of
/// the three edges taken as segments (SPEC; SoftRas's closed form differs for some obtuse
/// configurations).
pub fn euclidean_dist2(v: &[[f64; 3]; 3], xp: f64, yp: f64) -> f64 {
    let p = [xp, yp];
    let q = |k: usize| [v[k][0], v[k][1]];
    dist2_point_segment(p, q(0), q(1))
        .min(dist2_point_segment(p, q(1), q(2)))
        .min(dist2_point_segment(p, q(2), q(0)))
}

/// Coverage `D` of a face at a pixel, or `None` when the face is ignored there (outside and
/// beyond the cut-off `t` = [`cutoff`](crate::raster::settings::cutoff)`(σ)`).
pub fn coverage(
    face: &FaceSetup,
    w: &[f64; 3],
    xp: f64,
    yp: f64,
    dist: Dist,
    sigma: f64,
    t: f64,
) -> Option<f64> {
    match dist {
        Dist::Hard => inside_closed(w).then_some(1.0),
        Dist::Barycentric => {
            let m = w[0].min(w[1]).min(w[2]);
            let signed = m * m.abs();
            (-signed < t).then(|| sigmoid(signed / sigma))
        }
        Dist::Euclidean => {
            let d2 = euclidean_dist2(&face.v, xp, yp);
            if strictly_inside(w) {
                Some(sigmoid(d2 / sigma))
            } else {
                (d2 < t).then(|| sigmoid(-d2 / sigma))
            }
        }
    }
}

/// `w̃`: w clamped to [0, 1] and renormalized, the sum floored at [`CLIP_SUM_FLOOR`].
pub fn clip_barycentric(w: [f64; 3]) -> [f64; 3] {
    let c = w.map(|x| x.clamp(0.0, 1.0));
    let sum = (c[0] + c[1] + c[2]).max(CLIP_SUM_FLOOR);
    c.map(|x| x / sum)
}

/// Perspective-correct depth `z = 1 / Σ_k (w̃_k / z_k)`.
pub fn depth(face: &FaceSetup, w_clip: &[f64; 3]) -> f64 {
    1.0 / (w_clip[0] / face.v[0][2] + w_clip[1] / face.v[1][2] + w_clip[2] / face.v[2][2])
}

/// Index of the texel SoftRas samples within a face's R×R texture (SPEC §2):
/// `a = ⌊w̃0 R⌋, b = ⌊w̃1 R⌋`, texel `b R + a` if `(w̃0 + w̃1) R − a − b ≤ 1`, else
/// `(R−1−b) R + (R−1−a)`.
///
/// `a` and `b` are clamped to R − 1: at a corner (`w̃0 = 1` or `w̃1 = 1`, common for clipped
/// pixels outside a vertex) SoftRas reads past the face's texels into the next face's; the
/// clamp picks the corner texel instead and changes nothing anywhere else.
///
/// The test `frac ≤ 1` is taken with a slack of [`TEXEL_TIE_ULPS`]` · R` ulp. On the face's edge
/// `w̃2 = 0` (every pixel of the soft halo beyond edge v0 v1 clips there) the exact `frac` is 1,
/// a tie that the rule sends to the lower texel; the rounded `w̃0 + w̃1` lands on either side of
/// 1, and the other branch is the *mirrored* texel `a R + b`. SoftRas's f32 kernel flips between
/// the two there; the slack makes the rule's own answer come out in f64 and f32 alike. Elsewhere
/// it only moves texel boundaries by that many ulp.
pub fn surface_texel_index(w_clip: &[f64; 3], res: u32) -> usize {
    let r = f64::from(res);
    let a = ((w_clip[0] * r) as u32).min(res - 1);
    let b = ((w_clip[1] * r) as u32).min(res - 1);
    let frac = (w_clip[0] + w_clip[1]) * r - f64::from(a) - f64::from(b);
    if frac <= 1.0 + TEXEL_TIE_ULPS * r * f64::EPSILON {
        (b * res + a) as usize
    } else {
        ((res - 1 - b) * res + (res - 1 - a)) as usize
    }
}

/// Lit colours in the form the pixel loop samples.
#[derive(Clone, Debug, PartialEq)]
pub enum FaceColors {
    /// Per-face R×R texels, face-major.
    Surface {
        /// R.
        res: u32,
        /// `F * R²` lit texels.
        texels: Vec<[f64; 3]>,
    },
    /// Per-vertex lit colours and the faces that index them.
    Vertex {
        /// The mesh's faces.
        faces: Vec<[u32; 3]>,
        /// One lit colour per vertex.
        colors: Vec<[f64; 3]>,
    },
}

impl FaceColors {
    /// Lights the mesh's colours for the given mode.
    pub fn new(mesh: &Mesh, lighting: &Lighting, mode: ColorMode) -> FaceColors {
        FaceColors::of(&MeshF64::from_mesh(mesh), lighting, mode)
    }

    /// [`FaceColors::new`] of an f64 mesh.
    pub fn of(mesh: &MeshF64, lighting: &Lighting, mode: ColorMode) -> FaceColors {
        match mode {
            ColorMode::Surface => FaceColors::Surface {
                res: mesh.texture_res,
                texels: lighting.apply_surface_of(
                    &mesh.positions,
                    &mesh.faces,
                    mesh.texture_res,
                    &mesh.textures,
                ),
            },
            ColorMode::Vertex => FaceColors::Vertex {
                faces: mesh.faces.clone(),
                colors: lighting.apply_vertex_of(
                    &mesh.positions,
                    &mesh.faces,
                    mesh.vertex_colors.as_deref(),
                ),
            },
        }
    }

    /// `C_j` at clipped barycentrics `w̃`.
    pub fn sample(&self, face: usize, w_clip: &[f64; 3]) -> [f64; 3] {
        match self {
            FaceColors::Surface { res, texels } => {
                let r2 = (res * res) as usize;
                texels[face * r2 + surface_texel_index(w_clip, *res)]
            }
            FaceColors::Vertex { faces, colors } => {
                let c = faces[face].map(|v| colors[v as usize]);
                std::array::from_fn(|k| {
                    w_clip[0] * c[0][k] + w_clip[1] * c[1][k] + w_clip[2] * c[2][k]
                })
            }
        }
    }
}

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

/// Averages 2×2 blocks of a `2W × 2H` image into `W × H` (SoftRas `avg_pool2d(2, 2)`).
pub fn downsample_2x2(image: &[[f64; 4]], width: u32, height: u32) -> Vec<[f64; 4]> {
    let (w, h) = (width as usize, height as usize);
    let big_w = 2 * w;
    let mut out = Vec::with_capacity(w * h);
    for row in 0..h {
        for col in 0..w {
            let at = |dr: usize, dc: usize| image[(2 * row + dr) * big_w + 2 * col + dc];
            let px = [at(0, 0), at(0, 1), at(1, 0), at(1, 1)];
            out.push(std::array::from_fn(|k| {
                (px[0][k] + px[1][k] + px[2][k] + px[3][k]) / 4.0
            }));
        }
    }
    out
}

/// Renders RGBA, row-major, row 0 at the top, `width × height` pixels.
///
/// Lighting is applied in world space before projection; then the setup pass per face and the
/// fine pass per pixel. With `antialias`, the image is rendered at `2W × 2H` (pixel centres from
/// that size) and averaged 2×2.
pub fn render(
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    settings: &RasterSettings,
) -> Result<Vec<[f64; 4]>, RenderError> {
    render_f64(&MeshF64::from_mesh(mesh), camera, lighting, settings)
}

/// [`render`] of an f64 mesh: the same pass, with positions and colours that are not rounded
/// to f32 (finite differences of the backward's tests perturb them by 1e-6).
pub fn render_f64(
    mesh: &MeshF64,
    camera: &Camera,
    lighting: &Lighting,
    settings: &RasterSettings,
) -> Result<Vec<[f64; 4]>, RenderError> {
    render_impl(mesh, camera, lighting, settings, true)
}

/// The faces of one view after the setup pass.
pub fn setup_view(mesh: &MeshF64, camera: &Camera, settings: &RasterSettings) -> Vec<FaceSetup> {
    project_faces_of(&mesh.positions, &mesh.faces, camera)
        .into_iter()
        .map(|v| setup_face(v, settings.dist, settings.cutoff()))
        .collect()
}

fn render_impl(
    mesh: &MeshF64,
    camera: &Camera,
    lighting: &Lighting,
    settings: &RasterSettings,
    cull: bool,
) -> Result<Vec<[f64; 4]>, RenderError> {
    mesh.validate()?;
    settings.validate()?;
    let colors = FaceColors::of(mesh, lighting, settings.color_mode);
    let faces = setup_view(mesh, camera, settings);
    let scale = if settings.antialias { 2 } else { 1 };
    let (w, h) = (settings.width * scale, settings.height * scale);
    let mut image = Vec::with_capacity((w * h) as usize);
    for row in 0..h {
        for col in 0..w {
            let (xp, yp) = pixel_center(col, row, w, h);
            image.push(shade_pixel(&faces, &colors, xp, yp, settings, cull));
        }
    }
    Ok(if settings.antialias {
        downsample_2x2(&image, settings.width, settings.height)
    } else {
        image
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::Directional;
    use crate::mesh::texel_center_barycentric;
    use crate::raster::settings::{DIST_EPS, cutoff};

    /// Small deterministic generator (xorshift64*), so tests need no extra crate.
    struct Rng(u64);

    impl Rng {
        fn next_f64(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }

        fn range(&mut self, lo: f64, hi: f64) -> f64 {
            lo + (hi - lo) * self.next_f64()
        }
    }

    fn settings(width: u32, height: u32) -> RasterSettings {
        RasterSettings {
            width,
            height,
            ..RasterSettings::default()
        }
    }

    /// A square in the plane z = `z` (world), half size `h`, facing the default camera (its
    /// SPEC normal is −z), with one flat colour.
    fn square(h: f32, z: f32, color: [f32; 3]) -> Mesh {
        let mut m = Mesh::new(
            vec![[-h, -h, z], [-h, h, z], [h, h, z], [h, -h, z]],
            vec![[0, 1, 2], [0, 2, 3]],
            1,
        )
        .unwrap();
        m.textures = vec![color; 2];
        m
    }

    fn merge(a: &Mesh, b: &Mesh) -> Mesh {
        let n = a.vertex_count() as u32;
        Mesh {
            positions: [a.positions.clone(), b.positions.clone()].concat(),
            faces: a
                .faces
                .iter()
                .copied()
                .chain(b.faces.iter().map(|f| f.map(|i| i + n)))
                .collect(),
            texture_res: 1,
            textures: [a.textures.clone(), b.textures.clone()].concat(),
            vertex_colors: None,
        }
    }

    fn pixel(img: &[[f64; 4]], width: u32, col: u32, row: u32) -> [f64; 4] {
        img[(row * width + col) as usize]
    }

    #[test]
    fn full_screen_quad_is_texture_times_light_exactly() {
        let color = [0.2, 0.4, 0.8];
        let mesh = square(3.0, 0.0, color);
        let lighting = Lighting {
            ambient_intensity: 0.3,
            ambient_color: [1.0, 0.5, 1.0],
            directionals: vec![Directional {
                intensity: 0.6,
                color: [1.0, 1.0, 0.5],
                direction: [0.0, 0.6, -0.8],
            }],
        };
        // n = (0, 0, -1): cosine 0.8.
        let light = [0.3 + 0.6 * 0.8, 0.15 + 0.6 * 0.8, 0.3 + 0.3 * 0.8];
        let s = RasterSettings {
            background: [0.9, 0.1, 0.3],
            ..settings(24, 16)
        };
        let img = render(&mesh, &Camera::default(), &lighting, &s).unwrap();
        for (i, p) in img.iter().enumerate() {
            for k in 0..3 {
                let expected = f64::from(color[k]) * light[k];
                assert!((p[k] - expected).abs() < 1e-12, "pixel {i}: {p:?}");
            }
            // Away from the shared diagonal x_s = y_s both faces are sharp: alpha is 1.
            let (xp, yp) = pixel_center(i as u32 % 24, i as u32 / 24, 24, 16);
            if (xp - yp).abs() > 0.05 {
                assert!((p[3] - 1.0).abs() < 1e-12, "pixel {i}: alpha {}", p[3]);
            }
        }
        // On the shared edge each face has D = 1/2, so prod alpha is 1 − 1/4 (as in SoftRas).
        assert_eq!(pixel_center(10, 9, 24, 16), (-0.1875, -0.1875));
        assert!((pixel(&img, 24, 10, 9)[3] - 0.75).abs() < 1e-12);
    }

    #[test]
    fn triangle_alpha_is_one_inside_and_zero_far_outside() {
        // Screen-size triangle around the centre; σ = 1e-4 for a visible but narrow blur.
        let mesh = Mesh::new(
            vec![[-0.5, -0.5, 0.0], [0.0, 0.6, 0.0], [0.5, -0.5, 0.0]],
            vec![[0, 1, 2]],
            1,
        )
        .unwrap();
        let s = RasterSettings {
            sigma: 1e-4,
            ..settings(32, 32)
        };
        let img = render(&mesh, &Camera::default(), &Lighting::default(), &s).unwrap();
        let centre = pixel(&img, 32, 16, 17);
        assert!(centre[3] > 0.999, "inside alpha {}", centre[3]);
        assert!(centre[0] > 0.4, "inside colour {centre:?}");
        let corner = pixel(&img, 32, 0, 0);
        assert_eq!(corner, [0.0, 0.0, 0.0, 0.0]);
        // Alpha falls off across the edge: some pixel is neither covered nor empty.
        assert!(img.iter().any(|p| p[3] > 0.01 && p[3] < 0.99));
    }

    #[test]
    fn softmax_picks_the_nearer_of_two_overlapping_faces() {
        let red = square(3.0, 0.5, [1.0, 0.0, 0.0]);
        let green = square(3.0, 0.0, [0.0, 1.0, 0.0]); // nearer to the eye at z = -2.732
        let unlit = Lighting::unlit();
        for mesh in [merge(&red, &green), merge(&green, &red)] {
            let s = RasterSettings {
                gamma: 1e-4,
                ..settings(8, 8)
            };
            let img = render(&mesh, &Camera::default(), &unlit, &s).unwrap();
            for p in &img {
                assert!(p[1] > 0.999 && p[0] < 1e-3, "{p:?}");
            }
            // A large γ blends the two.
            let s = RasterSettings {
                gamma: 1.0,
                ..settings(8, 8)
            };
            let img = render(&mesh, &Camera::default(), &unlit, &s).unwrap();
            let p = pixel(&img, 8, 4, 4);
            assert!(p[0] > 0.3 && p[1] > 0.3, "{p:?}");
        }
    }

    #[test]
    fn hard_rgb_takes_the_nearest_inside_face() {
        let red = square(0.5, 0.5, [1.0, 0.0, 0.0]);
        let green = square(0.25, 0.0, [0.0, 1.0, 0.0]);
        let s = RasterSettings {
            rgb: Rgb::Hard,
            background: [0.0, 0.0, 1.0],
            ..settings(16, 16)
        };
        let mesh = merge(&red, &green);
        let img = render(&mesh, &Camera::default(), &Lighting::unlit(), &s).unwrap();
        assert_eq!(&pixel(&img, 16, 8, 8)[..3], &[0.0, 1.0, 0.0]);
        assert_eq!(&pixel(&img, 16, 6, 8)[..3], &[1.0, 0.0, 0.0]);
        assert_eq!(&pixel(&img, 16, 0, 0)[..3], &[0.0, 0.0, 1.0]);
    }

    #[test]
    fn single_sided_drops_a_back_face_from_colour_not_alpha() {
        // Wound so its SPEC normal points away from the camera: back-facing.
        let mesh = Mesh::new(
            vec![[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.0, 0.6, 0.0]],
            vec![[0, 1, 2]],
            1,
        )
        .unwrap();
        let cam = Camera::default();
        let v = project_faces(&mesh, &cam)[0];
        assert!(!is_front_facing(&v));
        let base = RasterSettings {
            background: [0.25, 0.5, 0.75],
            ..settings(16, 16)
        };
        let single = RasterSettings {
            double_sided: false,
            ..base
        };
        let lit = Lighting::unlit();
        let a = render(&mesh, &cam, &lit, &base).unwrap();
        let b = render(&mesh, &cam, &lit, &single).unwrap();
        let (pa, pb) = (pixel(&a, 16, 8, 8), pixel(&b, 16, 8, 8));
        assert!((pa[0] - 1.0).abs() < 1e-12, "double-sided colour {pa:?}");
        assert_eq!(&pb[..3], &[0.25, 0.5, 0.75]);
        assert!(pa[3] > 0.999);
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x[3], y[3], "alpha must not depend on facing");
        }
    }

    #[test]
    fn outward_faces_towards_the_camera_are_front_facing() {
        let mesh = Mesh::icosphere(1);
        let cam = Camera::default();
        let normals = crate::lighting::face_normals(&mesh);
        for (f, v) in project_faces(&mesh, &cam).iter().enumerate() {
            let c: DVec3 = mesh.faces[f]
                .iter()
                .map(|&i| DVec3::from(mesh.positions[i as usize].map(f64::from)))
                .sum::<DVec3>()
                / 3.0;
            let towards = normals[f].dot(cam.eye - c);
            if towards.abs() > 1e-3 {
                assert_eq!(is_front_facing(v), towards > 0.0, "face {f}");
            }
        }
    }

    #[test]
    fn tiny_gamma_stays_finite_and_picks_the_front() {
        let red = square(3.0, 0.5, [1.0, 0.0, 0.0]);
        let green = square(3.0, 0.0, [0.0, 1.0, 0.0]);
        let mesh = merge(&red, &green);
        let s = RasterSettings {
            gamma: 1e-6,
            ..settings(8, 6)
        };
        // The naive weights overflow: e^{ε/γ} = e^{1000}.
        assert!((s.eps / s.gamma).exp().is_infinite());
        let img = render(&mesh, &Camera::default(), &Lighting::unlit(), &s).unwrap();
        for p in &img {
            assert!(p.iter().all(|c| c.is_finite()), "{p:?}");
            assert!((p[1] - 1.0).abs() < 1e-12 && p[0] == 0.0, "{p:?}");
        }
        // And a triangle's soft edge against the background stays finite too.
        let tri = Mesh::new(
            vec![[-0.5, -0.5, 0.0], [0.0, 0.6, 0.0], [0.5, -0.5, 0.0]],
            vec![[0, 1, 2]],
            1,
        )
        .unwrap();
        let s = RasterSettings { sigma: 1e-3, ..s };
        let img = render(&tri, &Camera::default(), &Lighting::unlit(), &s).unwrap();
        assert!(img.iter().flatten().all(|c| c.is_finite()));
    }

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
    fn antialias_of_a_constant_image_is_that_constant() {
        let mesh = square(3.0, 0.0, [0.3, 0.6, 0.9]);
        let s = RasterSettings {
            antialias: true,
            ..settings(10, 7)
        };
        let img = render(&mesh, &Camera::default(), &Lighting::unlit(), &s).unwrap();
        assert_eq!(img.len(), 70);
        for p in &img {
            let expected = [0.3f32, 0.6, 0.9].map(f64::from);
            for k in 0..3 {
                assert!((p[k] - expected[k]).abs() < 1e-12, "{p:?}");
            }
        }
        // Anti-aliasing is exactly the 2× render averaged 2×2 (alpha included).
        let big = RasterSettings {
            antialias: false,
            ..settings(20, 14)
        };
        let big = render(&mesh, &Camera::default(), &Lighting::unlit(), &big).unwrap();
        assert_eq!(img, downsample_2x2(&big, 10, 7));
    }

    #[test]
    fn downsample_averages_each_2x2_block() {
        let big: Vec<[f64; 4]> = (0..16).map(|i| [f64::from(i), 0.0, 1.0, 2.0]).collect();
        let small = downsample_2x2(&big, 2, 2);
        assert_eq!(small[0], [(0.0 + 1.0 + 4.0 + 5.0) / 4.0, 0.0, 1.0, 2.0]);
        assert_eq!(small[3][0], (10.0 + 11.0 + 14.0 + 15.0) / 4.0);
    }

    #[test]
    fn non_square_images_keep_the_shorter_side_as_the_field_of_view() {
        // The same scene at 16×16 and 32×16: the wide image's middle 16 columns equal the square.
        let mesh = Mesh::icosphere(1);
        let sq = render(
            &mesh,
            &Camera::default(),
            &Lighting::default(),
            &settings(16, 16),
        );
        let wide = render(
            &mesh,
            &Camera::default(),
            &Lighting::default(),
            &settings(32, 16),
        );
        let (sq, wide) = (sq.unwrap(), wide.unwrap());
        for row in 0..16 {
            for col in 0..16 {
                let a = pixel(&sq, 16, col, row);
                let b = pixel(&wide, 32, col + 8, row);
                for k in 0..4 {
                    assert!((a[k] - b[k]).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn surface_texel_rule_inverts_the_texel_layout() {
        for res in 1..=8 {
            for i in 0..res * res {
                let w = texel_center_barycentric(res, i % res, i / res);
                assert_eq!(
                    surface_texel_index(&w, res),
                    i as usize,
                    "res {res} texel {i}"
                );
            }
        }
        // Corners read the corner texel, never past the face.
        for res in 1..=4 {
            assert_eq!(
                surface_texel_index(&[1.0, 0.0, 0.0], res),
                (res - 1) as usize
            );
            assert_eq!(
                surface_texel_index(&[0.0, 1.0, 0.0], res),
                ((res - 1) * res) as usize
            );
            assert_eq!(surface_texel_index(&[0.0, 0.0, 1.0], res), 0);
        }
    }

    /// Beyond edge v0 v1 every pixel clips to `w̃2 = 0`, where the rule's `frac` is exactly 1 and
    /// picks the lower texel; the rounded `w̃0 + w̃1` often lands just above 1, which without the
    /// tie slack would pick the mirrored texel `a R + b`.
    #[test]
    fn surface_texel_rule_keeps_the_lower_texel_on_the_edge_w2_0() {
        let mut rounded_above = 0;
        for i in 1..2000 {
            let c0 = f64::from(i) * 0.000_731_3;
            let w = clip_barycentric([c0, 1.3 - c0, -0.2]);
            assert_eq!(w[2], 0.0);
            rounded_above += usize::from(w[0] + w[1] > 1.0);
            for res in [2u32, 3, 5, 64] {
                let r = f64::from(res);
                let a = ((w[0] * r) as u32).min(res - 1);
                let b = ((w[1] * r) as u32).min(res - 1);
                assert_eq!(
                    surface_texel_index(&w, res),
                    (b * res + a) as usize,
                    "{w:?} R={res}"
                );
            }
        }
        assert!(
            rounded_above > 0,
            "the loop should hit the rounding it guards against"
        );
    }

    #[test]
    fn vertex_colours_interpolate_with_clipped_barycentrics() {
        let mut mesh = Mesh::new(
            vec![[-0.5, -0.5, 0.0], [0.0, 0.6, 0.0], [0.5, -0.5, 0.0]],
            vec![[0, 1, 2]],
            1,
        )
        .unwrap();
        mesh.vertex_colors = Some(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        let s = RasterSettings {
            color_mode: ColorMode::Vertex,
            rgb: Rgb::Hard,
            ..settings(16, 16)
        };
        let cam = Camera::default();
        let img = render(&mesh, &cam, &Lighting::unlit(), &s).unwrap();
        let face = setup_face(project_faces(&mesh, &cam)[0], s.dist, s.cutoff());
        let (xp, yp) = pixel_center(8, 9, 16, 16);
        let w = clip_barycentric(barycentric(&face, xp, yp));
        assert!(inside_closed(&w));
        let p = pixel(&img, 16, 8, 9);
        for k in 0..3 {
            assert!((p[k] - w[k]).abs() < 1e-12, "{p:?} vs {w:?}");
        }
    }

    #[test]
    fn near_and_far_drop_colour_but_not_alpha() {
        let mesh = square(3.0, 0.0, [1.0, 1.0, 1.0]); // depth 2.732
        let s = RasterSettings {
            near: 3.0,
            background: [0.5, 0.5, 0.5],
            ..settings(4, 4)
        };
        let img = render(&mesh, &Camera::default(), &Lighting::unlit(), &s).unwrap();
        for p in &img {
            assert_eq!(p[..3], [0.5, 0.5, 0.5]);
            assert!(p[3] >= 0.75, "{p:?}");
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

    #[test]
    fn euclidean_distance_is_to_edges_as_segments() {
        // Obtuse triangle; a point beyond the obtuse vertex is nearest to that vertex.
        let v = [[0.0, 0.0, 1.0], [4.0, 0.0, 1.0], [2.0, 0.5, 1.0]];
        assert!((euclidean_dist2(&v, 2.0, 1.5) - 1.0).abs() < 1e-12);
        // Beyond an end of the long edge: distance to the vertex, not to the edge's line.
        assert!((euclidean_dist2(&v, -3.0, -4.0) - 25.0).abs() < 1e-12);
        // Inside: distance to the nearest edge.
        let d = euclidean_dist2(&v, 2.0, 0.1);
        assert!((d - 0.01).abs() < 1e-12);
    }

    #[test]
    fn coverage_is_half_on_the_edge_and_ignored_past_the_cutoff() {
        let v = [[-0.5, -0.5, 2.0], [0.5, -0.5, 2.0], [0.0, 0.5, 2.0]];
        let sigma = 1e-3;
        let t = cutoff(sigma, DIST_EPS);
        let face = setup_face(v, Dist::Euclidean, t);
        assert!((t - 9.2102403669758 * sigma).abs() < 1e-12);
        let at =
            |x: f64, y: f64, dist| coverage(&face, &barycentric(&face, x, y), x, y, dist, sigma, t);
        assert!((at(0.0, -0.5, Dist::Euclidean).unwrap() - 0.5).abs() < 1e-9);
        let r = t.sqrt();
        assert!(at(0.0, -0.5 - 0.999 * r, Dist::Euclidean).is_some());
        assert!(at(0.0, -0.5 - 1.001 * r, Dist::Euclidean).is_none());
        // Just inside the cut-off the coverage is ε_d.
        let d = at(0.0, -0.5 - 0.999_999 * r, Dist::Euclidean).unwrap();
        assert!((d - DIST_EPS).abs() < 1e-8, "{d}");
        assert!(at(0.0, 0.0, Dist::Euclidean).unwrap() > 0.5);
        assert_eq!(at(0.0, 0.0, Dist::Hard), Some(1.0));
        assert_eq!(at(0.0, -0.51, Dist::Hard), None);
        assert!(at(0.0, 0.0, Dist::Barycentric).unwrap() > 0.5);
    }

    fn random_triangle(rng: &mut Rng) -> [[f64; 3]; 3] {
        let mut v: [[f64; 3]; 3] =
            std::array::from_fn(|_| [rng.range(-1.3, 1.3), rng.range(-1.3, 1.3), 2.0]);
        match (rng.next_f64() * 7.0) as u32 {
            // Sliver: the third vertex close to the first edge.
            0 => {
                let t = rng.range(-0.5, 1.5);
                let e = rng.range(-1e-4, 1e-4);
                v[2][0] = v[0][0] + t * (v[1][0] - v[0][0]);
                v[2][1] = v[0][1] + t * (v[1][1] - v[0][1]) + e;
            }
            // Near-degenerate: determinant around the clamp.
            1 => {
                let t = rng.range(0.2, 0.8);
                v[2][0] = v[0][0] + t * (v[1][0] - v[0][0]) + rng.range(-1e-10, 1e-10);
                v[2][1] = v[0][1] + t * (v[1][1] - v[0][1]);
            }
            // All three vertices on one row of pixel centres: exactly collinear.
            3 => {
                let row = (rng.next_f64() * 40.0) as u32;
                let y = pixel_center(0, row, 48, 40).1;
                for p in &mut v {
                    p[1] = y;
                }
            }
            // Small triangle.
            2 => {
                let base = v[0];
                for p in &mut v[1..] {
                    p[0] = base[0] + rng.range(-0.05, 0.05);
                    p[1] = base[1] + rng.range(-0.05, 0.05);
                }
            }
            _ => {}
        }
        v
    }

    /// Every (face, pixel) pair that is not ignored lies in the face's grown box, for every
    /// distance function, on random (also sliver and near-degenerate) triangles. Coverage is
    /// evaluated here without any box, so the test is independent of the cull.
    #[test]
    fn grown_bbox_contains_every_touched_pixel() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let (w, h) = (48u32, 40u32);
        // Adversarial slivers lying on a row (y = 0.025) or column (x = 1/40) of pixel centres,
        // with heights around and below the determinant clamp, and a point on a pixel centre.
        let mut special = Vec::new();
        for height in [0.0, 1e-13, 2e-12, 5e-11, 1e-9, 1e-6] {
            let y = 0.025;
            special.push([[-0.5, y, 2.0], [0.5, y, 2.0], [0.1, y + height, 2.0]]);
            let x = 0.025;
            special.push([[x, -0.5, 2.0], [x + height, 0.2, 2.0], [x, 0.5, 2.0]]);
        }
        special.push([[0.025, 0.025, 2.0]; 3]);
        let mut touched_outside_plain_bbox = [0usize; 3];
        for (di, dist) in [Dist::Euclidean, Dist::Barycentric, Dist::Hard]
            .into_iter()
            .enumerate()
        {
            for sigma in [1e-5, 1e-3, 2e-2, 1e-1] {
                let t = cutoff(sigma, DIST_EPS);
                let random = (0..60).map(|_| random_triangle(&mut rng));
                for v in special.clone().into_iter().chain(random) {
                    let face = setup_face(v, dist, t);
                    let plain = face_screen_bbox_grown(&v, Dist::Hard, t);
                    for row in 0..h {
                        for col in 0..w {
                            let (xp, yp) = pixel_center(col, row, w, h);
                            let wb = barycentric(&face, xp, yp);
                            if coverage(&face, &wb, xp, yp, dist, sigma, t).is_none() {
                                continue;
                            }
                            assert!(
                                !outside_bbox(&face.bbox, xp, yp),
                                "{dist:?} σ={sigma} {v:?}: pixel ({xp}, {yp}) outside {:?}",
                                face.bbox
                            );
                            if outside_bbox(&plain, xp, yp) {
                                touched_outside_plain_bbox[di] += 1;
                            }
                        }
                    }
                }
            }
        }
        // The growth matters: soft faces do reach past their vertices' box.
        assert!(touched_outside_plain_bbox[0] > 0 && touched_outside_plain_bbox[1] > 0);
        assert_eq!(touched_outside_plain_bbox[2], 0);
    }

    /// The barycentric distance reaches further than √T from a large triangle, so the euclidean
    /// growth would lose pixels there (SoftRas's √T border test does exactly that).
    #[test]
    fn barycentric_reach_exceeds_sqrt_t_for_large_triangles() {
        let v = [[-1.0, -1.0, 2.0], [1.0, -1.0, 2.0], [0.0, 1.0, 2.0]];
        let sigma = 1e-2;
        let t = cutoff(sigma, DIST_EPS);
        let face = setup_face(v, Dist::Barycentric, t);
        let euclid = face_screen_bbox_grown(&v, Dist::Euclidean, t);
        // Just below the bottom edge, beyond √T, but within the scaled triangle.
        let (xp, yp) = (0.0, -1.0 - 1.5 * t.sqrt());
        let w = barycentric(&face, xp, yp);
        assert!(coverage(&face, &w, xp, yp, Dist::Barycentric, sigma, t).is_some());
        assert!(outside_bbox(&euclid, xp, yp));
        assert!(!outside_bbox(&face.bbox, xp, yp));
    }

    #[test]
    fn coincident_vertices_cover_everything_in_barycentric_and_hard_modes() {
        let v = [[0.2, 0.2, 2.0]; 3];
        assert!(is_numerically_degenerate(&v));
        for dist in [Dist::Barycentric, Dist::Hard] {
            let face = setup_face(v, dist, cutoff(1e-4, DIST_EPS));
            let w = barycentric(&face, -0.9, 0.9);
            assert!(coverage(&face, &w, -0.9, 0.9, dist, 1e-4, cutoff(1e-4, DIST_EPS)).is_some());
        }
        for dist in [Dist::Euclidean, Dist::Barycentric, Dist::Hard] {
            let b = setup_face(v, dist, cutoff(1e-4, DIST_EPS)).bbox;
            assert!(b[0] == f64::NEG_INFINITY && b[3] == f64::INFINITY);
        }
        // A thin but well-conditioned sliver keeps a finite box.
        let sliver = [
            [-0.5, 0.025, 2.0],
            [0.5, 0.025, 2.0],
            [0.1, 0.025 + 1e-13, 2.0],
        ];
        assert!(!is_numerically_degenerate(&sliver));
        assert!(
            face_screen_bbox_grown(&sliver, Dist::Barycentric, cutoff(1e-4, DIST_EPS))[2]
                .is_finite()
        );
    }

    #[test]
    fn culling_by_the_grown_bbox_changes_nothing() {
        let mut rng = Rng(42);
        let mut positions = Vec::new();
        let mut faces = Vec::new();
        for f in 0..12u32 {
            let c = [
                rng.range(-0.8, 0.8),
                rng.range(-0.8, 0.8),
                rng.range(-0.5, 0.5),
            ];
            for _ in 0..3 {
                positions.push([
                    (c[0] + rng.range(-0.4, 0.4)) as f32,
                    (c[1] + rng.range(-0.4, 0.4)) as f32,
                    (c[2] + rng.range(-0.2, 0.2)) as f32,
                ]);
            }
            faces.push([3 * f, 3 * f + 1, 3 * f + 2]);
        }
        let mut mesh = Mesh::new(positions, faces, 2).unwrap();
        for (i, t) in mesh.textures.iter_mut().enumerate() {
            *t = [
                (i % 3) as f32 / 2.0,
                (i % 5) as f32 / 4.0,
                (i % 7) as f32 / 6.0,
            ];
        }
        for dist in [Dist::Euclidean, Dist::Barycentric, Dist::Hard] {
            for rgb in [Rgb::Softmax, Rgb::Hard] {
                let s = RasterSettings {
                    sigma: 3e-3,
                    gamma: 1e-2,
                    dist,
                    rgb,
                    alpha: Alpha::Sum,
                    ..settings(20, 14)
                };
                let cam = Camera::default();
                let lit = Lighting::default();
                let mesh = MeshF64::from_mesh(&mesh);
                let culled = render_impl(&mesh, &cam, &lit, &s, true).unwrap();
                let brute = render_impl(&mesh, &cam, &lit, &s, false).unwrap();
                assert_eq!(culled, brute, "{dist:?} {rgb:?}");
            }
        }
    }

    #[test]
    fn bad_settings_and_meshes_are_errors() {
        let mesh = Mesh::icosphere(0);
        let cam = Camera::default();
        let lit = Lighting::default();
        for s in [
            RasterSettings {
                width: 0,
                ..settings(4, 4)
            },
            RasterSettings {
                sigma: 0.0,
                ..settings(4, 4)
            },
            RasterSettings {
                gamma: f64::NAN,
                ..settings(4, 4)
            },
            RasterSettings {
                near: 5.0,
                far: 1.0,
                ..settings(4, 4)
            },
        ] {
            let err = render(&mesh, &cam, &lit, &s).unwrap_err();
            assert!(matches!(err, RenderError::Settings(_)), "{err}");
        }
        let mut bad = mesh.clone();
        bad.faces[3][1] = 99;
        let err = render(&bad, &cam, &lit, &settings(4, 4)).unwrap_err();
        assert!(err.to_string().contains("face 3"), "{err}");
    }

    #[test]
    fn spot_renders_to_a_plausible_image() {
        let mesh = Mesh::load_obj(&crate::assets::dir().join("spot_triangulated.obj"), 1).unwrap();
        let s = settings(32, 32);
        let img = render(
            &mesh,
            &Camera::from_angles(2.732, 30.0, -45.0),
            &Lighting::default(),
            &s,
        )
        .unwrap();
        let covered = img.iter().filter(|p| p[3] > 0.5).count();
        assert!(covered > 100 && covered < 1000, "{covered} pixels covered");
        assert!(
            img.iter()
                .flatten()
                .all(|c| c.is_finite() && (0.0..=1.0 + 1e-12).contains(c))
        );
    }
}
