//! Lighting on the GPU (`softvk::raster::light`) against its f64 twins: the lit colours of
//! moved vertices, the lighting's backward (unlit colours and positions), both colour modes,
//! reruns bit for bit, and misuse.

mod common;

use glam::{DMat3, DVec3};
use rand::RngExt;
use softvk::Error;
use softvk::camera::Camera;
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::raster::gpu::Renderer;
use softvk::raster::light::SceneLight;
use softvk::raster::reference_grad::{VertexFaces, lighting_grad_surface, lighting_grad_vertex};
use softvk::raster::settings::{ColorMode, RasterSettings};
use softvk::raster::setup::VertexLayout;

/// Two directional lights, one of them behind many faces (so max(0, n · d) clips), coloured.
fn lighting() -> Lighting {
    Lighting {
        ambient_intensity: 0.3,
        ambient_color: [1.0, 0.9, 0.8],
        directionals: vec![
            Directional {
                intensity: 0.6,
                color: [1.0, 1.0, 0.9],
                direction: [0.3, 0.5, -0.8],
            },
            Directional {
                intensity: 0.4,
                color: [0.5, 0.7, 1.0],
                direction: [-0.9, 0.1, 0.4],
            },
        ],
    }
}

/// A jittered icosphere(1) with random texels (R = 2) and vertex colours (or none).
fn mesh(seed: u64, vertex_colors: bool) -> Mesh {
    let mut rng = common::rng(seed);
    let ico = Mesh::icosphere(1);
    let positions = ico
        .positions
        .iter()
        .map(|p| p.map(|c| c * 0.6 + rng.random_range(-0.05..0.05)))
        .collect();
    let mut m = Mesh::new(positions, ico.faces.clone(), 2).unwrap();
    let mut colors = |n: usize| -> Vec<[f32; 3]> {
        (0..n)
            .map(|_| std::array::from_fn(|_| rng.random_range(0.1..0.9)))
            .collect()
    };
    m.textures = colors(m.textures.len());
    m.vertex_colors = vertex_colors.then(|| colors(m.vertex_count()));
    m
}

/// The mesh's positions turned and shifted (what a pose fit's vertices do).
fn moved(mesh: &Mesh) -> Vec<DVec3> {
    let r = DMat3::from_axis_angle(DVec3::new(0.3, -0.8, 0.5).normalize(), 0.9);
    mesh.positions
        .iter()
        .map(|p| r * DVec3::from(p.map(f64::from)) + DVec3::new(0.1, -0.2, 0.05))
        .collect()
}

fn widen3(v: &[f32]) -> Vec<[f64; 3]> {
    v.chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]].map(f64::from))
        .collect()
}

/// Largest |a − b| over the largest |b| (how much the lighting moves the positions' gradient).
fn rel_err(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    let (err, scale) = common::rel_err3(a, b);
    assert!(scale > 0.0);
    err
}

/// Every component of `got` within `rel` of its reference plus `floor` (measured, below).
fn held(what: &str, got: &[[f64; 3]], want: &[[f64; 3]], rel: f64, floor: f64) {
    let flat = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<f64>>();
    let (a, b) = (flat(got), flat(want));
    let size = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let (near, relative) = common::measured(&a, &b, 1e-2 * size);
    eprintln!("{what}: near zero {near:.2e} (largest {size:.2e}), relative {relative:.2e}");
    let (share, i) = common::worst_share(&a, &b, rel, floor);
    eprintln!(
        "{what}: worst component uses {:.3} of its bound ({} against {})",
        share, a[i], b[i]
    );
    assert!(
        share <= 1.0,
        "{what}: component {i} is {} against {}",
        a[i],
        b[i]
    );
}

/// One forward and one backward on the GPU at the moved positions: (lit colours, dL/d(unlit
/// colour), dL/d(position)), each read back.
struct Run {
    lit: Vec<[f64; 3]>,
    d_base: Vec<[f64; 3]>,
    d_positions: Vec<[f64; 3]>,
}

fn run(
    gpu: &common::Gpu,
    mesh: &Mesh,
    mode: ColorMode,
    posed: &[DVec3],
    d_lit: &[f32],
    g0: &[f32],
) -> Run {
    let settings = RasterSettings {
        width: 16,
        height: 16,
        color_mode: mode,
        ..RasterSettings::default()
    };
    let camera = Camera::from_angles(2.732, 20.0, 30.0);
    let renderer = Renderer::new(gpu).unwrap();
    let scene = renderer
        .prepare(gpu, mesh, &[camera], &lighting(), &settings)
        .unwrap();
    let light = SceneLight::new(gpu, &scene).unwrap();
    let n = light.color_count() as usize;
    assert_eq!(3 * n, d_lit.len());
    let flat: Vec<f32> = posed
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    gpu.write_buffer(scene.positions(), 0, &flat).unwrap();
    let d_lit = gpu.upload_buffer("d_lit", d_lit).unwrap();
    let d_positions = gpu.upload_buffer("d_positions", g0).unwrap();
    let d_base = gpu.upload_buffer("d_base", &vec![0f32; 3 * n]).unwrap();
    let layout = VertexLayout::default();
    gpu.submit_and_wait(|rec| {
        light.record_forward(
            rec,
            scene.positions().whole(),
            layout,
            scene.colors().whole(),
        )?;
        light.record_backward(
            rec,
            scene.positions().whole(),
            layout,
            d_lit.whole(),
            d_base.whole(),
            d_positions.whole(),
        )
    })
    .unwrap();
    let lit: Vec<[f32; 4]> = gpu.read_buffer(scene.colors(), 0, n).unwrap();
    Run {
        lit: lit
            .iter()
            .map(|c| [c[0], c[1], c[2]].map(f64::from))
            .collect(),
        d_base: widen3(&gpu.read_buffer::<f32>(&d_base, 0, 3 * n).unwrap()),
        d_positions: widen3(&gpu.read_buffer::<f32>(&d_positions, 0, g0.len()).unwrap()),
    }
}

