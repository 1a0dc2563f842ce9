//! The bit twins (`raster::bits`): the projection and face set-up, the lit colours (the host's
//! f64 lighting as uploaded, and the lighting kernels), the forward's fine pass and the backward
//! (brute force and the tiled default) evaluated in f32 on the CPU, operation for operation,
//! from the mesh, the cameras and the lighting, equal the device's set-ups, colours, images, aux
//! and gradients byte for byte, in every SoftRas mode. What the device computes is then the IEEE
//! evaluation of the written operations (softvk's own `exp`, sigmoid, square root and reciprocal
//! included), which every conformant device must reproduce.

mod common;

use softvk::camera::Camera;
use softvk::gpu::MemoryKind;
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::raster::backward::GradBuffers;
use softvk::raster::bits::{
    FineInputs, FineTwin, GpuLightTwin, SumOrder, face_setups, host_lit_colors,
};
use softvk::raster::fine::PixelAux;
use softvk::raster::gpu::{DEFAULT_TILE, Method, Renderer};
use softvk::raster::light::SceneLight;
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

/// Where a scene's lit colours come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Light {
    /// `Renderer::prepare`'s: the host's f64 lighting, rounded to f32 and uploaded.
    Host,
    /// The lighting kernels (`SceneLight`, what the pose fits record), run over the scene's
    /// colours before the forward.
    Gpu,
}

impl Light {
    /// The lighting of a scene lit this way: SoftRas's default (ambient 0.5, one white light
    /// from +y) through the host; through the kernels, coloured lights from two oblique
    /// directions, so that every term of `n · d` and of its gradient is nonzero.
    fn lighting(self) -> Lighting {
        match self {
            Light::Host => Lighting::default(),
            Light::Gpu => Lighting {
                ambient_intensity: 0.4,
                ambient_color: [1.0, 0.9, 0.8],
                directionals: vec![
                    Directional {
                        intensity: 0.6,
                        color: [1.0, 1.0, 0.9],
                        direction: [0.3, 0.8, 0.52],
                    },
                    Directional {
                        intensity: 0.3,
                        color: [0.5, 0.7, 1.0],
                        direction: [-0.6, 0.2, -0.77],
                    },
                ],
            },
        }
    }
}

fn gpu_views(cams: &[Camera]) -> Vec<GpuView> {
    cams.iter().map(|c| GpuView::new(c).unwrap()).collect()
}

/// Every word of a set-up, as bits.
fn setup_bits(s: &GpuFaceSetup) -> Vec<u32> {
    bytemuck::cast_slice(bytemuck::bytes_of(s)).to_vec()
}

/// A scene of `mesh` from `cams` lit by `lighting` as `light` says, ready to render, and the
/// twin's lit colours for it (from the mesh and the lighting, not the device's).
fn lit_scene(
    r: &Renderer,
    gpu: &common::Gpu,
    mesh: &Mesh,
    cams: &[Camera],
    lighting: &Lighting,
    s: &RasterSettings,
    light: Light,
) -> (GpuScene, Vec<[f32; 4]>) {
    let scene = r.prepare(gpu, mesh, cams, lighting, s).unwrap();
    let colors = match light {
        Light::Host => host_lit_colors(mesh, lighting, s.color_mode),
        Light::Gpu => {
            let l = SceneLight::new(gpu, &scene).unwrap();
            gpu.submit_and_wait(|rec| {
                l.record_forward(
                    rec,
                    scene.positions().whole(),
                    scene.position_layout(),
                    scene.colors().whole(),
                )
            })
            .unwrap();
            GpuLightTwin::new(mesh, &mesh.positions, lighting, s.color_mode).forward()
        }
    };
    (scene, colors)
}

