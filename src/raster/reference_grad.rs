//! The f64 backward pass (SPEC §3): the exact derivative of [`reference`](mod@reference)'s
//! forward, the oracle a GPU backward is diffed against.
//!
//! # Design
//!
//! The backward is split the way the GPU will run it, each step a function a kernel mirrors:
//!
//! 1. **Forward with aux** ([`forward_view`]): the forward also keeps, per rendered pixel, its
//!    RGBA and its aggregates' final state, [`PixelAux`]. The backward never re-runs the
//!    forward; it reads these.
//! 2. **Per pixel, per face** ([`pixel_face_grad`]): from the pixel's upstream gradient and its
//!    aggregates ([`PixelUpstream`]), one face's contribution is computed without looking at any
//!    other face, so one pass over the faces suffices:
//!    - softmax, `I = (Σ_j w_j C_j + w_b C_b) / S`, `w_j = D_j e_j`, `e_j = e^{(z̄_j − max)/γ}`:
//!      `∂I/∂C_j = w_j / S`, `∂I/∂w_j = (C_j − I) / S`, `∂w_j/∂D_j = e_j`,
//!      `∂w_j/∂z_j = −w_j / (γ (far − near))` (the running max cancels);
//!    - alpha prod, `A = 1 − Π(1 − D_k)`: `∂A/∂D_j = Π_{k≠j}(1 − D_k)`, taken exactly from the
//!      count of factors that are exactly 0 and the product of the others
//!      ([`PixelAux::alpha_zeros`], [`PixelAux::alpha_acc`]): never a 0/0 where `D_j` rounds
//!      to 1; sum: `1/F`; hard: 0;
//!    - hard colour: the winner ([`PixelAux::hard_face`]) gets the whole colour gradient.
//!
//!    Then, inside the face: colour through the clipped barycentrics `w̃` (vertex colours),
//!    depth `z = 1/Σ_k(w̃_k / z_k)` through `w̃` and the vertex depths, the clip and its
//!    renormalization (floor included), the coverage through the euclidean point–segment
//!    distance (by the envelope theorem `∂d²/∂a = 2(1 − t) r`, `∂d²/∂b = 2 t r`, `r` the
//!    pixel's offset from its nearest point `a + t (b − a)`) or the smallest barycentric, and
//!    the barycentrics `w_k = n_k / det` (`n_k` the sub-determinant, `det` the clamped
//!    determinant, constant where clamped) to the face's screen vertices `(x_s, y_s, z)`.
//!    Where the forward has a kink (cut-off, clip, near/far, texel and hard-colour boundaries,
//!    the nearest edge, the light's `max(0, ·)`) this is the derivative of the branch taken:
//!    the a.e. derivative.
//! 3. **Per view, per face** ([`backward_view`], [`face_screen_to_world_grad`]): the pixels'
//!    contributions are summed per face (screen vertices, and the face's R² texels or its 3
//!    corner colours), then chained through the projection to world space, with the face's
//!    share of `∂L/∂R` (R the look-at rotation) for the camera ([`camera_grad`],
//!    [`look_at_grad`]).
//! 4. **Per vertex** ([`VertexFaces::gather`]): every vertex sums its incident (face, corner)
//!    slots in face order. Lighting ([`lighting_grad_surface`], [`lighting_grad_vertex`])
//!    turns the lit colours' gradient into the raw colours' and, through face normals (surface)
//!    or vertex normals (vertex), into more per-corner position gradients before that gather.
//!
//! With anti-aliasing the output gradient is spread as `1/4` to each of the 2×2 rendered
//! pixels ([`upsample_grad_2x2`]); views are summed in order.
//!
//! Sources of the formulas: the forward's own definitions (SPEC §1–§2, `reference.rs`,
//! `camera.rs`, `lighting.rs`), differentiated by hand. SoftRas's
//! `backward_soft_rasterize_cuda_kernel` has the same softmax terms, but takes the prod's
//! `∂A/∂D_j` as `(1 − A) / max(1 − D_j, 1e-6)` (wrong where a coverage rounds to 1), sends
//! the depth term to the vertex depths only, and drops depth and colour through `w̃` (SPEC §3
//! asks for them). The tests check every component against central finite differences of
//! [`reference::render_f64`].
//!
//! # Per-pixel state the backward needs
//!
//! The rendered pixel's RGBA (before the 2×2 average) and [`PixelAux`]: `softmax_max` (the GPU
//! keeps it as a depth), `softmax_sum`, `alpha_acc` (prod: the product of the non-zero
//! factors), `alpha_zeros` and `hard_face`.

use glam::DVec3;

use crate::camera::{Camera, Projection, look_at, pixel_center};
use crate::lighting::{Lighting, NORMAL_EPS, face_normal_raw, vertex_normal_sums};
use crate::mesh::Mesh;
use crate::raster::reference::{
    self, FaceColors, FaceSetup, MeshF64, PixelAux, barycentric, clip_barycentric, coverage, depth,
    dist2_point_segment, outside_bbox, setup_view, shade_pixel_aux, surface_texel_index,
};
use crate::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, RenderError, Rgb};

/// `look_at` normalizes with this eps (SoftRas's).
const LOOK_AT_EPS: f64 = 1e-5;

/// dL/d(camera) of one view.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraGrad {
    /// dL/d(eye).
    pub eye: [f64; 3],
    /// dL/d(at), the point looked at.
    pub at: [f64; 3],
    /// dL/d(up), the up hint (as given: `look_at` normalizes it).
    pub up: [f64; 3],
}

impl CameraGrad {
    /// dL/d(distance, elevation°, azimuth°) for a camera built by
    /// [`Camera::from_angles`]`(distance, elevation_deg, azimuth_deg)`, from [`CameraGrad::eye`]
    /// (angles in degrees, as the camera takes them).
    pub fn angles(&self, distance: f64, elevation_deg: f64, azimuth_deg: f64) -> [f64; 3] {
        let (el, az) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
        let (se, ce, sa, ca) = (el.sin(), el.cos(), az.sin(), az.cos());
        let k = std::f64::consts::PI / 180.0;
        let g = DVec3::from(self.eye);
        let d_distance = DVec3::new(ce * sa, se, -ce * ca);
        let d_elevation = k * distance * DVec3::new(-se * sa, ce, se * ca);
        let d_azimuth = k * distance * DVec3::new(ce * ca, 0.0, ce * sa);
        [g.dot(d_distance), g.dot(d_elevation), g.dot(d_azimuth)]
    }
}

/// Everything [`grad`] returns.
#[derive(Clone, Debug, PartialEq)]
pub struct Gradients {
    /// dL/d(world vertex position), one per mesh vertex, in the mesh's order.
    pub positions: Vec<[f64; 3]>,
    /// dL/d(colours before lighting), in the layout of the colour source: surface mode the
    /// mesh's `F·R²` texels (face-major, as [`Mesh::textures`]); vertex mode one per vertex
    /// (with respect to the implicit white when the mesh has no vertex colours).
    pub colors: Vec<[f64; 3]>,
    /// dL/d(camera), one per view.
    pub cameras: Vec<CameraGrad>,
}