fn random(n: usize, seed: u64) -> Vec<f32> {
    let mut rng = common::rng(seed);
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// Each component of the lit colours and both gradients within REL of itself plus a floor of its
/// own, about 3 times the worst measured on lavapipe over the three modes: 3.9e-7 relative;
/// near zero, 0 for the lit colours, 1.7e-9 for the colours' gradient, and 6.1e-7 for the
/// positions' (whose components sum the random g0 and the lighting's share: a component of 0.05
/// carries the rounding of terms a hundred times larger).
const REL: f64 = 1.2e-6;
const LIT_FLOOR: f64 = 1e-8;
const COLOR_FLOOR: f64 = 5e-9;
const POSITION_FLOOR: f64 = 2e-6;

#[test]
fn gpu_lighting_and_its_backward_match_the_twins_in_both_colour_modes() {
    let Some(gpu) = common::gpu() else { return };
    let l = lighting();
    for (mode, vertex_colors) in [
        (ColorMode::Surface, false),
        (ColorMode::Vertex, true),
        (ColorMode::Vertex, false),
    ] {
        let what = format!("{mode:?}, vertex colours {vertex_colors}");
        let m = mesh(3, vertex_colors);
        let posed = moved(&m);
        let texels: Vec<[f64; 3]> = m.textures.iter().map(|t| t.map(f64::from)).collect();
        let colors: Option<Vec<[f64; 3]>> = m
            .vertex_colors
            .as_ref()
            .map(|cs| cs.iter().map(|c| c.map(f64::from)).collect());
        let want_lit = match mode {
            ColorMode::Surface => l.apply_surface_of(&posed, &m.faces, m.texture_res, &texels),
            ColorMode::Vertex => l.apply_vertex_of(&posed, &m.faces, colors.as_deref()),
        };
        let d_lit = random(3 * want_lit.len(), 11);
        let g0 = random(3 * m.vertex_count(), 12);
        let got = run(&gpu, &m, mode, &posed, &d_lit, &g0);
        held(
            &format!("{what}: lit colours"),
            &got.lit,
            &want_lit,
            REL,
            LIT_FLOOR,
        );

        let d_lit64 = widen3(&d_lit);
        let (want_base, corners) = match mode {
            ColorMode::Surface => {
                lighting_grad_surface(&l, &posed, &m.faces, m.texture_res, &texels, &d_lit64)
            }
            ColorMode::Vertex => {
                lighting_grad_vertex(&l, &posed, &m.faces, colors.as_deref(), &d_lit64)
            }
        };
        held(
            &format!("{what}: dL/d(unlit colour)"),
            &got.d_base,
            &want_base,
            REL,
            COLOR_FLOOR,
        );
        let light_share = VertexFaces::new(&m.faces, m.vertex_count()).gather(&corners);
        let g064 = widen3(&g0);
        let want_positions: Vec<[f64; 3]> = g064
            .iter()
            .zip(&light_share)
            .map(|(g, s)| std::array::from_fn(|k| g[k] + s[k]))
            .collect();
        held(
            &format!("{what}: dL/d(position)"),
            &got.d_positions,
            &want_positions,
            REL,
            POSITION_FLOOR,
        );
        // The lighting's own share is not negligible next to the random g0.
        let share = rel_err(&g064, &want_positions);
        assert!(share > 1e-2, "{what}: the lighting adds only {share:e}");

        // Bit for bit on a rerun.
        let again = run(&gpu, &m, mode, &posed, &d_lit, &g0);
        let bits = |v: &[[f64; 3]]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&again.lit), bits(&got.lit), "{what}");
        assert_eq!(bits(&again.d_positions), bits(&got.d_positions), "{what}");
    }
}

#[test]
fn gpu_lighting_refuses_another_layout_and_small_buffers() {
    let Some(gpu) = common::gpu() else { return };
    let m = mesh(5, false);
    let renderer = Renderer::new(&gpu).unwrap();
    let scene = renderer
        .prepare(
            &gpu,
            &m,
            &[Camera::from_angles(2.732, 20.0, 30.0)],
            &lighting(),
            &RasterSettings::default(),
        )
        .unwrap();
    let light = SceneLight::new(&gpu, &scene).unwrap();
    let small = gpu.upload_buffer("small", &[0f32; 4]).unwrap();
    let err = gpu
        .submit_and_wait(|rec| {
            light.record_forward(
                rec,
                scene.positions().whole(),
                VertexLayout {
                    offset: 0,
                    stride: 4,
                },
                scene.colors().whole(),
            )
        })
        .unwrap_err();
    assert!(matches!(err, Error::Misuse(_)), "{err}");
    let err = gpu
        .submit_and_wait(|rec| {
            light.record_forward(
                rec,
                scene.positions().whole(),
                VertexLayout::default(),
                small.whole(),
            )
        })
        .unwrap_err();
    assert!(matches!(err, Error::BufferTooSmall { .. }), "{err}");
}
