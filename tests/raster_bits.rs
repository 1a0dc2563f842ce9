//! The bit twin (`raster::bits`): the forward's fine pass evaluated in f32 on the CPU, operation
//! for operation, equals the device's images and aux byte for byte, in every SoftRas mode. What
//! the device computes is then the IEEE evaluation of the written operations (softvk's own
//! `exp`, sigmoid and reciprocal included), which every conformant device must reproduce.

mod common;

use softvk::camera::Camera;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::bits::{FineInputs, FineTwin};
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};
use softvk::raster::setup::GpuView;

fn aux_bits(a: &softvk::raster::fine::PixelAux) -> [u32; 5] {
    [
        a.softmax_ref_depth.to_bits(),
        a.softmax_sum.to_bits(),
        a.alpha_acc.to_bits(),
        a.alpha_zeros,
        a.hard_face,
    ]
}

/// Renders `mesh` from `cams` with `s` (tiled, the renderer's default) and compares every output
/// pixel and every rendered pixel's aux with the twin's. Returns the pixels compared.
fn check(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    cams: &[Camera],
    s: &RasterSettings,
    silhouette: bool,
) -> usize {
    let mut scene = r.prepare(gpu, mesh, cams, &Lighting::default(), s).unwrap();
    scene.set_silhouette_only(silhouette);
    r.run(gpu, &mut scene, Method::default()).unwrap();
    let frames = scene.read_frames(gpu).unwrap();
    let setups = scene.read_setups(gpu).unwrap();
    let colors: Vec<[f32; 4]> = gpu
        .read_buffer(scene.colors(), 0, (scene.colors().size() / 16) as usize)
        .unwrap();
    let twin = FineTwin::new(
        FineInputs {
            setups: &setups,
            colors: &colors,
            faces: &mesh.faces,
            face_count: mesh.faces.len() as u32,
            vertex_count: mesh.positions.len() as u32,
            texture_res: mesh.texture_res,
        },
        s,
        silhouette,
        true,
    );
    let (out_n, rendered_n) = (
        frames.images.len() / cams.len(),
        frames.aux.len() / cams.len(),
    );
    let mut covered = 0;
    for v in 0..cams.len() {
        let (images, aux) = twin.view(v as u32);
        for (i, (got, want)) in frames.images[v * out_n..(v + 1) * out_n]
            .iter()
            .zip(&images)
            .enumerate()
        {
            assert!(
                got.map(f32::to_bits) == want.map(f32::to_bits),
                "{what}: view {v} pixel {i}: device {got:?}, twin {want:?}"
            );
            covered += usize::from(got[3] > 0.0);
        }
        for (i, (got, want)) in frames.aux[v * rendered_n..(v + 1) * rendered_n]
            .iter()
            .zip(&aux)
            .enumerate()
        {
            assert_eq!(aux_bits(got), aux_bits(want), "{what}: view {v} aux {i}");
        }
    }
    // The scenes must show the mesh, or the comparison proves little.
    assert!(
        covered > out_n / 10,
        "{what}: only {covered} covered pixels"
    );
    covered
}

#[test]
fn the_fine_pass_equals_its_bit_twin_in_every_mode() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mut textured = Mesh::icosphere(2);
    textured.texture_res = 2;
    let texels = textured.faces.len() * 4;
    textured.textures = (0..texels)
        .map(|i| {
            [
                (i % 7) as f32 / 7.0,
                (i % 5) as f32 / 5.0,
                (i % 3) as f32 / 3.0,
            ]
        })
        .collect();
    let mut colored = Mesh::icosphere(2);
    colored.vertex_colors = Some(
        (0..colored.positions.len())
            .map(|i| [(i % 3) as f32 / 2.0, (i % 4) as f32 / 3.0, 0.5])
            .collect(),
    );
    let cams = [
        Camera::from_angles(2.732, 30.0, -45.0),
        Camera::from_angles(2.2, -10.0, 120.0),
    ];
    let mut compared = 0;
    for dist in [Dist::Euclidean, Dist::Barycentric, Dist::Hard] {
        for rgb in [Rgb::Softmax, Rgb::Hard] {
            for alpha in [Alpha::Prod, Alpha::Sum, Alpha::Hard] {
                for (mode, mesh) in [
                    (ColorMode::Surface, &textured),
                    (ColorMode::Vertex, &colored),
                ] {
                    let s = RasterSettings {
                        width: 24,
                        height: 20,
                        sigma: 3e-3,
                        gamma: 1e-3,
                        dist,
                        rgb,
                        alpha,
                        color_mode: mode,
                        double_sided: false,
                        background: [0.2, 0.3, 0.4],
                        ..RasterSettings::default()
                    };
                    let what = format!("{dist:?} {rgb:?} {alpha:?} {mode:?}");
                    compared += check(&r, &gpu, &what, mesh, &cams, &s, false);
                }
            }
        }
    }
    // Double-sided, anti-aliased, SoftRas's own σ and γ, and silhouettes.
    let s = RasterSettings {
        width: 16,
        height: 16,
        double_sided: true,
        antialias: true,
        ..RasterSettings::default()
    };
    compared += check(
        &r,
        &gpu,
        "double-sided, anti-aliased",
        &textured,
        &cams,
        &s,
        false,
    );
    let s = RasterSettings {
        width: 24,
        height: 24,
        sigma: 1e-4,
        ..RasterSettings::default()
    };
    compared += check(&r, &gpu, "silhouette", &colored, &cams, &s, true);
    assert!(compared > 5_000, "{compared} covered pixels compared");
}

