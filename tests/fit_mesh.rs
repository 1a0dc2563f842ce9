//! The GPU mesh fit (`fit::mesh_fit`) against the same iteration assembled from the CPU twins:
//! deformation → f64 render → 1 − IoU → f64 backward → Laplacian and flatten → deformation
//! backward → Adam.

mod common;

use softvk::camera::{Camera, Projection};
use softvk::fit::flatten::{self, FlattenEdges};
use softvk::fit::laplacian::{self, Adjacency};
use softvk::fit::mesh_fit::{FitLog, MeshFitOptions, fit_mesh};
use softvk::fit::session::Session;
use softvk::fit::{adam, deform, silhouette};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::reference;
use softvk::raster::reference_grad;
use softvk::raster::settings::{Alpha, Dist, RasterSettings, Rgb};

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
    let fit = fit_mesh(
        &gpu,
        &t,
        &cams,
        &targets,
        &opts,
        Session::new().on_row(|l: &FitLog| {
            gpu_losses.push(l.total);
            true
        }),
    )
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

/// A small fit problem: the box target seen from two views at 20².
fn small_problem(gpu: &common::Gpu) -> (Vec<Camera>, Vec<f32>, MeshFitOptions) {
    let size = 20;
    let cams: Vec<Camera> = [30.0, 150.0]
        .iter()
        .map(|&az| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(2.732, 30.0, az)
        })
        .collect();
    let hard = RasterSettings {
        width: size,
        height: size,
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..RasterSettings::default()
    };
    let targets: Vec<f32> = Renderer::new(gpu)
        .unwrap()
        .render_views(
            gpu,
            &Mesh::cuboid([0.4, 0.2, 0.3]),
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
        iterations: 12,
        // A large step, so that the entry count moves within a few iterations.
        adam: softvk::fit::AdamOptions {
            lr: 0.05,
            ..MeshFitOptions::default().adam
        },
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
    (cams, targets, opts)
}

/// The mean IoU of `mesh`'s hard silhouettes through `cams` with `targets` (> 0.5 inside).
fn hard_iou(gpu: &common::Gpu, mesh: &Mesh, cams: &[Camera], targets: &[f32], size: u32) -> f64 {
    let hard = RasterSettings {
        width: size,
        height: size,
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..RasterSettings::default()
    };
    let masks = Renderer::new(gpu)
        .unwrap()
        .render_silhouettes(gpu, mesh, cams, &hard, Method::default())
        .unwrap();
    let ious = silhouette::hard_ious(&masks, targets, (size * size) as usize);
    ious.iter().map(|&x| f64::from(x)).sum::<f64>() / ious.len() as f64
}

