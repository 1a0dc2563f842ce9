//! The bit twins (`raster::bits`): the forward's fine pass and the backward evaluated in f32 on
//! the CPU, operation for operation, equal the device's images, aux and gradients byte for byte,
//! in every SoftRas mode. What the device computes is then the IEEE evaluation of the written
//! operations (softvk's own `exp`, sigmoid and reciprocal included), which every conformant
//! device must reproduce.

mod common;

use softvk::camera::Camera;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::bits::{FineInputs, FineTwin};
use softvk::raster::fine::PixelAux;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::scene::GpuScene;
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};
use softvk::raster::setup::{GpuFaceSetup, GpuView};

fn aux_bits(a: &PixelAux) -> [u32; 5] {
    [
        a.softmax_ref_depth.to_bits(),
        a.softmax_sum.to_bits(),
        a.alpha_acc.to_bits(),
        a.alpha_zeros,
        a.hard_face,
    ]
}

/// An icosphere with 2 × 2 texels a face, and one with vertex colours, both in varied colours.
fn meshes(subdivisions: u32) -> (Mesh, Mesh) {
    let mut textured = Mesh::icosphere(subdivisions);
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
    let mut colored = Mesh::icosphere(subdivisions);
    colored.vertex_colors = Some(
        (0..colored.positions.len())
            .map(|i| [(i % 3) as f32 / 2.0, (i % 4) as f32 / 3.0, 0.5])
            .collect(),
    );
    (textured, colored)
}

fn cameras() -> [Camera; 2] {
    [
        Camera::from_angles(2.732, 30.0, -45.0),
        Camera::from_angles(2.2, -10.0, 120.0),
    ]
}

/// Every SoftRas mode (distance × colour × alpha × colour source) at `width × height`,
/// single-sided on a coloured background, with its mesh and a name.
fn every_mode<'a>(
    textured: &'a Mesh,
    colored: &'a Mesh,
    width: u32,
    height: u32,
    gamma: f64,
) -> Vec<(String, &'a Mesh, RasterSettings)> {
    let mut out = Vec::new();
    for dist in [Dist::Euclidean, Dist::Barycentric, Dist::Hard] {
        for rgb in [Rgb::Softmax, Rgb::Hard] {
            for alpha in [Alpha::Prod, Alpha::Sum, Alpha::Hard] {
                for (mode, mesh) in [(ColorMode::Surface, textured), (ColorMode::Vertex, colored)] {
                    let s = RasterSettings {
                        width,
                        height,
                        sigma: 3e-3,
                        gamma,
                        dist,
                        rgb,
                        alpha,
                        color_mode: mode,
                        double_sided: false,
                        background: [0.2, 0.3, 0.4],
                        ..RasterSettings::default()
                    };
                    out.push((format!("{dist:?} {rgb:?} {alpha:?} {mode:?}"), mesh, s));
                }
            }
        }
    }
    out
}

/// What the twin reads of a scene after its forward: the face setups and the lit colours.
fn device_inputs(gpu: &common::Gpu, scene: &GpuScene) -> (Vec<GpuFaceSetup>, Vec<[f32; 4]>) {
    let setups = scene.read_setups(gpu).unwrap();
    let colors = gpu
        .read_buffer(scene.colors(), 0, (scene.colors().size() / 16) as usize)
        .unwrap();
    (setups, colors)
}

fn twin<'a>(
    mesh: &'a Mesh,
    setups: &'a [GpuFaceSetup],
    colors: &'a [[f32; 4]],
    s: &RasterSettings,
    silhouette: bool,
    cull: bool,
) -> FineTwin<'a> {
    let inputs = FineInputs {
        setups,
        colors,
        faces: &mesh.faces,
        face_count: mesh.faces.len() as u32,
        vertex_count: mesh.positions.len() as u32,
        texture_res: mesh.texture_res,
    };
    FineTwin::new(inputs, s, silhouette, cull)
}