/// The twin's inputs against the device's after a forward: every face set-up of every view and
/// every lit colour, bit for bit (so that a failure says which stage differs). Returns the
/// components compared.
fn check_inputs(
    gpu: &common::Gpu,
    what: &str,
    scene: &GpuScene,
    setups: &[GpuFaceSetup],
    colors: &[[f32; 4]],
) -> usize {
    let device = scene.read_setups(gpu).unwrap();
    assert_eq!(device.len(), setups.len(), "{what}: set-ups");
    for (i, (got, want)) in device.iter().zip(setups).enumerate() {
        assert_eq!(
            setup_bits(got),
            setup_bits(want),
            "{what}: face set-up {i}: device {got:?}, twin {want:?}"
        );
    }
    // (The buffer may be larger than its colours.)
    assert!(
        scene.colors().size() >= 16 * colors.len() as u64,
        "{what}: lit colours"
    );
    let device: Vec<[f32; 4]> = gpu.read_buffer(scene.colors(), 0, colors.len()).unwrap();
    for (i, (got, want)) in device.iter().zip(colors).enumerate() {
        assert!(
            got.map(f32::to_bits) == want.map(f32::to_bits),
            "{what}: lit colour {i}: device {got:?}, twin {want:?}"
        );
    }
    setups.len() * 32 + colors.len() * 4
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

/// The device's frames against the twin's: every output pixel and every rendered pixel's aux.
/// Returns the covered output pixels.
fn check_frames(gpu: &common::Gpu, what: &str, scene: &GpuScene, twin: &FineTwin<'_>) -> usize {
    let views = scene.view_count() as usize;
    let frames = scene.read_frames(gpu).unwrap();
    let out_n = frames.images.len() / views;
    let rendered_n = frames.aux.len() / views;
    let mut covered = 0;
    for v in 0..views {
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

/// Renders `mesh` from the cameras with `s` (tiled, the renderer's default), lit by
/// [`Light::lighting`] as `light` says, and compares the device's face set-ups and lit colours
/// with the twins' (from the mesh, cameras and lighting), then every output pixel and every
/// rendered pixel's aux with the fine pass's twin over those. Returns the covered pixels
/// compared.
fn check_forward(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    s: &RasterSettings,
    silhouette: bool,
    light: Light,
) -> usize {
    let what = format!("{what} ({light:?} lighting)");
    let cams = cameras();
    let lighting = light.lighting();
    let (mut scene, colors) = lit_scene(r, gpu, mesh, &cams, &lighting, s, light);
    scene.set_silhouette_only(silhouette);
    r.run(gpu, &mut scene, Method::default()).unwrap();
    let setups = face_setups(&[&mesh.positions], &mesh.faces, &gpu_views(&cams), s);
    check_inputs(gpu, &what, &scene, &setups, &colors);
    let twin = twin(mesh, &setups, &colors, s, silhouette, true);
    check_frames(gpu, &what, &scene, &twin)
}

/// What one backward check compared.
#[derive(Default)]
struct Compared {
    /// Nonzero gradient components compared (raster backward, and lighting's).
    nonzero: usize,
    /// Gradient components compared.
    components: usize,
}

/// A backward (`method`, lit by [`Light::lighting`] as `light` says) against the twin's,
/// byte for byte: the device's f32 results, dL/d(world position) and dL/d(lit colour) (the
/// per-pixel chain, `method`'s sums, the reductions, the view transform and the gather), for an
/// upstream gradient on every output pixel, with every twin input (set-ups, lit colours,
/// rendered images and aux, all checked against the device first) from the mesh, cameras and
/// lighting. Host lighting's share of the gradients is the host's, in f64
/// (`GradKernels::finish`): not compared here. With the lighting kernels, their backward
/// (`SceneLight::record_backward`: dL/d(unlit colour), and the normals' share added to the
/// positions') is compared too.
#[allow(clippy::too_many_arguments)]
fn check_backward(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    s: &RasterSettings,
    silhouette: bool,
    method: Method,
    light: Light,
) -> Compared {
    let what = format!("{what} ({method:?}, {light:?} lighting)");
    let cams = cameras();
    let lighting = light.lighting();
    let (mut scene, colors) = lit_scene(r, gpu, mesh, &cams, &lighting, s, light);
    scene.set_silhouette_only(silhouette);
    r.run(gpu, &mut scene, method).unwrap();
    let run = scene.last_run().unwrap();
    let binned = run.binned();
    let scene = binned.scene();
    let views = gpu_views(&cams);
    let setups = face_setups(&[&mesh.positions], &mesh.faces, &views, s);
    check_inputs(gpu, &what, scene, &setups, &colors);
    let twin = twin(mesh, &setups, &colors, s, silhouette, false);
    check_frames(gpu, &what, scene, &twin);

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
    let gb = GradBuffers::new(gpu, &binned).unwrap();
    gb.set_d_image(gpu, scene, &d_image).unwrap();
    let io = gb.io();
    gpu.submit_and_wait(|rec| r.grad_kernels().record(rec, &binned, &gb, &io))
        .unwrap();
    let nv = mesh.positions.len();
    let nc = colors.len();
    let device_positions: Vec<[f32; 3]> = gpu
        .read_buffer(io.positions.buffer, io.positions.offset, nv)
        .unwrap();
    let device_colors: Vec<[f32; 3]> = gpu
        .read_buffer(io.colors.buffer, io.colors.offset, nc)
        .unwrap();

    let rendered: Vec<_> = (0..cams.len()).map(|v| twin.rendered(v as u32)).collect();
    let order = match method {
        Method::Brute => {
            // One band of every rendered row: these scenes are far under any loop cap.
            assert_eq!(gb.bands(), 1, "{what}: brute-force bands");
            SumOrder::Brute {
                band_rows: scene.rendered_size().1,
            }
        }
        Method::Tiled { tile } => SumOrder::Tiled { tile },
    };
    let want = twin.backward(&views, &mesh.positions, &d_image, &rendered, order);
    let mut compared = Compared::default();
    let mut compare = |kind: &str, got: &[[f32; 3]], want: &[[f32; 3]]| {
        assert_eq!(got.len(), want.len(), "{what}: {kind} gradients");
        for (i, (got, want)) in got.iter().zip(want).enumerate() {
            assert!(
                got.map(f32::to_bits) == want.map(f32::to_bits),
                "{what}: {kind} {i}: device {got:?}, twin {want:?}"
            );
            compared.nonzero += got.iter().filter(|x| **x != 0.0).count();
            compared.components += 3;
        }
    };
    compare("vertex", &device_positions, &want.positions);
    compare("lit colour", &device_colors, &want.colors);

    if light == Light::Gpu {
        // The lighting kernels' backward over the raster backward's results, as a fit records it.
        let l = SceneLight::new(gpu, scene).unwrap();
        let d_base = gpu
            .create_buffer("d base", 12 * nc as u64, MemoryKind::Device)
            .unwrap();
        gpu.submit_and_wait(|rec| {
            l.record_backward(
                rec,
                scene.positions().whole(),
                scene.position_layout(),
                io.colors,
                d_base.whole(),
                io.positions,
            )
        })
        .unwrap();
        let got_base: Vec<[f32; 3]> = gpu.read_buffer(&d_base, 0, nc).unwrap();
        let got_positions: Vec<[f32; 3]> = gpu
            .read_buffer(io.positions.buffer, io.positions.offset, nv)
            .unwrap();
        let light_twin = GpuLightTwin::new(mesh, &mesh.positions, &lighting, s.color_mode);
        let (want_base, want_positions) = light_twin.backward(&want.colors, &want.positions);
        compare("unlit colour", &got_base, &want_base);
        compare("lit vertex", &got_positions, &want_positions);
    }
    // Every mode has gradients (hard coverage, colour and alpha leave the colours' at least).
    assert!(
        compared.nonzero > nv / 2,
        "{what}: only {} nonzero gradient components",
        compared.nonzero
    );
    compared
}

#[test]
fn the_fine_pass_and_its_setups_equal_their_bit_twins_in_every_mode() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let (textured, colored) = meshes(2);
    let mut compared = 0;
    for light in [Light::Host, Light::Gpu] {
        for (what, mesh, s) in every_mode(&textured, &colored, 24, 20, 1e-3) {
            compared += check_forward(&r, &gpu, &what, mesh, &s, false, light);
        }
        // Double-sided, anti-aliased, SoftRas's own σ and γ, and silhouettes.
        let s = RasterSettings {
            width: 16,
            height: 16,
            double_sided: true,
            antialias: true,
            ..RasterSettings::default()
        };
        compared += check_forward(
            &r,
            &gpu,
            "double-sided, anti-aliased",
            &textured,
            &s,
            false,
            light,
        );
        let s = RasterSettings {
            width: 24,
            height: 24,
            sigma: 1e-4,
            ..RasterSettings::default()
        };
        compared += check_forward(&r, &gpu, "silhouette", &colored, &s, true, light);
    }
    assert!(compared > 10_000, "{compared} covered pixels compared");
}

/// `method`'s backward against the twin in every differentiable mode, anti-aliased and for a
/// silhouette, under each of `lights`.
fn backward_in_every_mode(method: Method, lights: &[Light]) -> Compared {
    let Some(gpu) = common::gpu() else {
        return Compared::default();
    };
    let r = Renderer::new(&gpu).unwrap();
    let (textured, colored) = meshes(1);
    let mut total = Compared::default();
    let mut add = |c: Compared| {
        total.nonzero += c.nonzero;
        total.components += c.components;
    };
    for &light in lights {
        for (what, mesh, s) in every_mode(&textured, &colored, 16, 14, 1e-2) {
            add(check_backward(
                &r, &gpu, &what, mesh, &s, false, method, light,
            ));
        }
        let s = RasterSettings {
            width: 12,
            height: 12,
            sigma: 1e-3,
            antialias: true,
            ..RasterSettings::default()
        };
        add(check_backward(
            &r,
            &gpu,
            "anti-aliased",
            &textured,
            &s,
            false,
            method,
            light,
        ));
        let s = RasterSettings {
            width: 16,
            height: 16,
            sigma: 1e-3,
            ..RasterSettings::default()
        };
        add(check_backward(
            &r,
            &gpu,
            "silhouette",
            &colored,
            &s,
            true,
            method,
            light,
        ));
    }
    println!(
        "{method:?}: {} gradient components compared, {} nonzero",
        total.components, total.nonzero
    );
    assert!(
        total.nonzero > 5_000 * lights.len(),
        "{} nonzero gradient components compared",
        total.nonzero
    );
    total
}

#[test]
fn the_brute_force_backward_equals_its_bit_twin_in_every_differentiable_mode() {
    backward_in_every_mode(Method::Brute, &[Light::Host]);
}

#[test]
fn the_tiled_backward_equals_its_bit_twin_in_every_differentiable_mode() {
    assert_eq!(Method::default(), Method::Tiled { tile: DEFAULT_TILE });
    backward_in_every_mode(Method::default(), &[Light::Host, Light::Gpu]);
}

/// The tiled backward's order is the pixels', whatever the tile: on 16-pixel tiles (four 8 × 8
/// blocks each) too.
#[test]
fn the_tiled_backward_on_larger_tiles_equals_its_bit_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let (textured, colored) = meshes(1);
    for (what, mesh, s) in every_mode(&textured, &colored, 20, 18, 1e-2)
        .into_iter()
        .filter(|(_, _, s)| s.dist != Dist::Hard && s.alpha == Alpha::Prod)
    {
        let method = Method::Tiled { tile: 16 };
        check_backward(&r, &gpu, &what, mesh, &s, false, method, Light::Gpu);
    }
}
