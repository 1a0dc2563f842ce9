//! The f64 forward soft rasterizer (SPEC §2): the oracle the GPU kernels are diffed against.
//!
//! It is written the way the GLSL will be, so a shader can follow it loop for loop:
//! - a *setup* pass per face ([`setup_face`], SoftRas's `forward_soft_rasterize_inv` kernel):
//!   screen vertices, inverse barycentric matrix, facing, grown bounding box;
//! - a *fine* pass per pixel ([`shade_pixel`]): one loop over faces with running accumulators
//!   for alpha ([`AlphaAccum`]), softmax colour ([`SoftmaxAccum`]) and hard colour
//!   ([`HardAccum`]), each step a small function: [`barycentric`], [`coverage()`],
//!   [`clip_barycentric`], [`depth`], [`FaceColors::sample`].
//!
//! Where the SPEC differs from SoftRas (non-square pixel centres, euclidean distance to the edges
//! as segments, the clip floor, the softmax background weight `e^{ε/γ}`, no √T cull for the
//! barycentric distance), the SPEC is followed; see each function.
//!
//! Each stage has its own file: `setup` (per face), `coverage` (one face at one pixel), `color`
//! (lit colours and the texel rule) and `fine` (per pixel: the face loop and its aggregates);
//! this file holds the f64 mesh and the drivers that render a whole image.

mod color;
mod coverage;
mod fine;
mod setup;

use glam::DVec3;

pub use color::{FaceColors, TEXEL_TIE_ULPS, surface_texel_index};
pub use coverage::{
    CLIP_SUM_FLOOR, barycentric, clip_barycentric, coverage, depth, dist2_point_segment,
    euclidean_dist2, inside_closed,
};
pub use fine::{
    AlphaAccum, HardAccum, NO_FACE, PixelAux, SoftmaxAccum, shade_pixel, shade_pixel_aux,
};
pub use setup::{
    FaceSetup, MIN_DET, face_screen_bbox_grown, is_front_facing, is_numerically_degenerate,
    outside_bbox, project_faces, project_faces_of, setup_face,
};
pub(crate) use setup::{clamp_det, screen_det};

use crate::camera::{Camera, pixel_center};
use crate::lighting::{Lighting, positions_f64};
use crate::mesh::{Mesh, MeshError, validate_parts};
use crate::raster::settings::{RasterSettings, RenderError};

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
    use crate::raster::settings::{Alpha, ColorMode, Dist, Rgb};

    /// Small deterministic generator (xorshift64*), so tests need no extra crate.
    pub(super) struct Rng(pub(super) u64);

    impl Rng {
        pub(super) fn next_f64(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }

        pub(super) fn range(&mut self, lo: f64, hi: f64) -> f64 {
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
        let mesh = Mesh::load_obj(
            &softvk_testing::assets_dir().join("spot_triangulated.obj"),
            1,
        )
        .unwrap();
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