/// The fit converges: on the small problem (a box's silhouettes from two views at 20²), the
/// template's hard silhouettes go from a poor match to an IoU of at least 0.9 with the
/// targets. A fit whose gradients, steps or deformation were broken would not get there.
#[test]
fn a_mesh_fit_converges_to_its_targets() {
    let Some(gpu) = common::gpu() else { return };
    let (cams, targets, opts) = small_problem(&gpu);
    // σ as SoftRas's demo: sharp enough that the soft silhouettes the fit matches are close to
    // the hard ones measured.
    let opts = MeshFitOptions {
        iterations: 200,
        settings: RasterSettings {
            sigma: 1e-4,
            ..opts.settings
        },
        ..opts
    };
    let before = hard_iou(&gpu, &template(), &cams, &targets, 20);
    let fit = fit_mesh(&gpu, &template(), &cams, &targets, &opts, Session::new()).unwrap();
    let after = hard_iou(&gpu, &fit.mesh, &cams, &targets, 20);
    eprintln!("hard IoU {before:.3} -> {after:.3}");
    assert!(
        before < 0.8 && after >= 0.9,
        "hard IoU {before:.3} -> {after:.3}"
    );
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// A fit's parameter bits, logged (iteration, total loss bits, entries), regrowths, and the
/// queue submissions softvk made.
type FitRun = (Vec<u32>, Vec<(u32, u32, u64)>, u32, u64);

/// Runs a fit.
fn run_fit(gpu: &common::Gpu, cams: &[Camera], targets: &[f32], opts: &MeshFitOptions) -> FitRun {
    let mut logged = Vec::new();
    let before = gpu.counters().submissions;
    let fit = fit_mesh(
        gpu,
        &template(),
        cams,
        targets,
        opts,
        Session::new().on_row(|l: &FitLog| {
            logged.push((l.iteration, l.total.to_bits(), l.entries));
            true
        }),
    )
    .unwrap();
    let submissions = gpu.counters().submissions - before;
    (bits(&fit.params), logged, fit.regrowths, submissions)
}

#[test]
fn k_iterations_per_submission_give_the_bits_of_one_per_submission() {
    let Some(gpu) = common::gpu() else { return };
    let (cams, targets, opts) = small_problem(&gpu);
    let one = MeshFitOptions {
        log_every: 1,
        ..opts.clone()
    };
    let (params_1, log_1, regrowths_1, submissions_1) = run_fit(&gpu, &cams, &targets, &one);
    assert_eq!(log_1.len(), 12);
    assert_eq!(regrowths_1, 0, "the default capacity has headroom");
    let mut submissions = vec![(1, submissions_1)];
    for k in [5, 12] {
        let batched = MeshFitOptions {
            log_every: k,
            ..opts.clone()
        };
        let (params_k, log_k, regrowths_k, submissions_k) =
            run_fit(&gpu, &cams, &targets, &batched);
        assert_eq!(regrowths_k, 0);
        submissions.push((k, submissions_k));
        assert_eq!(params_k, params_1, "k = {k}: parameters differ from k = 1");
        // Logged after iterations k, 2k, ... and the last: the same values as k = 1's there.
        let want: Vec<u32> = (1..=12).filter(|i| i % k == 0 || *i == 12).collect();
        assert_eq!(log_k.iter().map(|l| l.0).collect::<Vec<_>>(), want);
        for l in &log_k {
            assert_eq!(*l, log_1[l.0 as usize - 1], "k = {k}, iteration {}", l.0);
        }
    }
    // Submissions grow with the chunks of k iterations (one submission for the chunk, then the
    // gate's status and the logged losses read back), not with the iterations: one chunk of
    // 12 iterations costs what a fit of 1 iteration costs, and 12, 3 and 1 chunks (k = 1, 5,
    // 12) cost that plus a fixed amount per further chunk.
    let single = MeshFitOptions {
        iterations: 1,
        log_every: 1,
        ..opts.clone()
    };
    let (_, _, _, submissions_single) = run_fit(&gpu, &cams, &targets, &single);
    assert_eq!(submissions[2].1, submissions_single, "{submissions:?}");
    let chunks = |k: u64| 12u64.div_ceil(k);
    let per_chunk = (submissions_1 - submissions[2].1) / (chunks(1) - chunks(12));
    assert!(per_chunk > 0);
    for &(k, n) in &submissions {
        assert_eq!(
            n,
            submissions[2].1 + (chunks(u64::from(k)) - 1) * per_chunk,
            "k = {k}: {submissions:?}"
        );
    }
}

#[test]
fn a_fit_that_outgrows_its_entry_capacity_equals_one_that_never_did() {
    let Some(gpu) = common::gpu() else { return };
    let (cams, targets, opts) = small_problem(&gpu);
    let ample = MeshFitOptions {
        log_every: 1,
        ..opts.clone()
    };
    let (params, log, regrowths, _) = run_fit(&gpu, &cams, &targets, &ample);
    assert_eq!(regrowths, 0);
    let entries: Vec<u64> = log.iter().map(|l| l.2).collect();
    // (a) A capacity of 8 entries: the first iteration of the first submission stops.
    // (b) Exactly the first iteration's count: a later iteration that counts more stops in the
    //     middle of a submission, and the iterations after it in that submission are skipped.
    let grows_at = entries
        .iter()
        .position(|&e| e > entries[0])
        .expect("the entry count must grow at some iteration for this test to say anything");
    assert!(grows_at > 0);
    for (capacity, log_every) in [(8, 12), (8, 5), (entries[0], 12), (entries[0], 5)] {
        let tight = MeshFitOptions {
            log_every,
            entry_capacity: Some(capacity),
            ..opts.clone()
        };
        let (params_t, log_t, regrowths_t, _) = run_fit(&gpu, &cams, &targets, &tight);
        let what = format!("capacity {capacity}, {log_every} iterations per submission");
        assert!(regrowths_t >= 1, "{what}: never outgrew its capacity");
        assert_eq!(params_t, params, "{what}: parameters differ");
        for l in &log_t {
            assert_eq!(*l, log[l.0 as usize - 1], "{what}: iteration {}", l.0);
        }
    }
}

#[test]
fn the_iteration_gate_matches_its_twin_and_its_stop_is_sticky() {
    use softvk::gpu::gate::{GATE_SLOTS, IterationGate, cpu};
    let Some(gpu) = common::gpu() else { return };
    let mut gate = IterationGate::new(&gpu).unwrap();
    let grids = [[3, 1, 1], [7, 2, 1], [1, 1, 1]];
    gate.upload(&grids).unwrap();
    let total = gpu.upload_buffer("total", &[0u32]).unwrap();
    let capacity = 100;
    let mut status = [0u32; 4];
    // (reset first?, total, iteration): fits, over, fits but after a stop, reset then fits.
    for (reset, t, it) in [(true, 100, 1), (false, 101, 2), (false, 5, 3), (true, 5, 4)] {
        gpu.write_buffer(&total, 0, &[t]).unwrap();
        gpu.submit_and_wait(|rec| {
            if reset {
                gate.reset();
            }
            gate.record_check(rec, total.whole(), it, capacity)
        })
        .unwrap();
        if reset {
            status = [0; 4];
        }
        let want = cpu::gate(&mut status, t, it, capacity as u32, &grids);
        let (status_buf, args_buf) = gate.buffers();
        let got_status: Vec<u32> = gpu.read_buffer(status_buf, 0, 4).unwrap();
        assert_eq!(got_status, status.to_vec(), "iteration {it}");
        let got: Vec<[u32; 3]> = gpu.read_buffer(args_buf, 0, GATE_SLOTS as usize).unwrap();
        assert_eq!(&got[..grids.len()], want.as_slice(), "iteration {it}");
        assert!(got[grids.len()..].iter().all(|g| *g == [0; 3]));
        let read = gate.read(&gpu).unwrap();
        assert_eq!(
            read.stopped,
            (status[0] != 0).then_some((status[1], u64::from(status[2])))
        );
    }
    assert_eq!(status, [0, 0, 0, 5], "the last check ran after the reset");
}