/// The gradient of `L` with respect to the mesh and cameras, given `d_image` = dL/d(image):
/// RGBA per output pixel, view-major, then row-major, `W × H` per view (as the forward's output,
/// after the 2×2 average when anti-aliasing).
pub fn grad(
    mesh: &Mesh,
    cameras: &[Camera],
    lighting: &Lighting,
    settings: &RasterSettings,
    d_image: &[[f64; 4]],
) -> Result<Gradients, RenderError> {
    grad_f64(
        &MeshF64::from_mesh(mesh),
        cameras,
        lighting,
        settings,
        d_image,
    )
}

/// [`grad`] of an f64 mesh.
pub fn grad_f64(
    mesh: &MeshF64,
    cameras: &[Camera],
    lighting: &Lighting,
    s: &RasterSettings,
    d_image: &[[f64; 4]],
) -> Result<Gradients, RenderError> {
    mesh.validate()?;
    s.validate()?;
    if cameras.is_empty() {
        return Err(RenderError::Input("no views to differentiate".into()));
    }
    let px = (s.width * s.height) as usize;
    if d_image.len() != cameras.len() * px {
        return Err(RenderError::Input(format!(
            "the image gradient has {} pixels, but {} views of {}x{} need {}",
            d_image.len(),
            cameras.len(),
            s.width,
            s.height,
            cameras.len() * px
        )));
    }
    if let Some(i) = d_image
        .iter()
        .position(|g| !g.iter().all(|c| c.is_finite()))
    {
        return Err(RenderError::Input(format!(
            "the image gradient is not finite at pixel {} of view {}",
            i % px,
            i / px
        )));
    }

    let colors = FaceColors::of(mesh, lighting, s.color_mode);
    let nf = mesh.faces.len();
    let slots = color_slots(s.color_mode, mesh.texture_res);
    // Per (face, corner): dL/d(world position), from every view's projection, then lighting.
    let mut corner_positions = vec![[0.0; 3]; 3 * nf];
    // Per face and colour slot: dL/d(lit colour), summed over views.
    let mut lit_colors = vec![[0.0; 3]; slots * nf];
    let mut camera_grads = Vec::with_capacity(cameras.len());
    for (view, camera) in cameras.iter().enumerate() {
        let fwd = forward_view(mesh, camera, &colors, s);
        let d_view = &d_image[view * px..(view + 1) * px];
        let d_rendered = if s.antialias {
            upsample_grad_2x2(d_view, s.width, s.height)
        } else {
            d_view.to_vec()
        };
        let faces = backward_view(&fwd, &colors, &d_rendered, s);
        let rotation = look_at(camera.eye, camera.at, camera.up);
        let mut d_rotation = [[0.0; 3]; 3];
        let mut d_world_sum = [0.0; 3];
        for (f, face) in mesh.faces.iter().enumerate() {
            let corners = face.map(|i| mesh.positions[i as usize]);
            let world = face_screen_to_world_grad(camera, &rotation, corners, &faces.screen[f]);
            for (c, g) in world.corners.into_iter().enumerate() {
                add3(&mut corner_positions[3 * f + c], g);
                add3(&mut d_world_sum, g);
            }
            for (acc, row) in d_rotation.iter_mut().zip(world.rotation) {
                add3(acc, row);
            }
        }
        for (acc, g) in lit_colors.iter_mut().zip(&faces.colors) {
            add3(acc, *g);
        }
        camera_grads.push(camera_grad(camera, d_rotation, d_world_sum));
    }

    let adjacency = VertexFaces::new(&mesh.faces, mesh.positions.len());
    let (color_grads, light_corners) = match s.color_mode {
        ColorMode::Surface => lighting_grad_surface(
            lighting,
            &mesh.positions,
            &mesh.faces,
            mesh.texture_res,
            &mesh.textures,
            &lit_colors,
        ),
        ColorMode::Vertex => {
            let d_lit = adjacency.gather(&lit_colors);
            lighting_grad_vertex(
                lighting,
                &mesh.positions,
                &mesh.faces,
                mesh.vertex_colors.as_deref(),
                &d_lit,
            )
        }
    };
    for (acc, g) in corner_positions.iter_mut().zip(&light_corners) {
        add3(acc, *g);
    }
    Ok(Gradients {
        positions: adjacency.gather(&corner_positions),
        colors: color_grads,
        cameras: camera_grads,
    })
}

