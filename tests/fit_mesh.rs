//! The GPU mesh fit (`fit::mesh_fit`) against the same iteration assembled from the CPU twins:
//! deformation → f64 render → 1 − IoU → f64 backward → Laplacian and flatten → deformation
//! backward → Adam.

mod common;

use softvk::camera::{Camera, Projection};
use softvk::fit::flatten::{self, FlattenEdges};
use softvk::fit::laplacian::{self, Adjacency};
use softvk::fit::mesh_fit::{MeshFitOptions, fit_mesh};
use softvk::fit::{adam, deform, silhouette};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::reference::{self, Alpha, Dist, RasterSettings, Rgb};
use softvk::raster::reference_grad;

/// An icosphere(1) of radius 0.5, turned so no coordinate is zero.
fn template() -> Mesh {
    let mut mesh = Mesh::icosphere(1);
    let rot = glam::DMat3::from_euler(glam::EulerRot::XYZ, 0.31, 0.47, 0.13);
    for p in &mut mesh.positions {
        let v = rot * glam::DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])) * 0.5;
        *p = [v.x as f32, v.y as f32, v.z as f32];
    }
    mesh
}

/// Iterations compared: past the first, Adam's steps depend on the gradients' sizes too.
const ITERATIONS: u32 = 3;

#[test]
fn a_gpu_iteration_equals_the_iteration_of_the_twins() {
    let Some(gpu) = common::gpu() else { return };
    let size = 20;
    let cams: Vec<Camera> = [0.0, 120.0]
        .iter()
        .map(|&az| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(2.732, 30.0, az)
        })
        .collect();
    // Target: a box, rendered hard.
    let target_mesh = Mesh::cuboid([0.35, 0.25, 0.3]);
    let hard = RasterSettings {
        width: size,
        height: size,
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..RasterSettings::default()
    };
    let targets: Vec<f32> = Renderer::new(&gpu)
        .unwrap()
        .render_views(
            &gpu,
            &target_mesh,
            &cams,
            &Lighting::unlit(),
            &hard,
            Method::default(),
        )
        .unwrap()
        .images
        .iter()
        .map(|p| p[3])
        .collect();
    let opts = MeshFitOptions {
        iterations: ITERATIONS,
        log_every: 1,
        settings: RasterSettings {
            width: size,
            height: size,
            sigma: 1e-3,
            rgb: Rgb::Hard,
            ..RasterSettings::default()
        },
        tile: 8,
        ..MeshFitOptions::default()
    };
    let t = template();
    let mut gpu_losses = Vec::new();
    let fit = fit_mesh(&gpu, &t, &cams, &targets, &opts, |l, _, _| {
        gpu_losses.push(l.total);
        true
    })
    .unwrap();
    assert_eq!(gpu_losses.len(), ITERATIONS as usize);

    // The twins, iteration by iteration.
    let n = t.vertex_count();
    let (base, signs) = deform::cpu::template_terms(&t.positions).unwrap();
    let adjacency = Adjacency::from_faces(&t.faces, n).unwrap();
    let edges = FlattenEdges::from_faces(&t.faces, n).unwrap();
    let s = &opts.settings;
    let t64: Vec<f64> = targets.iter().map(|&v| f64::from(v)).collect();
    let mut params = vec![0.0; 3 * n + 3];
    let (mut m, mut v) = (vec![0.0; params.len()], vec![0.0; params.len()]);
    // Parameters whose gradient was ever at the level of f32 rounding (see below).
    let mut ambiguous = vec![false; params.len()];
    let mut losses = Vec::new();
    for step in 1..=ITERATIONS {
        let x = deform::cpu::forward(&base, &signs, &params);
        let mut mesh = t.clone();
        for (p, c) in mesh.positions.iter_mut().zip(x.chunks(3)) {
            *p = [c[0] as f32, c[1] as f32, c[2] as f32];
        }
        let images: Vec<[f64; 4]> = cams
            .iter()
            .flat_map(|c| reference::render(&mesh, c, &Lighting::unlit(), s).unwrap())
            .collect();
        let iou = silhouette::cpu::neg_iou(&images, &t64, cams.len());
        let g = reference_grad::grad(&mesh, &cams, &Lighting::unlit(), s, &iou.d_image).unwrap();
        let mut d_x: Vec<f64> = g.positions.iter().flatten().copied().collect();
        let (lap, d_lap) = laplacian::cpu::loss_and_grad(&adjacency, &x);
        let (flat, d_flat) = flatten::cpu::loss_and_grad(&edges, &x);
        for i in 0..3 * n {
            d_x[i] += f64::from(opts.laplacian) * d_lap[i] + f64::from(opts.flatten) * d_flat[i];
        }
        losses.push(iou.loss + f64::from(opts.laplacian) * lap + f64::from(opts.flatten) * flat);
        let d_params = deform::cpu::backward(&base, &signs, &params, &d_x);
        let scale = d_params.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        for (a, d) in ambiguous.iter_mut().zip(&d_params) {
            *a |= d.abs() < 1e-3 * scale;
        }
        adam::cpu::step(&mut params, &d_params, &mut m, &mut v, step, &opts.adam);
    }
    let x1 = deform::cpu::forward(&base, &signs, &params);

    for (it, (got, want)) in gpu_losses.iter().zip(&losses).enumerate() {
        assert!(
            (f64::from(*got) - want).abs() < 1e-4,
            "iteration {}: loss GPU {got} vs twins {want}",
            it + 1
        );
    }
    // Adam's first step moves every parameter by ±lr (m̂/√v̂ = sign g): a parameter whose
    // gradient is at the level of the GPU's rounding may go either way, and then differ for
    // good. Elsewhere the positions must agree; and most must be unambiguous for the test to
    // say anything.
    let center_ambiguous = ambiguous[3 * n..].iter().any(|&a| a);
    assert!(
        !center_ambiguous,
        "the centre's gradient is ambiguous: pick another target"
    );
    let mut checked = 0;
    for vtx in 0..n {
        for k in 0..3 {
            let i = 3 * vtx + k;
            if ambiguous[i] {
                continue;
            }
            checked += 1;
            let got = f64::from(fit.mesh.positions[vtx][k]);
            assert!(
                (got - x1[i]).abs() < 1e-5,
                "vertex {vtx} coordinate {k}: GPU {got} vs twins {}",
                x1[i]
            );
        }
    }
    assert!(
        checked * 10 >= 3 * n * 8,
        "only {checked} of {} coordinates checked",
        3 * n
    );
}
