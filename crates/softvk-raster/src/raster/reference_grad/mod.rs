//! The f64 backward pass (SPEC §3): the exact derivative of
//! [`reference`](mod@crate::raster::reference)'s forward, the oracle a GPU backward is diffed
//! against.
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
//! Sources of the formulas: the forward's own definitions (SPEC §1–§2, `reference`,
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
//!
//! # Layout
//!
//! This file holds the entry points ([`grad`], [`grad_f64`]) and step 1, the forward with aux;
//! the other steps have their own files: `pixel` (step 2), `view` (step 3) and `vertex` (step 4,
//! with lighting).
//!
//! [`reference::render_f64`]: crate::raster::reference::render_f64

mod pixel;
mod vertex;
mod view;

#[cfg(test)]
mod finite_differences;

use glam::DVec3;

pub use pixel::{ColorSampleGrad, PixelFaceGrad, PixelUpstream, pixel_face_grad};
pub use vertex::{VertexFaces, light_grad, lighting_grad_surface, lighting_grad_vertex};
pub use view::{
    FaceScreenGrads, FaceWorldGrad, backward_view, camera_grad, face_screen_to_world_grad,
    look_at_grad,
};

use crate::camera::{Camera, look_at, pixel_center};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::reference::{
    FaceColors, FaceSetup, MeshF64, PixelAux, setup_view, shade_pixel_aux,
};
use crate::raster::settings::{ColorMode, RasterSettings, RenderError};

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

/// Colour parameters per face: R² texels (surface) or 3 corner colours (vertex).
pub fn color_slots(mode: ColorMode, texture_res: u32) -> usize {
    match mode {
        ColorMode::Surface => (texture_res * texture_res) as usize,
        ColorMode::Vertex => 3,
    }
}

// ---------------------------------------------------------------------------------------------
// Step 1: the forward with aux.

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
///
/// [`reference::render_f64`]: crate::raster::reference::render_f64
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
///
/// [`reference::downsample_2x2`]: crate::raster::reference::downsample_2x2
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

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use rand::{RngExt, SeedableRng};
    use rand_pcg::Pcg64;

    use super::*;
    use crate::lighting::Directional;
    use crate::raster::reference::{downsample_2x2, render_f64};
    use crate::raster::settings::{Alpha, Dist, Rgb};
    use glam::{DQuat, EulerRot};

    pub(super) fn rng(seed: u64) -> Pcg64 {
        Pcg64::seed_from_u64(seed)
    }

    /// Two directional lights from off-axis directions (so no face normal of the test scenes
    /// sits on a light's `max(0, ·)` kink by symmetry), coloured.
    pub(super) fn lights() -> Lighting {
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
    pub(super) fn scene(seed: u64, icosphere: bool, res: u32) -> MeshF64 {
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

    pub(super) fn settings(width: u32, height: u32) -> RasterSettings {
        RasterSettings {
            width,
            height,
            sigma: 2e-2,
            gamma: 3e-2,
            ..RasterSettings::default()
        }
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