fn add3(acc: &mut [f64; 3], g: [f64; 3]) {
    for k in 0..3 {
        acc[k] += g[k];
    }
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Colour parameters per face: R² texels (surface) or 3 corner colours (vertex).
pub fn color_slots(mode: ColorMode, texture_res: u32) -> usize {
    match mode {
        ColorMode::Surface => (texture_res * texture_res) as usize,
        ColorMode::Vertex => 3,
    }
}

// ---------------------------------------------------------------------------------------------
// Forward with aux.

/// One view's forward, as the GPU forward leaves it for the backward: the setup pass's faces,
/// and per *rendered* pixel (2× with anti-aliasing) the RGBA and the [`PixelAux`].
#[derive(Clone, Debug)]
pub struct ViewForward {
    /// Faces after the setup pass.
    pub faces: Vec<FaceSetup>,
    /// Rendered width (2× the output with anti-aliasing).
    pub width: u32,
    /// Rendered height.
    pub height: u32,
    /// Rendered RGBA, row-major.
    pub image: Vec<[f64; 4]>,
    /// The aggregates' final state per rendered pixel.
    pub aux: Vec<PixelAux>,
}

/// The forward of one view with its aux, exactly [`reference::render_f64`]'s pixels before the
/// 2×2 average.
pub fn forward_view(
    mesh: &MeshF64,
    camera: &Camera,
    colors: &FaceColors,
    s: &RasterSettings,
) -> ViewForward {
    let faces = setup_view(mesh, camera, s);
    let scale = if s.antialias { 2 } else { 1 };
    let (width, height) = (s.width * scale, s.height * scale);
    let mut image = Vec::with_capacity((width * height) as usize);
    let mut aux = Vec::with_capacity((width * height) as usize);
    for row in 0..height {
        for col in 0..width {
            let (xp, yp) = pixel_center(col, row, width, height);
            let (rgba, a) = shade_pixel_aux(&faces, colors, xp, yp, s, true);
            image.push(rgba);
            aux.push(a);
        }
    }
    ViewForward {
        faces,
        width,
        height,
        image,
        aux,
    }
}

/// The adjoint of [`reference::downsample_2x2`]: each output pixel's gradient, `/4`, to its
/// 2×2 rendered pixels.
pub fn upsample_grad_2x2(d: &[[f64; 4]], width: u32, height: u32) -> Vec<[f64; 4]> {
    let (w, h) = (width as usize, height as usize);
    let mut out = vec![[0.0; 4]; 4 * w * h];
    for row in 0..2 * h {
        for col in 0..2 * w {
            out[row * 2 * w + col] = d[(row / 2) * w + col / 2].map(|g| g / 4.0);
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// Step 1: per pixel, per face.

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
fn nearest_edge(v: &[[f64; 3]; 3], p: [f64; 2]) -> (f64, usize, usize, f64) {
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
fn argmin3(w: &[f64; 3]) -> usize {
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

// ---------------------------------------------------------------------------------------------
// Step 2: per view, per face.

/// One view's pixel contributions summed per face.
#[derive(Clone, Debug, PartialEq)]
pub struct FaceScreenGrads {
    /// Per face, dL/d(screen vertex `(x_s, y_s, z)`) of each corner.
    pub screen: Vec<[[f64; 3]; 3]>,
    /// Per face, [`color_slots`] dL/d(lit colour)s: its R² texels or its 3 corners.
    pub colors: Vec<[f64; 3]>,
}

/// The backward of one view's fine pass: every rendered pixel (row-major), every face in
/// order, summed per face. `d_rendered` is dL/d(rendered RGBA) ([`upsample_grad_2x2`] of the
/// output's with anti-aliasing).
pub fn backward_view(
    fwd: &ViewForward,
    colors: &FaceColors,
    d_rendered: &[[f64; 4]],
    s: &RasterSettings,
) -> FaceScreenGrads {
    let nf = fwd.faces.len();
    let slots = match colors {
        FaceColors::Surface { res, .. } => color_slots(ColorMode::Surface, *res),
        FaceColors::Vertex { .. } => color_slots(ColorMode::Vertex, 1),
    };
    let mut out = FaceScreenGrads {
        screen: vec![[[0.0; 3]; 3]; nf],
        colors: vec![[0.0; 3]; slots * nf],
    };
    for row in 0..fwd.height {
        for col in 0..fwd.width {
            let i = (row * fwd.width + col) as usize;
            let up = PixelUpstream::new(
                pixel_center(col, row, fwd.width, fwd.height),
                fwd.image[i],
                fwd.aux[i],
                d_rendered[i],
                nf,
            );
            if up.is_zero() {
                continue;
            }
            for (j, face) in fwd.faces.iter().enumerate() {
                let Some(g) = pixel_face_grad(face, j, colors, &up, s) else {
                    continue;
                };
                for (acc, gk) in out.screen[j].iter_mut().zip(g.screen) {
                    add3(acc, gk);
                }
                match g.color {
                    Some(ColorSampleGrad::Texel { texel, rgb }) => {
                        add3(&mut out.colors[j * slots + texel], rgb);
                    }
                    Some(ColorSampleGrad::Corners(c)) => {
                        for (k, ck) in c.into_iter().enumerate() {
                            add3(&mut out.colors[j * 3 + k], ck);
                        }
                    }
                    None => {}
                }
            }
        }
    }
    out
}

/// One face's screen-space gradient in world space, for one view.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FaceWorldGrad {
    /// dL/d(world position) of each corner, through this view's projection.
    pub corners: [[f64; 3]; 3],
    /// This face's share of dL/d(R), R the look-at rotation (rows x, y, z); zero for a matrix
    /// projection, which does not use the look-at.
    pub rotation: [[f64; 3]; 3],
}

/// Chains a face's dL/d(screen vertices) through the projection and `p_c = R (p − eye)` to
/// world space; `rotation` is the view's `look_at(eye, at, up)`.
pub fn face_screen_to_world_grad(
    camera: &Camera,
    rotation: &[[f64; 3]; 3],
    corners: [DVec3; 3],
    screen: &[[f64; 3]; 3],
) -> FaceWorldGrad {
    let mut out = FaceWorldGrad::default();
    let r = rotation.map(DVec3::from);
    for (k, &p) in corners.iter().enumerate() {
        let g = screen[k];
        // Also keeps a vertex on a perspective camera's plane (a face the forward skips as
        // not finite) from turning 0 · ∞ into NaN.
        if g == [0.0; 3] {
            continue;
        }
        let rel = p - camera.eye;
        let pc = DVec3::new(r[0].dot(rel), r[1].dot(rel), r[2].dot(rel));
        let d_cam = match &camera.projection {
            Projection::Perspective { viewing_angle_deg } => {
                let width = viewing_angle_deg.to_radians().tan();
                let k_xy = 1.0 / (pc.z * width);
                DVec3::new(
                    g[0] * k_xy,
                    g[1] * k_xy,
                    g[2] - (g[0] * pc.x + g[1] * pc.y) * k_xy / pc.z,
                )
            }
            Projection::Orthographic { scale } => DVec3::new(g[0] * scale, g[1] * scale, g[2]),
            Projection::Matrix {
                p: m,
                dist_coeffs,
                orig_size,
            } => {
                out.corners[k] = matrix_projection_grad(m, dist_coeffs, *orig_size, p, g);
                continue;
            }
        };
        out.corners[k] = (r[0] * d_cam.x + r[1] * d_cam.y + r[2] * d_cam.z).to_array();
        for (i, di) in d_cam.to_array().into_iter().enumerate() {
            for c in 0..3 {
                out.rotation[i][c] += di * rel[c];
            }
        }
    }
    out
}

/// dL/d(world point) through SoftRas's `projection` (3×4 matrix, Brown distortion, `orig_size`;
/// see `Projection::Matrix`), given dL/d(screen point).
fn matrix_projection_grad(
    m: &[[f64; 4]; 3],
    dist: &[f64; 5],
    orig_size: f64,
    p: DVec3,
    g: [f64; 3],
) -> [f64; 3] {
    let row = |r: &[f64; 4]| r[0] * p.x + r[1] * p.y + r[2] * p.z + r[3];
    let (x, y, z) = (row(&m[0]), row(&m[1]), row(&m[2]));
    let zs = z + 1e-5;
    let (x1, y1) = (x / zs, y / zs);
    let [k1, k2, p1, p2, k3] = *dist;
    let r2 = x1 * x1 + y1 * y1;
    let radial = 1.0 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
    let d_radial = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r2 * r2;
    let half = orig_size / 2.0;
    let (g_x2, g_y2) = (g[0] / half, g[1] / half);
    let dx2_dx1 = radial + 2.0 * x1 * x1 * d_radial + 2.0 * p1 * y1 + 6.0 * p2 * x1;
    let dx2_dy1 = 2.0 * x1 * y1 * d_radial + 2.0 * p1 * x1 + 2.0 * p2 * y1;
    let dy2_dx1 = 2.0 * x1 * y1 * d_radial + 2.0 * p1 * x1 + 2.0 * p2 * y1;
    let dy2_dy1 = radial + 2.0 * y1 * y1 * d_radial + 6.0 * p1 * y1 + 2.0 * p2 * x1;
    let g_x1 = g_x2 * dx2_dx1 + g_y2 * dy2_dx1;
    let g_y1 = g_x2 * dx2_dy1 + g_y2 * dy2_dy1;
    let g_row = [g_x1 / zs, g_y1 / zs, g[2] - (g_x1 * x1 + g_y1 * y1) / zs];
    std::array::from_fn(|c| g_row[0] * m[0][c] + g_row[1] * m[1][c] + g_row[2] * m[2][c])
}

/// The adjoint of `v / max(|v|, eps)`.
fn normalize_eps_grad(v: DVec3, eps: f64, g: DVec3) -> DVec3 {
    let len = v.length();
    if len > eps {
        let n = v / len;
        (g - n * n.dot(g)) / len
    } else {
        g / eps
    }
}

/// dL/d(eye, at, up) of `R = look_at(eye, at, up)` given dL/dR (rows x, y, z), through
/// `z = N(at − eye)`, `x = N(up × z)`, `y = N(z × x)`, `N` SoftRas's eps-normalization.
pub fn look_at_grad(eye: DVec3, at: DVec3, up: DVec3, d_rotation: [[f64; 3]; 3]) -> CameraGrad {
    let vz = at - eye;
    let z = vz / vz.length().max(LOOK_AT_EPS);
    let vx = up.cross(z);
    let x = vx / vx.length().max(LOOK_AT_EPS);
    let vy = z.cross(x);
    let [mut g_x, g_y, mut g_z] = d_rotation.map(DVec3::from);
    let g_vy = normalize_eps_grad(vy, LOOK_AT_EPS, g_y);
    g_z += x.cross(g_vy);
    g_x += g_vy.cross(z);
    let g_vx = normalize_eps_grad(vx, LOOK_AT_EPS, g_x);
    let g_up = z.cross(g_vx);
    g_z += g_vx.cross(up);
    let g_vz = normalize_eps_grad(vz, LOOK_AT_EPS, g_z);
    CameraGrad {
        eye: (-g_vz).to_array(),
        at: g_vz.to_array(),
        up: g_up.to_array(),
    }
}

/// A view's camera gradient from its faces' summed [`FaceWorldGrad`]s: `d_rotation`
/// (Σ rotation) and `d_world_sum` (Σ corners; `p − eye` makes the eye's direct share its
/// negative). Zero for a matrix projection.
pub fn camera_grad(
    camera: &Camera,
    d_rotation: [[f64; 3]; 3],
    d_world_sum: [f64; 3],
) -> CameraGrad {
    if matches!(camera.projection, Projection::Matrix { .. }) {
        return CameraGrad::default();
    }
    let mut g = look_at_grad(camera.eye, camera.at, camera.up, d_rotation);
    for (e, d) in g.eye.iter_mut().zip(d_world_sum) {
        *e -= d;
    }
    g
}

// ---------------------------------------------------------------------------------------------
// Step 3: per vertex, and lighting.

/// The (face, corner) slots incident to each vertex, in face order (CSR): the fixed order in
/// which per-corner gradients are summed per vertex.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VertexFaces {
    /// `offsets[v]..offsets[v + 1]` index `slots` for vertex v.
    pub offsets: Vec<u32>,
    /// Slot `3 f + c`: corner c of face f.
    pub slots: Vec<u32>,
}

impl VertexFaces {
    /// Counts, scans, scatters.
    pub fn new(faces: &[[u32; 3]], vertex_count: usize) -> VertexFaces {
        let mut offsets = vec![0u32; vertex_count + 1];
        for f in faces {
            for &v in f {
                offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            offsets[v + 1] += offsets[v];
        }
        let mut next = offsets.clone();
        let mut slots = vec![0u32; 3 * faces.len()];
        for (fi, f) in faces.iter().enumerate() {
            for (c, &v) in f.iter().enumerate() {
                slots[next[v as usize] as usize] = (3 * fi + c) as u32;
                next[v as usize] += 1;
            }
        }
        VertexFaces { offsets, slots }
    }

    /// Per vertex, the sum of its slots of `per_corner` (`3 F` values).
    pub fn gather(&self, per_corner: &[[f64; 3]]) -> Vec<[f64; 3]> {
        (0..self.offsets.len() - 1)
            .map(|v| {
                let mut acc = [0.0; 3];
                for &slot in &self.slots[self.offsets[v] as usize..self.offsets[v + 1] as usize] {
                    add3(&mut acc, per_corner[slot as usize]);
                }
                acc
            })
            .collect()
    }
}

/// dL/d(unit normal) from dL/d(light factor L) of `L = I_a c_a + Σ_l I_l c_l max(0, n · d_l)`.
pub fn light_grad(lighting: &Lighting, normal: DVec3, d_light: [f64; 3]) -> DVec3 {
    let mut g = DVec3::ZERO;
    for l in &lighting.directionals {
        let dir = DVec3::from(l.direction);
        if normal.dot(dir) > 0.0 {
            g += dir * (l.intensity * dot3(l.color, d_light));
        }
    }
    g
}

/// dL/d(corners) of the raw face normal `cross(v2 − v1, v0 − v1)` given dL/d(it).
fn face_normal_raw_grad(positions: &[DVec3], face: [u32; 3], g: DVec3) -> [[f64; 3]; 3] {
    let [p0, p1, p2] = face.map(|i| positions[i as usize]);
    let (a, b) = (p2 - p1, p0 - p1);
    let (g_a, g_b) = (b.cross(g), g.cross(a));
    [g_b.to_array(), (-g_a - g_b).to_array(), g_a.to_array()]
}

/// Surface-mode lighting backward, per face: from dL/d(lit texels) (`F·R²`) to dL/d(raw
/// texels) and, through the face normal, dL/d(world position) per (face, corner) slot.
pub fn lighting_grad_surface(
    lighting: &Lighting,
    positions: &[DVec3],
    faces: &[[u32; 3]],
    texture_res: u32,
    textures: &[[f64; 3]],
    d_lit: &[[f64; 3]],
) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let r2 = (texture_res * texture_res) as usize;
    let mut d_textures = vec![[0.0; 3]; textures.len()];
    let mut corners = vec![[0.0; 3]; 3 * faces.len()];
    for (f, &face) in faces.iter().enumerate() {
        let raw = face_normal_raw(positions, face);
        let n = raw / raw.length().max(NORMAL_EPS);
        let light = lighting.light(n);
        let mut d_light = [0.0; 3];
        for t in f * r2..(f + 1) * r2 {
            for k in 0..3 {
                d_textures[t][k] = d_lit[t][k] * light[k];
                d_light[k] += d_lit[t][k] * textures[t][k];
            }
        }
        let d_raw = normalize_eps_grad(raw, NORMAL_EPS, light_grad(lighting, n, d_light));
        corners[3 * f..3 * f + 3].copy_from_slice(&face_normal_raw_grad(positions, face, d_raw));
    }
    (d_textures, corners)
}

/// Vertex-mode lighting backward: per vertex, from dL/d(lit colour) to dL/d(raw colour) and
/// dL/d(vertex normal sum); then per face, the sum's share of each incident face's raw normal
/// to dL/d(world position) per (face, corner) slot.
pub fn lighting_grad_vertex(
    lighting: &Lighting,
    positions: &[DVec3],
    faces: &[[u32; 3]],
    vertex_colors: Option<&[[f64; 3]]>,
    d_lit: &[[f64; 3]],
) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let sums = vertex_normal_sums(positions, faces);
    let mut d_colors = vec![[0.0; 3]; positions.len()];
    let mut d_sums = vec![DVec3::ZERO; positions.len()];
    for (v, &sum) in sums.iter().enumerate() {
        let n = sum / sum.length().max(NORMAL_EPS);
        let light = lighting.light(n);
        let c = vertex_colors.map_or([1.0; 3], |cs| cs[v]);
        let mut d_light = [0.0; 3];
        for k in 0..3 {
            d_colors[v][k] = d_lit[v][k] * light[k];
            d_light[k] = d_lit[v][k] * c[k];
        }
        d_sums[v] = normalize_eps_grad(sum, NORMAL_EPS, light_grad(lighting, n, d_light));
    }
    let mut corners = vec![[0.0; 3]; 3 * faces.len()];
    for (f, &face) in faces.iter().enumerate() {
        let d_raw = face.iter().map(|&v| d_sums[v as usize]).sum::<DVec3>();
        corners[3 * f..3 * f + 3].copy_from_slice(&face_normal_raw_grad(positions, face, d_raw));
    }
    (d_colors, corners)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lighting::{Directional, face_normals_of, vertex_normals_of};
    use crate::raster::reference::{downsample_2x2, render_f64};
    use glam::{DQuat, EulerRot};
    use rand::{RngExt, SeedableRng};
    use rand_pcg::Pcg64;

    fn rng(seed: u64) -> Pcg64 {
        Pcg64::seed_from_u64(seed)
    }

    /// A view as the tests parametrize it: a camera, or [`Camera::from_angles`]'s parameters.
    #[derive(Clone, Copy, Debug)]
    enum View {
        Camera(Camera),
        Angles {
            distance: f64,
            elevation: f64,
            azimuth: f64,
            projection: Projection,
        },
    }

    impl View {
        fn camera(&self) -> Camera {
            match *self {
                View::Camera(c) => c,
                View::Angles {
                    distance,
                    elevation,
                    azimuth,
                    projection,
                } => Camera {
                    projection,
                    ..Camera::from_angles(distance, elevation, azimuth)
                },
            }
        }
    }

    /// One finite-difference check: scene, views, lights, settings and the random dL/dImage.
    struct Case {
        mesh: MeshF64,
        views: Vec<View>,
        lighting: Lighting,
        settings: RasterSettings,
        weights: Vec<[f64; 4]>,
    }

    impl Case {
        fn new(
            mesh: MeshF64,
            views: Vec<View>,
            lighting: Lighting,
            settings: RasterSettings,
        ) -> Case {
            let mut r = rng(0x5eed);
            let n = views.len() * (settings.width * settings.height) as usize;
            let weights = (0..n)
                .map(|_| std::array::from_fn(|_| r.random_range(-1.0..1.0)))
                .collect();
            Case {
                mesh,
                views,
                lighting,
                settings,
                weights,
            }
        }

        fn cameras(&self) -> Vec<Camera> {
            self.views.iter().map(View::camera).collect()
        }
    }

    /// Two directional lights from off-axis directions (so no face normal of the test scenes
    /// sits on a light's `max(0, ·)` kink by symmetry), coloured.
    fn lights() -> Lighting {
        Lighting {
            ambient_intensity: 0.4,
            ambient_color: [1.0, 0.9, 0.8],
            directionals: vec![
                Directional {
                    intensity: 0.6,
                    color: [1.0, 1.0, 0.9],
                    direction: [0.3, 0.5, -0.8],
                },
                Directional {
                    intensity: 0.3,
                    color: [0.5, 0.7, 1.0],
                    direction: [-0.7, -0.2, -0.6],
                },
            ],
        }
    }

    /// Three triangles overlapping at depths 0.3, 0 and −0.3 (the middle one wound to face away
    /// from a camera on −z), optionally with a small randomly rotated icosphere among them;
    /// everything jittered by `seed`; random texels at resolution `res` and vertex colours.
    fn scene(seed: u64, icosphere: bool, res: u32) -> MeshF64 {
        let mut r = rng(seed);
        let triangles = [
            [[-0.9, -0.6, 0.3], [-0.1, 0.7, 0.3], [0.5, -0.5, 0.3]],
            [[-0.4, -0.2, 0.0], [0.7, -0.4, 0.0], [0.2, 0.6, 0.0]],
            [[-0.7, 0.1, -0.3], [-0.2, 0.8, -0.3], [0.3, 0.0, -0.3]],
        ];
        let mut positions = Vec::new();
        let mut faces = Vec::new();
        for t in triangles {
            for p in t {
                let j: [f64; 3] = std::array::from_fn(|_| r.random_range(-0.06..0.06));
                positions.push(DVec3::from(p) + DVec3::from(j));
            }
            let n = positions.len() as u32;
            faces.push([n - 3, n - 2, n - 1]);
        }
        if icosphere {
            let ico = Mesh::icosphere(0);
            let q = DQuat::from_euler(
                EulerRot::XYZ,
                r.random_range(0.0..6.0),
                r.random_range(0.0..6.0),
                r.random_range(0.0..6.0),
            );
            let centre = DVec3::new(0.35, 0.3, -0.1);
            let base = positions.len() as u32;
            for p in &ico.positions {
                positions.push(centre + q * DVec3::from(p.map(f64::from)) * 0.3);
            }
            faces.extend(ico.faces.iter().map(|f| f.map(|i| i + base)));
        }
        let texels = faces.len() * (res * res) as usize;
        let mut color = || std::array::from_fn(|_| r.random_range(0.2..1.0));
        let textures = (0..texels).map(|_| color()).collect();
        let vertex_colors = Some((0..positions.len()).map(|_| color()).collect());
        MeshF64 {
            positions,
            faces,
            texture_res: res,
            textures,
            vertex_colors,
        }
    }

    fn settings(width: u32, height: u32) -> RasterSettings {
        RasterSettings {
            width,
            height,
            sigma: 2e-2,
            gamma: 3e-2,
            ..RasterSettings::default()
        }
    }

    /// A parameter of the loss that finite differences perturb.
    #[derive(Clone, Copy, Debug, PartialEq)]
    enum Param {
        Position(usize, usize),
        Color(usize, usize),
        Eye(usize, usize),
        At(usize, usize),
        Up(usize, usize),
        Angle(usize, usize),
    }

    impl Param {
        fn group(&self) -> &'static str {
            match self {
                Param::Position(..) => "positions",
                Param::Color(..) => "colors",
                Param::Eye(..) => "eye",
                Param::At(..) => "at",
                Param::Up(..) => "up",
                Param::Angle(..) => "angles",
            }
        }

        /// Whether it moves geometry (colours move no kink).
        fn geometric(&self) -> bool {
            !matches!(self, Param::Color(..))
        }
    }

    fn params(case: &Case) -> Vec<Param> {
        let mut out = Vec::new();
        for i in 0..case.mesh.positions.len() {
            out.extend((0..3).map(|k| Param::Position(i, k)));
        }
        let colors = match case.settings.color_mode {
            ColorMode::Surface => case.mesh.textures.len(),
            ColorMode::Vertex => case.mesh.positions.len(),
        };
        for i in 0..colors {
            out.extend((0..3).map(|k| Param::Color(i, k)));
        }
        for (v, view) in case.views.iter().enumerate() {
            if matches!(view.camera().projection, Projection::Matrix { .. }) {
                continue;
            }
            for k in 0..3 {
                out.extend([Param::Eye(v, k), Param::At(v, k), Param::Up(v, k)]);
            }
            if matches!(view, View::Angles { .. }) {
                out.extend((0..3).map(|k| Param::Angle(v, k)));
            }
        }
        out
    }

    /// The case with one parameter moved by `delta`: its mesh and cameras.
    fn perturbed(case: &Case, p: Param, delta: f64) -> (MeshF64, Vec<Camera>) {
        let mut mesh = case.mesh.clone();
        let mut views = case.views.clone();
        match p {
            Param::Position(i, k) => mesh.positions[i][k] += delta,
            Param::Color(i, k) => match case.settings.color_mode {
                ColorMode::Surface => mesh.textures[i][k] += delta,
                ColorMode::Vertex => mesh.vertex_colors.as_mut().unwrap()[i][k] += delta,
            },
            Param::Angle(v, k) => {
                if let View::Angles {
                    distance,
                    elevation,
                    azimuth,
                    ..
                } = &mut views[v]
                {
                    *[distance, elevation, azimuth][k] += delta;
                }
            }
            _ => {}
        }
        let mut cameras: Vec<Camera> = views.iter().map(View::camera).collect();
        match p {
            Param::Eye(v, k) => cameras[v].eye[k] += delta,
            Param::At(v, k) => cameras[v].at[k] += delta,
            Param::Up(v, k) => cameras[v].up[k] += delta,
            _ => {}
        }
        (mesh, cameras)
    }

    fn param_value(case: &Case, p: Param) -> f64 {
        let cams = case.cameras();
        match p {
            Param::Position(i, k) => case.mesh.positions[i][k],
            Param::Color(i, k) => match case.settings.color_mode {
                ColorMode::Surface => case.mesh.textures[i][k],
                ColorMode::Vertex => case.mesh.vertex_colors.as_ref().unwrap()[i][k],
            },
            Param::Eye(v, k) => cams[v].eye[k],
            Param::At(v, k) => cams[v].at[k],
            Param::Up(v, k) => cams[v].up[k],
            Param::Angle(v, k) => match case.views[v] {
                View::Angles {
                    distance,
                    elevation,
                    azimuth,
                    ..
                } => [distance, elevation, azimuth][k],
                View::Camera(_) => unreachable!(),
            },
        }
    }

    fn analytic(case: &Case, g: &Gradients, p: Param) -> f64 {
        match p {
            Param::Position(i, k) => g.positions[i][k],
            Param::Color(i, k) => g.colors[i][k],
            Param::Eye(v, k) => g.cameras[v].eye[k],
            Param::At(v, k) => g.cameras[v].at[k],
            Param::Up(v, k) => g.cameras[v].up[k],
            Param::Angle(v, k) => match case.views[v] {
                View::Angles {
                    distance,
                    elevation,
                    azimuth,
                    ..
                } => g.cameras[v].angles(distance, elevation, azimuth)[k],
                View::Camera(_) => unreachable!(),
            },
        }
    }

    fn images(case: &Case, mesh: &MeshF64, cameras: &[Camera]) -> Vec<[f64; 4]> {
        cameras
            .iter()
            .flat_map(|c| render_f64(mesh, c, &case.lighting, &case.settings).unwrap())
            .collect()
    }

    /// Every discrete decision the forward takes, for the kink guard: per (rendered pixel,
    /// face) whether the face is ignored, each barycentric's side of 0 and 1 (clip, inside
    /// sign, hard tests), the clip floor, the near/far and facing tests, the nearest edge, the
    /// smallest barycentric, the texel, the determinant clamp; per pixel the hard winner and
    /// the count of coverages that round to 1; per normal and light the side of `max(0, ·)`.
    /// Equal signatures at `p − h`, `p` and `p + h` mean the central difference crosses no kink.
    fn signature(case: &Case, mesh: &MeshF64, cameras: &[Camera]) -> Vec<u64> {
        let s = &case.settings;
        let mut sig = Vec::new();
        let normals = match s.color_mode {
            ColorMode::Surface => face_normals_of(&mesh.positions, &mesh.faces),
            ColorMode::Vertex => vertex_normals_of(&mesh.positions, &mesh.faces),
        };
        for n in normals {
            for l in &case.lighting.directionals {
                sig.push(u64::from(n.dot(DVec3::from(l.direction)) > 0.0));
            }
        }
        let colors = FaceColors::of(mesh, &case.lighting, s.color_mode);
        let t = s.cutoff();
        for camera in cameras {
            let fwd = forward_view(mesh, camera, &colors, s);
            for row in 0..fwd.height {
                for col in 0..fwd.width {
                    let i = (row * fwd.width + col) as usize;
                    sig.push(u64::from(fwd.aux[i].hard_face));
                    sig.push(u64::from(fwd.aux[i].alpha_zeros));
                    let (xp, yp) = pixel_center(col, row, fwd.width, fwd.height);
                    for face in &fwd.faces {
                        sig.push(pair_code(face, (xp, yp), s, t, mesh.texture_res));
                    }
                }
            }
        }
        sig
    }

    fn pair_code(
        face: &FaceSetup,
        (xp, yp): (f64, f64),
        s: &RasterSettings,
        t: f64,
        texture_res: u32,
    ) -> u64 {
        if !face.finite {
            return 0;
        }
        let w = barycentric(face, xp, yp);
        if coverage(face, &w, xp, yp, s.dist, s.sigma, t).is_none() {
            return 1;
        }
        let mut code = 2u64;
        let mut push = |value: u64, radix: u64| code = code * radix + value;
        for x in w {
            push(
                if x < 0.0 {
                    0
                } else if x > 1.0 {
                    2
                } else {
                    1
                },
                3,
            );
        }
        let clamped = w.map(|x| x.clamp(0.0, 1.0));
        push(
            u64::from(clamped[0] + clamped[1] + clamped[2] < reference::CLIP_SUM_FLOOR),
            2,
        );
        let w_clip = clip_barycentric(w);
        let z = depth(face, &w_clip);
        push(u64::from(z >= s.near && z <= s.far), 2);
        push(u64::from(face.front), 2);
        // The nearest feature: a vertex (where two edges tie) or an edge's interior.
        let (_, a, b, t_edge) = nearest_edge(&face.v, [xp, yp]);
        push(
            if t_edge == 0.0 {
                a as u64
            } else if t_edge == 1.0 {
                b as u64
            } else {
                3 + a as u64
            },
            6,
        );
        push(argmin3(&w) as u64, 3);
        let det = reference::screen_det(&face.v);
        push(u64::from(reference::clamp_det(det) != det), 2);
        if s.color_mode == ColorMode::Surface {
            push(surface_texel_index(&w_clip, texture_res) as u64, 4096);
        }
        code
    }

    /// What one finite-difference comparison found for one group of parameters.
    #[derive(Debug, Default)]
    struct GroupReport {
        count: usize,
        significant: usize,
        max_fd: f64,
        worst_rel: f64,
        worst_small_abs: f64,
    }

    const FD_REL_STEP: f64 = 1e-6;
    const REL_TOL: f64 = 1e-5;
    const SIGNIFICANT: f64 = 1e-3;

    /// Central differences of every parameter against [`grad_f64`]; `Err` names a parameter
    /// whose step crosses a kink (the signature changed).
    fn fd_compare(case: &Case) -> Result<Vec<(&'static str, GroupReport)>, Param> {
        let cams = case.cameras();
        let s = &case.settings;
        let base_sig = signature(case, &case.mesh, &cams);
        let g = grad_f64(&case.mesh, &cams, &case.lighting, s, &case.weights).unwrap();
        let mut rows = Vec::new();
        for p in params(case) {
            let h = FD_REL_STEP * param_value(case, p).abs().max(1.0);
            let (mesh_p, cams_p) = perturbed(case, p, h);
            let (mesh_m, cams_m) = perturbed(case, p, -h);
            if p.geometric()
                && (signature(case, &mesh_p, &cams_p) != base_sig
                    || signature(case, &mesh_m, &cams_m) != base_sig)
            {
                return Err(p);
            }
            // Differences per pixel first: pixels the step does not touch add exactly 0.
            let plus = images(case, &mesh_p, &cams_p);
            let minus = images(case, &mesh_m, &cams_m);
            let mut diff = 0.0;
            for ((a, b), w) in plus.iter().zip(&minus).zip(&case.weights) {
                for k in 0..4 {
                    diff += w[k] * (a[k] - b[k]);
                }
            }
            rows.push((p, analytic(case, &g, p), diff / (2.0 * h)));
        }
        let mut groups: Vec<(&'static str, GroupReport)> = Vec::new();
        for &(p, _, fd) in &rows {
            match groups.iter_mut().find(|(n, _)| *n == p.group()) {
                Some((_, r)) => r.max_fd = r.max_fd.max(fd.abs()),
                None => groups.push((
                    p.group(),
                    GroupReport {
                        max_fd: fd.abs(),
                        ..GroupReport::default()
                    },
                )),
            }
        }
        for &(p, an, fd) in &rows {
            let r = &mut groups.iter_mut().find(|(n, _)| *n == p.group()).unwrap().1;
            r.count += 1;
            let err = (an - fd).abs();
            if fd.abs() >= SIGNIFICANT * r.max_fd {
                r.significant += 1;
                if err / fd.abs() > r.worst_rel {
                    r.worst_rel = err / fd.abs();
                }
                if err > REL_TOL * fd.abs() {
                    eprintln!("  {p:?}: analytic {an:.12e} fd {fd:.12e}");
                }
            } else {
                r.worst_small_abs = r.worst_small_abs.max(err / r.max_fd.max(f64::MIN_POSITIVE));
            }
        }
        Ok(groups)
    }

    /// Tries jitter seeds until one has no kink within a finite-difference step, then asserts
    /// the tolerance on every group.
    fn check_case(name: &str, build: impl Fn(u64) -> Case) {
        for seed in 0..8 {
            let case = build(seed);
            match fd_compare(&case) {
                Err(p) => eprintln!("{name}: seed {seed} crosses a kink at {p:?}, next seed"),
                Ok(groups) => {
                    for (group, r) in &groups {
                        eprintln!("{name} seed {seed} {group}: {r:?}");
                        assert!(r.significant > 0 && r.max_fd > 0.0, "{name} {group}: {r:?}");
                        assert!(r.worst_rel <= REL_TOL, "{name} {group}: {r:?}");
                        assert!(
                            r.worst_small_abs <= REL_TOL * SIGNIFICANT,
                            "{name} {group}: {r:?}"
                        );
                    }
                    return;
                }
            }
        }
        panic!("{name}: every seed crosses a kink");
    }

    #[test]
    fn fd_euclidean_prod_softmax_surface_r1_perspective_double_sided_with_angles() {
        check_case("euclid/prod/R1/persp", |seed| {
            Case::new(
                scene(seed, true, 1),
                vec![
                    View::Angles {
                        distance: 2.732,
                        elevation: 15.0,
                        azimuth: -20.0,
                        projection: Projection::default(),
                    },
                    View::Camera(Camera {
                        eye: DVec3::new(0.4, 0.5, -2.6),
                        at: DVec3::new(0.05, -0.02, 0.1),
                        up: DVec3::new(0.1, 1.0, 0.05),
                        projection: Projection::default(),
                    }),
                ],
                lights(),
                settings(12, 12),
            )
        });
    }

    fn ortho() -> Projection {
        Projection::Orthographic { scale: 0.6 }
    }

    #[test]
    fn fd_euclidean_sum_softmax_surface_r3_orthographic_single_sided() {
        check_case("euclid/sum/R3/ortho/single", |seed| {
            Case::new(
                scene(seed, false, 3),
                vec![
                    View::Camera(Camera {
                        projection: ortho(),
                        ..Camera::default()
                    }),
                    View::Camera(Camera {
                        eye: DVec3::new(-0.5, 0.3, -2.5),
                        at: DVec3::new(0.0, 0.1, 0.0),
                        up: DVec3::Y,
                        projection: ortho(),
                    }),
                ],
                lights(),
                RasterSettings {
                    sigma: 1e-2,
                    gamma: 5e-2,
                    alpha: Alpha::Sum,
                    double_sided: false,
                    near: 0.5,
                    far: 10.0,
                    background: [0.2, 0.3, 0.4],
                    ..settings(14, 12)
                },
            )
        });
    }

    #[test]
    fn fd_barycentric_prod_softmax_vertex_colors_perspective_antialiased() {
        check_case("bary/prod/vertex/persp/aa", |seed| {
            Case::new(
                scene(seed, true, 1),
                vec![View::Camera(Camera {
                    eye: DVec3::new(0.3, -0.4, -2.7),
                    ..Camera::default()
                })],
                lights(),
                RasterSettings {
                    dist: Dist::Barycentric,
                    gamma: 2e-2,
                    color_mode: ColorMode::Vertex,
                    antialias: true,
                    far: 10.0,
                    ..settings(8, 8)
                },
            )
        });
    }

    #[test]
    fn fd_barycentric_sum_softmax_surface_r2_orthographic_single_sided_with_angles() {
        check_case("bary/sum/R2/ortho/single", |seed| {
            Case::new(
                scene(seed, true, 2),
                vec![View::Angles {
                    distance: 3.0,
                    elevation: -10.0,
                    azimuth: 25.0,
                    projection: ortho(),
                }],
                lights(),
                RasterSettings {
                    dist: Dist::Barycentric,
                    alpha: Alpha::Sum,
                    sigma: 3e-2,
                    gamma: 1e-1,
                    double_sided: false,
                    ..settings(12, 12)
                },
            )
        });
    }

    /// The a.e. derivative of hard colour: the winner's colour through w̃ (vertex colours).
    #[test]
    fn fd_euclidean_prod_hard_rgb_vertex_colors_perspective() {
        check_case("euclid/prod/hard-rgb/vertex", |seed| {
            Case::new(
                scene(seed, true, 1),
                vec![View::Angles {
                    distance: 2.732,
                    elevation: 20.0,
                    azimuth: 10.0,
                    projection: Projection::default(),
                }],
                lights(),
                RasterSettings {
                    rgb: Rgb::Hard,
                    color_mode: ColorMode::Vertex,
                    ..settings(12, 12)
                },
            )
        });
    }

    /// Hard coverage, softmax colour: only depth and colour through w̃ move with the vertices
    /// (γ large enough for the depth to blend overlapping faces).
    #[test]
    fn fd_hard_dist_softmax_vertex_colors_single_sided() {
        check_case("hard-dist/softmax/vertex", |seed| {
            Case::new(
                scene(seed, true, 1),
                vec![View::Camera(Camera::default())],
                lights(),
                RasterSettings {
                    dist: Dist::Hard,
                    alpha: Alpha::Sum,
                    gamma: 1e-1,
                    far: 5.0,
                    color_mode: ColorMode::Vertex,
                    double_sided: false,
                    ..settings(12, 12)
                },
            )
        });
    }

    #[test]
    fn fd_euclidean_prod_softmax_matrix_projection_with_distortion() {
        // K [R | t] of the default camera, for a 64-pixel image, plus Brown distortion (SoftRas
        // applies it to pixel coordinates, r² ~ 10³, hence the small coefficients).
        let cam = Camera::default();
        let r = look_at(cam.eye, cam.at, cam.up).map(DVec3::from);
        let t = r.map(|row| -row.dot(cam.eye));
        let f = 32.0 / 30f64.to_radians().tan();
        let k = [[f, 0.0, 32.0], [0.0, f, 32.0], [0.0, 0.0, 1.0]];
        let p: [[f64; 4]; 3] = std::array::from_fn(|i| {
            let kr = (0..3).fold(DVec3::ZERO, |acc, j| acc + r[j] * k[i][j]);
            let kt: f64 = (0..3).map(|j| k[i][j] * t[j]).sum();
            [kr.x, kr.y, kr.z, kt]
        });
        check_case("euclid/prod/matrix", |seed| {
            Case::new(
                scene(seed, true, 1),
                vec![View::Camera(Camera {
                    projection: Projection::Matrix {
                        p,
                        dist_coeffs: [5e-5, -1e-9, 1e-4, -1e-4, 1e-12],
                        orig_size: 64.0,
                    },
                    ..cam
                })],
                lights(),
                settings(12, 12),
            )
        });
    }

    #[test]
    fn forward_view_is_the_forward_before_the_average() {
        let mesh = scene(3, true, 2);
        for antialias in [false, true] {
            let s = RasterSettings {
                antialias,
                ..settings(10, 7)
            };
            let cam = Camera::from_angles(2.732, 10.0, 30.0);
            let colors = FaceColors::of(&mesh, &lights(), s.color_mode);
            let fwd = forward_view(&mesh, &cam, &colors, &s);
            let img = if antialias {
                downsample_2x2(&fwd.image, s.width, s.height)
            } else {
                fwd.image.clone()
            };
            assert_eq!(img, render_f64(&mesh, &cam, &lights(), &s).unwrap());
        }
    }

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

    #[test]
    fn vertex_faces_lists_corners_in_face_order() {
        let adj = VertexFaces::new(&[[0, 1, 2], [2, 1, 3], [3, 0, 2]], 5);
        assert_eq!(adj.offsets, vec![0, 2, 4, 7, 9, 9]);
        assert_eq!(adj.slots, vec![0, 7, 1, 4, 2, 3, 8, 5, 6]);
        let per_corner: Vec<[f64; 3]> = (0..9).map(|i| [f64::from(i), 0.0, 1.0]).collect();
        let g = adj.gather(&per_corner);
        assert_eq!(g[2], [2.0 + 3.0 + 8.0, 0.0, 3.0]);
        assert_eq!(g[4], [0.0; 3]);
    }

    #[test]
    fn bad_gradient_inputs_are_errors() {
        let mesh = Mesh::icosphere(0);
        let s = settings(4, 4);
        let cams = [Camera::default()];
        let lit = Lighting::default();
        let err = grad(&mesh, &cams, &lit, &s, &[[0.0; 4]; 15]).unwrap_err();
        assert!(matches!(err, RenderError::Input(_)), "{err}");
        let err = grad(&mesh, &[], &lit, &s, &[]).unwrap_err();
        assert!(matches!(err, RenderError::Input(_)), "{err}");
        let mut d = [[0.0; 4]; 16];
        d[5][2] = f64::NAN;
        let err = grad(&mesh, &cams, &lit, &s, &d).unwrap_err();
        assert!(err.to_string().contains("pixel 5"), "{err}");
        let g = grad(&mesh, &cams, &lit, &s, &[[0.0; 4]; 16]).unwrap();
        assert_eq!(g.positions.len(), mesh.vertex_count());
        assert_eq!(g.colors.len(), mesh.textures.len());
        assert!(g.positions.iter().flatten().all(|&x| x == 0.0));
    }

    fn hard_silhouette(mesh: &MeshF64, cam: &Camera, size: u32) -> Vec<bool> {
        let s = RasterSettings {
            dist: Dist::Hard,
            alpha: Alpha::Hard,
            rgb: Rgb::Hard,
            ..settings(size, size)
        };
        render_f64(mesh, cam, &Lighting::unlit(), &s)
            .unwrap()
            .iter()
            .map(|p| p[3] > 0.5)
            .collect()
    }

    /// Gradient descent (Adam) on one triangle's vertices with the silhouette loss
    /// `Σ (A − A_target)²`, σ annealed from 1e-2 to 1e-3 at 32², reaches the target's hard
    /// silhouette.
    #[test]
    fn gradient_descent_fits_a_triangle_silhouette() {
        let triangle = |p: [[f64; 3]; 3]| MeshF64 {
            positions: p.map(DVec3::from).to_vec(),
            faces: vec![[0, 1, 2]],
            texture_res: 1,
            textures: vec![[1.0; 3]],
            vertex_colors: None,
        };
        let target = triangle([[-1.0, -0.8, 0.0], [0.1, 1.1, 0.0], [1.0, -0.6, 0.0]]);
        let mut mesh = triangle([[-0.4, -0.3, 0.2], [0.3, 0.5, 0.0], [0.6, -0.1, -0.2]]);
        let cam = Camera::default();
        let lit = Lighting::unlit();
        let size = 32;
        let iou = |mesh: &MeshF64| {
            let (a, b) = (
                hard_silhouette(mesh, &cam, size),
                hard_silhouette(&target, &cam, size),
            );
            let inter = a.iter().zip(&b).filter(|(x, y)| **x && **y).count();
            let union = a.iter().zip(&b).filter(|(x, y)| **x || **y).count();
            inter as f64 / union as f64
        };
        let start = iou(&mesh);
        let (b1, b2, eps) = (0.9, 0.999, 1e-8);
        let mut m = [[0.0; 3]; 3];
        let mut v = [[0.0; 3]; 3];
        let mut step = 0;
        for (sigma, iters, lr) in [(1e-2, 150, 2e-2), (3e-3, 150, 1e-2), (1e-3, 150, 3e-3)] {
            let s = RasterSettings {
                sigma,
                ..settings(size, size)
            };
            let goal = render_f64(&target, &cam, &lit, &s).unwrap();
            for _ in 0..iters {
                step += 1;
                let img = render_f64(&mesh, &cam, &lit, &s).unwrap();
                let d: Vec<[f64; 4]> = img
                    .iter()
                    .zip(&goal)
                    .map(|(p, q)| [0.0, 0.0, 0.0, 2.0 * (p[3] - q[3])])
                    .collect();
                let g = grad_f64(&mesh, &[cam], &lit, &s, &d).unwrap();
                for i in 0..3 {
                    for k in 0..3 {
                        let gk = g.positions[i][k];
                        m[i][k] = b1 * m[i][k] + (1.0 - b1) * gk;
                        v[i][k] = b2 * v[i][k] + (1.0 - b2) * gk * gk;
                        let mh = m[i][k] / (1.0 - b1.powi(step));
                        let vh = v[i][k] / (1.0 - b2.powi(step));
                        mesh.positions[i][k] -= lr * mh / (vh.sqrt() + eps);
                    }
                }
            }
        }
        let end = iou(&mesh);
        eprintln!("IoU {start:.4} -> {end:.4}");
        assert!(start < 0.5, "{start}");
        assert!(end > 0.99, "IoU {start} -> {end}");
    }
}
