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