/// The brute-force backward against the twin's, byte for byte: every vertex's position gradient
/// and every colour gradient (the per-pixel chain, the sums in the brute force's row-major order,
/// the view transform and the gather), for an upstream gradient on every output pixel. Unlit, so the
/// host's f64 lighting share is exactly zero and the device's f32 results come through as they
/// are. Returns the nonzero position components compared.
fn check_backward(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    cams: &[Camera],
    s: &RasterSettings,
    silhouette: bool,
) -> usize {
    let mut scene = r.prepare(gpu, mesh, cams, &Lighting::unlit(), s).unwrap();
    scene.set_silhouette_only(silhouette);
    let run = r.run(gpu, &mut scene, Method::Brute).unwrap();
    let n = (s.width * s.height) as usize * cams.len();
    let d_image: Vec<[f32; 4]> = (0..n)
        .map(|i| {
            let h = |k: usize| (((i * 7 + k * 13) % 23) as f32 - 11.0) / 16.0;
            if silhouette {
                [0.0, 0.0, 0.0, h(3)]
            } else {
                [h(0), h(1), h(2), h(3)]
            }
        })
        .collect();
    let grads = r.backward(gpu, &run.binned(), &d_image, false).unwrap();
    let setups = scene.read_setups(gpu).unwrap();
    let colors: Vec<[f32; 4]> = gpu
        .read_buffer(scene.colors(), 0, (scene.colors().size() / 16) as usize)
        .unwrap();
    let twin = FineTwin::new(
        FineInputs {
            setups: &setups,
            colors: &colors,
            faces: &mesh.faces,
            face_count: mesh.faces.len() as u32,
            vertex_count: mesh.positions.len() as u32,
            texture_res: mesh.texture_res,
        },
        s,
        silhouette,
        false,
    );
    let views: Vec<GpuView> = cams.iter().map(|c| GpuView::new(c).unwrap()).collect();
    let rendered: Vec<_> = (0..cams.len()).map(|v| twin.rendered(v as u32)).collect();
    let rows = if s.antialias { 2 * s.height } else { s.height };
    let want = twin.backward(&views, &mesh.positions, &d_image, &rendered, rows);
    let mut nonzero = 0;
    for (i, (got, want)) in grads.positions.iter().zip(&want.positions).enumerate() {
        let got = got.map(|x| x as f32);
        assert!(
            got.map(f32::to_bits) == want.map(f32::to_bits),
            "{what}: vertex {i}: device {got:?}, twin {want:?}"
        );
        nonzero += got.iter().filter(|x| **x != 0.0).count();
    }
    assert_eq!(
        grads.colors.len(),
        want.colors.len(),
        "{what}: colour slots"
    );
    for (i, (got, want)) in grads.colors.iter().zip(&want.colors).enumerate() {
        let got = got.map(|x| x as f32);
        assert!(
            got.map(f32::to_bits) == want.map(f32::to_bits),
            "{what}: colour {i}: device {got:?}, twin {want:?}"
        );
        nonzero += got.iter().filter(|x| **x != 0.0).count();
    }
    // Every mode has gradients (hard coverage, colour and alpha leave the colours' at least).
    assert!(
        nonzero > mesh.positions.len() / 2,
        "{what}: only {nonzero} nonzero gradient components"
    );
    nonzero
}

#[test]
fn the_backward_equals_its_bit_twin_in_every_differentiable_mode() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mut textured = Mesh::icosphere(1);
    textured.texture_res = 2;
    textured.textures = (0..textured.faces.len() * 4)
        .map(|i| {
            [
                (i % 7) as f32 / 7.0,
                (i % 5) as f32 / 5.0,
                (i % 3) as f32 / 3.0,
            ]
        })
        .collect();
    let mut colored = Mesh::icosphere(1);
    colored.vertex_colors = Some(
        (0..colored.positions.len())
            .map(|i| [(i % 3) as f32 / 2.0, (i % 4) as f32 / 3.0, 0.5])
            .collect(),
    );
    let cams = [
        Camera::from_angles(2.732, 30.0, -45.0),
        Camera::from_angles(2.2, -10.0, 120.0),
    ];
    let mut compared = 0;
    for dist in [Dist::Euclidean, Dist::Barycentric, Dist::Hard] {
        for rgb in [Rgb::Softmax, Rgb::Hard] {
            for alpha in [Alpha::Prod, Alpha::Sum, Alpha::Hard] {
                for (mode, mesh) in [
                    (ColorMode::Surface, &textured),
                    (ColorMode::Vertex, &colored),
                ] {
                    let s = RasterSettings {
                        width: 16,
                        height: 14,
                        sigma: 3e-3,
                        gamma: 1e-2,
                        dist,
                        rgb,
                        alpha,
                        color_mode: mode,
                        double_sided: false,
                        background: [0.2, 0.3, 0.4],
                        ..RasterSettings::default()
                    };
                    let what = format!("{dist:?} {rgb:?} {alpha:?} {mode:?}");
                    compared += check_backward(&r, &gpu, &what, mesh, &cams, &s, false);
                }
            }
        }
    }
    let s = RasterSettings {
        width: 12,
        height: 12,
        sigma: 1e-3,
        antialias: true,
        ..RasterSettings::default()
    };
    compared += check_backward(&r, &gpu, "anti-aliased", &textured, &cams, &s, false);
    let s = RasterSettings {
        width: 16,
        height: 16,
        sigma: 1e-3,
        ..RasterSettings::default()
    };
    compared += check_backward(&r, &gpu, "silhouette", &colored, &cams, &s, true);
    assert!(
        compared > 5_000,
        "{compared} nonzero gradient components compared"
    );
}