/// Renders `mesh` from `cams` with `s` (tiled, the renderer's default) and compares every output
/// pixel and every rendered pixel's aux with the twin's. Returns the covered pixels compared.
fn check_forward(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    s: &RasterSettings,
    silhouette: bool,
) -> usize {
    let cams = cameras();
    let mut scene = r
        .prepare(gpu, mesh, &cams, &Lighting::default(), s)
        .unwrap();
    scene.set_silhouette_only(silhouette);
    r.run(gpu, &mut scene, Method::default()).unwrap();
    let frames = scene.read_frames(gpu).unwrap();
    let (setups, colors) = device_inputs(gpu, &scene);
    let twin = twin(mesh, &setups, &colors, s, silhouette, true);
    let out_n = frames.images.len() / cams.len();
    let rendered_n = frames.aux.len() / cams.len();
    let mut covered = 0;
    for v in 0..cams.len() {
        let (images, aux) = twin.view(v as u32);
        let device = &frames.images[v * out_n..(v + 1) * out_n];
        for (i, (got, want)) in device.iter().zip(&images).enumerate() {
            assert!(
                got.map(f32::to_bits) == want.map(f32::to_bits),
                "{what}: view {v} pixel {i}: device {got:?}, twin {want:?}"
            );
            covered += usize::from(got[3] > 0.0);
        }
        let device = &frames.aux[v * rendered_n..(v + 1) * rendered_n];
        for (i, (got, want)) in device.iter().zip(&aux).enumerate() {
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

/// The brute-force backward against the twin's, byte for byte: every vertex's position gradient
/// and every colour gradient (the per-pixel chain, the brute force's row-major sums, the view
/// transform and the gather), for an upstream gradient on every output pixel. Unlit, so the
/// host's f64 lighting share is exactly zero and the device's f32 results come through as they
/// are. Returns the nonzero gradient components compared.
fn check_backward(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    s: &RasterSettings,
    silhouette: bool,
) -> usize {
    let cams = cameras();
    let mut scene = r.prepare(gpu, mesh, &cams, &Lighting::unlit(), s).unwrap();
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
    let (setups, colors) = device_inputs(gpu, &scene);
    let twin = twin(mesh, &setups, &colors, s, silhouette, false);
    let views: Vec<GpuView> = cams.iter().map(|c| GpuView::new(c).unwrap()).collect();
    let rendered: Vec<_> = (0..cams.len()).map(|v| twin.rendered(v as u32)).collect();
    let rows = if s.antialias { 2 * s.height } else { s.height };
    let want = twin.backward(&views, &mesh.positions, &d_image, &rendered, rows);
    let mut nonzero = 0;
    let pairs = [
        ("vertex", &grads.positions, &want.positions),
        ("colour", &grads.colors, &want.colors),
    ];
    for (kind, got, want) in pairs {
        assert_eq!(got.len(), want.len(), "{what}: {kind} gradients");
        for (i, (got, want)) in got.iter().zip(want).enumerate() {
            let got = got.map(|x| x as f32); // widened from f32 by the host: exact
            assert!(
                got.map(f32::to_bits) == want.map(f32::to_bits),
                "{what}: {kind} {i}: device {got:?}, twin {want:?}"
            );
            nonzero += got.iter().filter(|x| **x != 0.0).count();
        }
    }
    // Every mode has gradients (hard coverage, colour and alpha leave the colours' at least).
    assert!(
        nonzero > mesh.positions.len() / 2,
        "{what}: only {nonzero} nonzero gradient components"
    );
    nonzero
}

#[test]
fn the_fine_pass_equals_its_bit_twin_in_every_mode() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let (textured, colored) = meshes(2);
    let mut compared = 0;
    for (what, mesh, s) in every_mode(&textured, &colored, 24, 20, 1e-3) {
        compared += check_forward(&r, &gpu, &what, mesh, &s, false);
    }
    // Double-sided, anti-aliased, SoftRas's own σ and γ, and silhouettes.
    let s = RasterSettings {
        width: 16,
        height: 16,
        double_sided: true,
        antialias: true,
        ..RasterSettings::default()
    };
    compared += check_forward(&r, &gpu, "double-sided, anti-aliased", &textured, &s, false);
    let s = RasterSettings {
        width: 24,
        height: 24,
        sigma: 1e-4,
        ..RasterSettings::default()
    };
    compared += check_forward(&r, &gpu, "silhouette", &colored, &s, true);
    assert!(compared > 5_000, "{compared} covered pixels compared");
}

#[test]
fn the_backward_equals_its_bit_twin_in_every_differentiable_mode() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let (textured, colored) = meshes(1);
    let mut compared = 0;
    for (what, mesh, s) in every_mode(&textured, &colored, 16, 14, 1e-2) {
        compared += check_backward(&r, &gpu, &what, mesh, &s, false);
    }
    let s = RasterSettings {
        width: 12,
        height: 12,
        sigma: 1e-3,
        antialias: true,
        ..RasterSettings::default()
    };
    compared += check_backward(&r, &gpu, "anti-aliased", &textured, &s, false);
    let s = RasterSettings {
        width: 16,
        height: 16,
        sigma: 1e-3,
        ..RasterSettings::default()
    };
    compared += check_backward(&r, &gpu, "silhouette", &colored, &s, true);
    assert!(
        compared > 5_000,
        "{compared} nonzero gradient components compared"
    );
}
