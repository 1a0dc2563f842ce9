//! Pose estimation (`fit::pose`, `softvk fit-pose`): the pose chain against central
//! finite differences of the f64 twin's forward, the GPU's pose gradient against the twin's,
//! a small fit that converges, determinism, and the command line (outputs and errors).

mod common;

use common::TempDir;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use glam::DVec3;
use rand::RngExt;
use softvk::camera::Camera;
use softvk::fit::pose::{
    self, Pose, PoseFitOptions, PoseFitter, PoseProblem, PoseTarget, Refine, Schedule, fit_pose,
    rotation_distance,
};
use softvk::fit::session::Session;
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::reference::{self, MeshF64};
use softvk::raster::settings::{ColorMode, RasterSettings};

fn lighting() -> Lighting {
    Lighting {
        ambient_intensity: 0.4,
        ambient_color: [1.0; 3],
        directionals: vec![Directional {
            intensity: 0.6,
            color: [1.0; 3],
            direction: [0.3, 0.8, -0.5],
        }],
    }
}

fn camera() -> Camera {
    Camera::from_angles(2.732, 20.0, -30.0)
}

fn random_colors(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = common::rng(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(0.1..0.95)))
        .collect()
}

/// A box of three different extents with one random colour per triangle (R = 1): no rotation
/// but the identity maps its appearance to itself.
fn colored_box() -> Mesh {
    let mut mesh = Mesh::cuboid([0.5, 0.32, 0.22]);
    mesh.textures = random_colors(mesh.textures.len(), 3);
    mesh
}

/// A jittered icosphere(1) with random vertex colours (vertex colour mode).
fn colored_blob() -> Mesh {
    let mut rng = common::rng(11);
    let mut mesh = Mesh::icosphere(1);
    for p in &mut mesh.positions {
        *p = [
            p[0] * 0.6 + rng.random_range(-0.04..0.04),
            p[1] * 0.45 + rng.random_range(-0.04..0.04),
            p[2] * 0.5 + rng.random_range(-0.04..0.04),
        ];
    }
    mesh.vertex_colors = Some(random_colors(mesh.vertex_count(), 12));
    mesh
}

fn settings(size: u32, mode: ColorMode) -> RasterSettings {
    RasterSettings {
        width: size,
        height: size,
        sigma: 2e-3,
        gamma: 2e-2,
        color_mode: mode,
        ..RasterSettings::default()
    }
}

/// The pose the gradients are taken at, and the one the targets are rendered at.
fn poses() -> (Pose, Pose) {
    (
        Pose {
            rotation: DVec3::new(0.25, -0.45, 0.3),
            translation: DVec3::new(0.04, -0.03, 0.05),
        },
        Pose {
            rotation: DVec3::new(0.1, -0.2, 0.05),
            translation: DVec3::new(0.0, 0.02, -0.03),
        },
    )
}

/// The f64 target: the mesh rendered at the target pose.
fn twin_target(mesh: &MeshF64, centre: DVec3, s: &RasterSettings, at: &Pose) -> Vec<[f64; 4]> {
    reference::render_f64(
        &pose::cpu::posed(mesh, centre, at),
        &camera(),
        &lighting(),
        s,
    )
    .unwrap()
}

fn cases() -> Vec<(&'static str, Mesh, RasterSettings)> {
    vec![
        (
            "textured box",
            colored_box(),
            settings(16, ColorMode::Surface),
        ),
        (
            "vertex-coloured blob",
            colored_blob(),
            settings(16, ColorMode::Vertex),
        ),
    ]
}

/// Largest |a − b| over the largest |b|.
fn rel_err(a: &[f64], b: &[f64]) -> (f64, f64) {
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let err = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    (err / scale.max(1e-300), scale)
}

#[test]
fn pose_gradient_of_the_twin_matches_central_differences_of_its_forward() {
    let (at, target_pose) = poses();
    for (what, mesh, s) in cases() {
        let m = MeshF64::from_mesh(&mesh);
        let centre = pose::centroid(&m.positions);
        let target = twin_target(&m, centre, &s, &target_pose);
        let (loss, analytic) =
            pose::cpu::loss_and_gradient(&m, centre, &camera(), &lighting(), &s, &target, &at)
                .unwrap();
        assert!(loss > 1e-4, "{what}: the pose should not match the target");
        let h = 1e-6;
        let fd: Vec<f64> = (0..6)
            .map(|k| {
                let mut p = at.to_array();
                let f = |p: [f64; 6]| {
                    pose::cpu::loss(
                        &m,
                        centre,
                        &camera(),
                        &lighting(),
                        &s,
                        &target,
                        &Pose::from_array(p),
                    )
                    .unwrap()
                };
                p[k] = at.to_array()[k] + h;
                let up = f(p);
                p[k] = at.to_array()[k] - h;
                (up - f(p)) / (2.0 * h)
            })
            .collect();
        // Rotation and translation separately: each must be non-zero and match.
        for (part, r) in [("rotation", 0..3), ("translation", 3..6)] {
            let (err, scale) = rel_err(&analytic[r.clone()], &fd[r.clone()]);
            eprintln!(
                "{what} {part}: analytic {:?} fd {:?}",
                &analytic[r.clone()],
                &fd[r]
            );
            assert!(scale > 1e-6, "{what}: {part} gradient is ~0");
            assert!(
                err < 1e-5,
                "{what}: {part} differs by {err:.2e} of {scale:.3e}"
            );
        }
    }
}

/// The f64 twin of one evaluation of `mesh` at `at` against its render at `target_pose`: the
/// rotation centre, that target in f32, the loss and the gradient.
fn twin_chain(
    mesh: &Mesh,
    s: &RasterSettings,
    at: &Pose,
    target_pose: &Pose,
) -> (DVec3, Vec<[f32; 4]>, f64, [f64; 6]) {
    let m = MeshF64::from_mesh(mesh);
    let centre = pose::centroid(&m.positions);
    let target = twin_target(&m, centre, s, target_pose);
    let (loss, want) =
        pose::cpu::loss_and_gradient(&m, centre, &camera(), &lighting(), s, &target, at).unwrap();
    let target32 = target.iter().map(|p| p.map(|c| c as f32)).collect();
    (centre, target32, loss, want)
}

#[test]
fn gpu_pose_gradient_equals_the_twin_chain() {
    let Some(gpu) = common::gpu() else { return };
    let (at, target_pose) = poses();
    for (what, mesh, s) in cases() {
        let (centre, target32, loss, want) = twin_chain(&mesh, &s, &at, &target_pose);
        for tile in [8, 16] {
            let mut problem =
                PoseProblem::new(&gpu, &mesh, &camera(), &lighting(), &target32, &s, tile).unwrap();
            assert!(problem.centre().abs_diff_eq(centre, 1e-12));
            let got = problem.evaluate(&gpu, &at, s.sigma, s.gamma).unwrap();
            let (err, scale) = rel_err(&got.gradient, &want);
            eprintln!(
                "{what} tile {tile}: loss {} vs {loss}, gradient error {err:.2e} of {scale:.3e}",
                got.loss
            );
            assert!((got.loss - loss).abs() <= 1e-4 * loss, "{what}: loss");
            assert!(
                err <= 1e-3,
                "{what} tile {tile}: {:?} vs {want:?}",
                got.gradient
            );
        }
    }
}

#[test]
fn a_gpu_fit_iteration_equals_the_twin_chain() {
    // The pose, its lighting, the loss and the chain to (ω, t) all on the GPU in f32
    // (`PoseFitter`), against the f64 twin of the same iteration.
    let Some(gpu) = common::gpu() else { return };
    let (at, target_pose) = poses();
    for (what, mesh, s) in cases() {
        let (centre, target32, loss, want) = twin_chain(&mesh, &s, &at, &target_pose);
        let opts = PoseFitOptions {
            iterations: 1,
            schedule: None,
            settings: s,
            ..PoseFitOptions::default()
        };
        let mut fitter =
            PoseFitter::new(&gpu, &mesh, &camera(), &lighting(), &target32, &at, &opts).unwrap();
        assert!(fitter.centre().abs_diff_eq(centre, 1e-6));
        assert_eq!(fitter.run(1, 1, None).unwrap(), None);
        let log = fitter.log(1, 1, 0.0).unwrap();
        let got = fitter.gradient().unwrap();
        let (err, scale) = rel_err(&got, &want);
        eprintln!(
            "{what}: loss {} vs {loss}, gradient error {err:.2e} of {scale:.3e}",
            log[0].loss
        );
        assert!((log[0].loss - loss).abs() <= 1e-4 * loss, "{what}: loss");
        assert!(err <= 1e-3, "{what}: {got:?} vs {want:?}");
        // The log holds the pose the iteration evaluated (f32 parameters).
        let p = log[0].pose.to_array();
        for (k, a) in at.to_array().iter().enumerate() {
            assert!(
                (p[k] - a).abs() <= 1e-7 * (1.0 + a.abs()),
                "{what}: pose {k}"
            );
        }
    }
}

#[test]
fn k_pose_iterations_per_submission_give_the_bits_of_one_per_submission() {
    let Some(gpu) = common::gpu() else { return };
    let (mesh, target_pose, init, opts) = small_fit();
    let s = opts.settings;
    let target = gpu_target(&gpu, &mesh, &s, &target_pose);
    let fit = |iterations: u32, log_every: u32| {
        let o = PoseFitOptions {
            iterations,
            log_every,
            ..opts.clone()
        };
        let before = gpu.counters().submissions;
        let r = fit_pose(
            &gpu,
            &mesh,
            &camera(),
            &lighting(),
            PoseTarget::Fixed(&target),
            &init,
            &o,
            Session::new(),
        )
        .unwrap();
        let submissions = gpu.counters().submissions - before;
        let log: Vec<(u32, u64, [u64; 6])> = r
            .log
            .iter()
            .map(|l| {
                (
                    l.iteration,
                    l.loss.to_bits(),
                    l.pose.to_array().map(f64::to_bits),
                )
            })
            .collect();
        (r.pose.to_array().map(f64::to_bits), log, submissions)
    };
    // 12 iterations in 3 σ/γ stages of 4: a submission ends at a stage's end or every k.
    let o12 = PoseFitOptions {
        iterations: 12,
        ..opts.clone()
    };
    assert_eq!(o12.sigma_gamma(3), o12.sigma_gamma(0));
    assert_ne!(o12.sigma_gamma(4), o12.sigma_gamma(3));
    let (pose_1, log_1, submissions_1) = fit(12, 1);
    assert_eq!(log_1.len(), 12);
    let mut submissions = vec![(1u64, submissions_1)];
    for k in [2, 4, 12] {
        let (pose_k, log_k, submissions_k) = fit(12, k);
        assert_eq!(pose_k, pose_1, "k = {k}: the pose differs from k = 1");
        assert_eq!(log_k, log_1, "k = {k}: the log differs from k = 1");
        submissions.push((u64::from(k), submissions_k));
    }
    // Submissions grow with the chunks, not with the iterations: chunks of at most k within
    // each stage of 4 (k = 1: 12, 2: 6, 4 and 12: 3 chunks).
    let chunks = |k: u64| 3 * 4u64.div_ceil(k.min(4));
    let per_chunk = (submissions_1 - submissions[3].1) / (chunks(1) - chunks(12));
    assert!(per_chunk > 0);
    for &(k, n) in &submissions {
        assert_eq!(
            n,
            submissions[3].1 + (chunks(k) - chunks(12)) * per_chunk,
            "k = {k}: {submissions:?}"
        );
    }
    assert_eq!(submissions[2].1, submissions[3].1, "{submissions:?}");
}

/// The target of the small fits: the box at `target`, rendered by the GPU at its sharp settings.
fn gpu_target(gpu: &common::Gpu, mesh: &Mesh, s: &RasterSettings, target: &Pose) -> Vec<[f32; 4]> {
    let rest = softvk::lighting::positions_f64(mesh);
    let centre = pose::centroid(&rest);
    let mut posed = mesh.clone();
    for (p, q) in posed.positions.iter_mut().zip(target.apply(&rest, centre)) {
        *p = [q.x as f32, q.y as f32, q.z as f32];
    }
    Renderer::new(gpu)
        .unwrap()
        .render_views(gpu, &posed, &[camera()], &lighting(), s, Method::default())
        .unwrap()
        .images
}

fn small_fit_options(iterations: u32) -> PoseFitOptions {
    PoseFitOptions {
        iterations,
        lr_rotation: 0.05,
        lr_translation: 0.003,
        schedule: Some(Schedule {
            sigma_start: 1e-3,
            gamma_start: 1e-2,
            stages: 3,
        }),
        settings: RasterSettings {
            width: 32,
            height: 32,
            ..RasterSettings::default()
        },
        refine: None,
        ..PoseFitOptions::default()
    }
}

/// The blob at a target pose, a start 25° away about an oblique axis, and the fit's options:
/// 48², 60 iterations.
fn small_fit() -> (Mesh, Pose, Pose, PoseFitOptions) {
    let mesh = colored_blob();
    let target = Pose {
        rotation: DVec3::new(0.3, 0.5, -0.2),
        translation: DVec3::new(0.03, -0.02, 0.0),
    };
    let off =
        glam::DQuat::from_axis_angle(DVec3::new(1.0, 1.0, 0.3).normalize(), 25f64.to_radians());
    let init = Pose {
        rotation: (glam::DQuat::from_scaled_axis(target.rotation) * off).to_scaled_axis(),
        translation: DVec3::ZERO,
    };
    assert!((rotation_distance(init.rotation, target.rotation).to_degrees() - 25.0).abs() < 1e-9);
    let mut opts = small_fit_options(60);
    opts.settings.width = 48;
    opts.settings.height = 48;
    opts.settings.color_mode = ColorMode::Vertex;
    (mesh, target, init, opts)
}

/// Runs a small fit and returns (rotation error °, translation error, first loss, last loss).
fn run_small_fit(
    gpu: &common::Gpu,
    mesh: &Mesh,
    target: &Pose,
    init: &Pose,
    opts: &PoseFitOptions,
    fit_target: PoseTarget<'_>,
) -> (f64, f64, f64, f64) {
    let result = fit_pose(
        gpu,
        mesh,
        &camera(),
        &lighting(),
        fit_target,
        init,
        opts,
        Session::new().on_row(|l: &pose::PoseLog| {
            if std::env::var_os("POSE_DEBUG").is_some() {
                eprintln!(
                    "it {} σ {:.0e} γ {:.0e} loss {:.4e} err {:.3}°",
                    l.iteration,
                    l.sigma,
                    l.gamma,
                    l.loss,
                    rotation_distance(l.pose.rotation, target.rotation).to_degrees()
                );
            }
            true
        }),
    )
    .unwrap();
    assert_eq!(result.iterations, opts.iterations);
    let err = rotation_distance(result.pose.rotation, target.rotation).to_degrees();
    let shift = (result.pose.translation - target.translation).length();
    let first = result.log[0].loss;
    eprintln!(
        "error {err:.3}°, translation {shift:.4}, loss {first:.3e} → {:.3e}",
        result.loss
    );
    (err, shift, first, result.loss)
}

#[test]
fn a_sharp_fit_from_25_degrees_off_ends_within_2_degrees() {
    let Some(gpu) = common::gpu() else { return };
    let (mesh, target, init, mut opts) = small_fit();
    opts.schedule = None;
    let image = gpu_target(&gpu, &mesh, &opts.settings, &target);
    let (err, shift, first, last) = run_small_fit(
        &gpu,
        &mesh,
        &target,
        &init,
        &opts,
        PoseTarget::Fixed(&image),
    );
    assert!(err < 2.0, "ended {err}° from the target");
    assert!(shift < 0.02, "translation off by {shift}");
    assert!(last < 0.05 * first, "loss {first} → {last}");
}

/// The refinement after the schedule: it runs past the schedule's iterations until the loss
/// stops improving (the session's stopping rule holds where it ended, before its maximum), and
/// ends closer than the schedule alone. Of several starts, only the winner is refined.
#[test]
fn refinement_runs_until_the_loss_stops_improving_and_only_the_winner_is_refined() {
    let Some(gpu) = common::gpu() else { return };
    let (mesh, target, init, mut opts) = small_fit();
    opts.iterations = 30;
    let image = gpu_target(&gpu, &mesh, &opts.settings, &target);
    let fit = |opts: &PoseFitOptions| {
        fit_pose(
            &gpu,
            &mesh,
            &camera(),
            &lighting(),
            PoseTarget::Fixed(&image),
            &init,
            opts,
            Session::new(),
        )
        .unwrap()
    };
    let error = |p: &Pose| rotation_distance(p.rotation, target.rotation).to_degrees();
    let plain = fit(&opts);
    assert_eq!(plain.iterations, 30);
    let refined_opts = PoseFitOptions {
        refine: Some(Refine {
            iterations: 300,
            window: 10,
            min_improvement: 1e-2,
        }),
        ..opts.clone()
    };
    let refined = fit(&refined_opts);
    let rule = refined_opts.stop_rule().unwrap();
    assert!(
        refined.iterations > 30 && refined.iterations < refined_opts.last_iteration(),
        "stopped after {} of at most {}",
        refined.iterations,
        refined_opts.last_iteration()
    );
    assert!(rule.stalled(&refined.log), "ended before the rule held");
    // The schedule's iterations are the plain fit's, bit for bit.
    let bits = |l: &[pose::PoseLog]| -> Vec<u64> { l.iter().map(|r| r.loss.to_bits()).collect() };
    assert_eq!(bits(&refined.log[..30]), bits(&plain.log));
    let (before, after) = (error(&plain.pose), error(&refined.pose));
    eprintln!(
        "{before:.3}° after the schedule, {after:.3}° refined in {} iterations",
        refined.iterations
    );
    assert!(after < 0.5 * before, "{before}° → {after}°");
    assert!(
        refined.loss < plain.loss,
        "{} → {}",
        plain.loss,
        refined.loss
    );
    // Two starts: both run the schedule, the winner (the near one) alone is refined.
    let far = Pose {
        rotation: DVec3::new(2.0, -1.0, 0.5),
        ..init
    };
    let multi = pose::fit_pose_multistart(
        &gpu,
        &mesh,
        &camera(),
        &lighting(),
        PoseTarget::Fixed(&image),
        &[far, init],
        &refined_opts,
        |_, _| true,
    )
    .unwrap();
    assert_eq!(multi.best_start, 1);
    assert_eq!(
        multi.starts[0].iterations, 30,
        "the loser ran the schedule only"
    );
    assert_eq!(multi.starts[1].iterations, 30 + refined.iterations);
    assert_eq!(multi.best.pose.to_array(), refined.pose.to_array());
}

#[test]
fn a_scheduled_fit_with_targets_rendered_per_stage_ends_within_2_degrees() {
    let Some(gpu) = common::gpu() else { return };
    let (mesh, target, init, mut opts) = small_fit();
    opts.schedule = Some(Schedule {
        sigma_start: 1e-2,
        gamma_start: 1e-1,
        stages: 3,
    });
    let mut stages = Vec::new();
    let mut render = |sigma: f64, gamma: f64| {
        stages.push((sigma, gamma));
        let s = RasterSettings {
            sigma,
            gamma,
            ..opts.settings
        };
        Ok(gpu_target(&gpu, &mesh, &s, &target))
    };
    let (err, shift, _, _) = run_small_fit(
        &gpu,
        &mesh,
        &target,
        &init,
        &opts,
        PoseTarget::PerStage(&mut render),
    );
    // One target per stage, the last (sharp) one also for the final evaluation.
    assert_eq!(stages.len(), 3, "{stages:?}");
    assert_eq!(stages[2], (opts.settings.sigma, opts.settings.gamma));
    assert!(err < 2.0, "ended {err}° from the target");
    assert!(shift < 0.02, "translation off by {shift}");
}

#[test]
fn spread_rotations_start_at_the_identity_and_cover_the_rotations() {
    let k = 32;
    let q = pose::spread_rotations(k);
    assert_eq!(q.len(), k as usize);
    assert!(q[0].angle_between(glam::DQuat::IDENTITY) < 1e-12);
    assert!(q.iter().all(|p| (p.length() - 1.0).abs() < 1e-12));
    // Every rotation lies within reach of a point: the farthest of 2 000 random rotations from
    // its nearest point, against the same for 32 random points (the negative control, the
    // best of 5 draws).
    let mut rng = common::rng(4);
    let mut random = || loop {
        // Uniform in the 4-ball, then onto the sphere: uniform rotations.
        let v: [f64; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
        let n = v.iter().map(|x| x * x).sum::<f64>();
        if n > 1e-6 && n <= 1.0 {
            break glam::DQuat::from_array(v).normalize();
        }
    };
    let samples: Vec<glam::DQuat> = (0..2000).map(|_| random()).collect();
    let gap = |points: &[glam::DQuat]| {
        samples
            .iter()
            .map(|r| {
                points
                    .iter()
                    .map(|p| p.angle_between(*r))
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0f64, f64::max)
    };
    let spread = gap(&q);
    let best_random = (0..5)
        .map(|_| gap(&(0..k).map(|_| random()).collect::<Vec<_>>()))
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "32 rotations: every sample within {:.1}° of the spread, {:.1}° of random ones",
        spread.to_degrees(),
        best_random.to_degrees()
    );
    assert!(
        spread.to_degrees() < 80.0,
        "a gap of {:.1}°",
        spread.to_degrees()
    );
    assert!(spread < best_random, "no better spread than random points");
    // Starts: the first is the init itself; the others are the spread turned by it.
    let init = Pose {
        rotation: DVec3::new(0.2, -0.4, 0.1),
        translation: DVec3::new(0.01, 0.02, 0.03),
    };
    let starts = pose::spread_starts(&init, 4);
    assert_eq!(starts[0], init);
    for (s, p) in starts.iter().zip(pose::spread_rotations(4)) {
        assert_eq!(s.translation, init.translation);
        let want = init.quaternion() * p;
        assert!(s.quaternion().dot(want).abs() > 1.0 - 1e-12);
    }
}

#[test]
fn screened_starts_recover_a_pose_a_single_far_start_misses() {
    let Some(gpu) = common::gpu() else { return };
    let (mesh, target, _, mut opts) = small_fit();
    opts.schedule = None;
    let image = gpu_target(&gpu, &mesh, &opts.settings, &target);
    // 150° away about an oblique axis.
    let off =
        glam::DQuat::from_axis_angle(DVec3::new(0.2, 1.0, -0.5).normalize(), 150f64.to_radians());
    let init = Pose {
        rotation: (glam::DQuat::from_scaled_axis(target.rotation) * off).to_scaled_axis(),
        translation: DVec3::ZERO,
    };
    let (single, ..) = run_small_fit(
        &gpu,
        &mesh,
        &target,
        &init,
        &opts,
        PoseTarget::Fixed(&image),
    );
    assert!(
        single > 20.0,
        "one start from 150° already succeeds ({single}°)"
    );
    let starts = pose::screened_starts(
        &gpu,
        &mesh,
        &camera(),
        &lighting(),
        &image,
        &init,
        4,
        96,
        30f64.to_radians(),
        &opts,
    )
    .unwrap();
    assert_eq!(starts.len(), 4);
    for (i, a) in starts.iter().enumerate() {
        for b in &starts[..i] {
            assert!(rotation_distance(a.rotation, b.rotation) >= 30f64.to_radians() - 1e-9);
        }
    }
    let fit = |starts: &[Pose], progress: &mut dyn FnMut(usize, &pose::PoseLog) -> bool| {
        pose::fit_pose_multistart(
            &gpu,
            &mesh,
            &camera(),
            &lighting(),
            PoseTarget::Fixed(&image),
            starts,
            &opts,
            progress,
        )
    };
    let mut calls = vec![0; 4];
    let multi = fit(&starts, &mut |k, _| {
        calls[k] += 1;
        true
    })
    .unwrap();
    assert_eq!(multi.starts.len(), 4);
    assert!(
        calls.iter().all(|&c| c == 6),
        "{calls:?}: one call per submission of 10"
    );
    let best = multi
        .starts
        .iter()
        .map(|s| s.loss)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(multi.best.loss, best);
    assert_eq!(multi.starts[multi.best_start].loss, best);
    let err = rotation_distance(multi.best.pose.rotation, target.rotation).to_degrees();
    eprintln!(
        "multi-start: best start {} ends {err:.3}° off",
        multi.best_start
    );
    assert!(err < 2.0, "the best of 4 screened starts ends {err}° off");
    // A stop from the callback ends the start it is in and skips the rest.
    let stopped = fit(&starts, &mut |k, _| k < 1).unwrap();
    assert_eq!(stopped.starts.len(), 2);
    assert!(matches!(
        fit(&[], &mut |_, _| true),
        Err(softvk::Error::Input(_))
    ));
}

#[test]
fn repeated_fits_are_bit_identical() {
    let Some(gpu) = common::gpu() else { return };
    let mesh = colored_box();
    let opts = small_fit_options(6);
    let image = gpu_target(&gpu, &mesh, &opts.settings, &poses().1);
    let init = poses().0;
    let run = || {
        let r = fit_pose(
            &gpu,
            &mesh,
            &camera(),
            &lighting(),
            PoseTarget::Fixed(&image),
            &init,
            &opts,
            Session::new(),
        )
        .unwrap();
        let losses: Vec<u64> = r.log.iter().map(|l| l.loss.to_bits()).collect();
        (r.pose.to_array().map(f64::to_bits), losses, r.image)
    };
    let a = run();
    let b = run();
    assert_eq!(a.0, b.0);
    assert_eq!(a.1, b.1);
    assert!(a.2 == b.2);
}

#[test]
fn bad_inputs_to_the_library_are_errors() {
    let Some(gpu) = common::gpu() else { return };
    let mesh = colored_box();
    let opts = small_fit_options(3);
    let px = 32 * 32;
    let good = vec![[0.0f32; 4]; px];
    let init = Pose::default();
    let fit = |target: &[[f32; 4]], init: &Pose, opts: &PoseFitOptions| {
        fit_pose(
            &gpu,
            &mesh,
            &camera(),
            &lighting(),
            PoseTarget::Fixed(target),
            init,
            opts,
            Session::new(),
        )
    };
    assert!(fit(&good[..px - 1], &init, &opts).is_err(), "short target");
    let mut nan = good.clone();
    nan[5][1] = f32::NAN;
    assert!(fit(&nan, &init, &opts).is_err(), "NaN target");
    let bad_init = Pose {
        rotation: DVec3::new(f64::NAN, 0.0, 0.0),
        ..init
    };
    assert!(fit(&good, &bad_init, &opts).is_err(), "NaN pose");
    for bad in [
        PoseFitOptions {
            iterations: 0,
            ..opts.clone()
        },
        PoseFitOptions {
            lr_rotation: -1.0,
            ..opts.clone()
        },
        PoseFitOptions {
            schedule: Some(Schedule {
                sigma_start: 0.0,
                ..Schedule::default()
            }),
            ..opts.clone()
        },
    ] {
        assert!(fit(&good, &init, &bad).is_err(), "{bad:?}");
    }
}

// The command line.

fn softvk() -> Command {
    let mut c = common::softvk();
    c.env("SOFTVK_VALIDATION", common::validation_env());
    c
}

/// The blob as an OBJ with its vertex colours (`v x y z r g b`).
fn blob_obj(dir: &TempDir) -> PathBuf {
    let mesh = colored_blob();
    let colors = mesh.vertex_colors.clone().unwrap();
    let mut text = String::new();
    for (p, c) in mesh.positions.iter().zip(&colors) {
        text += &format!("v {} {} {} {} {} {}\n", p[0], p[1], p[2], c[0], c[1], c[2]);
    }
    for f in &mesh.faces {
        text += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    let path = dir.path("blob.obj");
    std::fs::write(&path, text).unwrap();
    path
}

const VIEW: [&str; 5] = ["--elevation", "20", "--azimuth", "-30", "--vertex-colors"];

fn fit_cmd(mesh: &Path, target: &Path, out: &Path, args: &[&str]) -> Output {
    softvk()
        .arg("fit-pose")
        .arg("--mesh")
        .arg(mesh)
        .arg("--target")
        .arg(target)
        .arg("--out")
        .arg(out)
        .args(VIEW)
        .args(["--quiet"])
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn fit_pose_writes_the_pose_json_and_both_images() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("cli");
    let mesh = blob_obj(&dir);
    let target = dir.path("target.png");
    let o = softvk()
        .arg("render")
        .arg("--mesh")
        .arg(&mesh)
        .arg("--out")
        .arg(&target)
        .args(["--size", "32"])
        .args(VIEW)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = dir.path("pose.json");
    let o = fit_cmd(
        &mesh,
        &target,
        &out,
        &[
            "--iters",
            "40",
            "--init-rotation",
            "0,12,0",
            "--no-schedule",
            "--lr",
            "0.05",
            "--starts",
            "1",
            "--refine",
            "0",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        dir.entries(),
        [
            "blob.obj",
            "pose-compare.png",
            "pose-error.png",
            "pose-render.png",
            "pose.json",
            "target.png"
        ]
    );
    let json = read_json(&out);
    let omega = json_v3(&json, "rotation_axis_angle");
    let q = json["quaternion_wxyz"].as_array().unwrap();
    let q = glam::DQuat::from_xyzw(
        q[1].as_f64().unwrap(),
        q[2].as_f64().unwrap(),
        q[3].as_f64().unwrap(),
        q[0].as_f64().unwrap(),
    );
    assert!(rotation_distance(q.to_scaled_axis(), omega) < 1e-9);
    let rows = json["rotation_matrix"].as_array().unwrap();
    let r = pose::rotation_matrix(omega);
    for (i, row) in rows.iter().enumerate() {
        for (j, x) in row.as_array().unwrap().iter().enumerate() {
            assert!((x.as_f64().unwrap() - r.row(i)[j]).abs() < 1e-12);
        }
    }
    assert_eq!(json["iterations"].as_u64(), Some(40));
    assert!(json["schedule"].is_null());
    let (loss, initial) = (
        json["loss"].as_f64().unwrap(),
        json["initial_loss"].as_f64().unwrap(),
    );
    assert!(loss < 0.2 * initial, "loss {initial} → {loss}");
    // The target is the rest pose: from 12° off, the fit comes back.
    let err = omega.length().to_degrees();
    eprintln!("fit-pose ended {err:.3}° from the target, loss {initial:.3e} → {loss:.3e}");
    assert!(err < 3.0, "ended {err}° from the rest pose");
    let to_init = json["angle_to_init_degrees"].as_f64().unwrap();
    let want = rotation_distance(omega, DVec3::Y * 12f64.to_radians()).to_degrees();
    assert!((to_init - want).abs() < 1e-9, "{to_init} vs {want}");
    assert!(json_v3(&json, "translation").length() < 0.03);
    for f in ["pose-render.png", "pose-error.png"] {
        let img = image::open(dir.path(f)).unwrap();
        assert_eq!((img.width(), img.height()), (32, 32), "{f}");
    }
    // Target, start and result side by side under their labels (1-pixel gaps): the result
    // panel is the final render, the start panel (12° off) differs from it, and the result is
    // nearer the target than the start.
    let sheet = image::open(dir.path("pose-compare.png")).unwrap().to_rgb8();
    assert_eq!(sheet.width(), 3 * 32 + 4);
    assert!(sheet.height() > 32 + 8, "no room for the labels");
    let panel = |i: u32| -> Vec<f64> {
        let (x0, y0) = (1 + 33 * i, sheet.height() - 33);
        (0..32 * 32)
            .flat_map(|k| sheet.get_pixel(x0 + k % 32, y0 + k / 32).0)
            .map(f64::from)
            .collect()
    };
    let diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>();
    let render = image::open(dir.path("pose-render.png")).unwrap().to_rgba8();
    let result_panel: Vec<f64> = render
        .pixels()
        .flat_map(|p| {
            p.0[..3]
                .iter()
                .map(move |&c| (f64::from(c) * f64::from(p.0[3]) / 255.0).round())
        })
        .collect();
    assert!(
        diff(&panel(2), &result_panel) <= 3.0 * 32.0 * 32.0,
        "result panel"
    );
    let (goal, start, result) = (panel(0), panel(1), panel(2));
    assert!(diff(&start, &result) > 0.0, "start panel equals the result");
    assert!(
        diff(&result, &goal) < 0.5 * diff(&start, &goal),
        "result {} vs start {} from the target",
        diff(&result, &goal),
        diff(&start, &goal)
    );

    // The schedule's flags reach the fit; --render and --error name the images.
    let out2 = dir.path("scheduled.json");
    let (r, e) = (dir.path("r.png"), dir.path("e.png"));
    let o = fit_cmd(
        &mesh,
        &target,
        &out2,
        &[
            "--iters",
            "4",
            "--starts",
            "1",
            "--refine",
            "0",
            "--stages",
            "2",
            "--sigma-start",
            "1e-3",
            "--gamma-start",
            "2e-3",
            "--render",
            r.to_str().unwrap(),
            "--error",
            e.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json = read_json(&out2);
    assert_eq!(json["schedule"]["stages"].as_u64(), Some(2));
    assert_eq!(json["schedule"]["sigma_start"].as_f64(), Some(1e-3));
    assert_eq!(json["schedule"]["gamma_start"].as_f64(), Some(2e-3));
    assert!(r.is_file() && e.is_file());
    assert!(!dir.path("scheduled-render.png").exists());

    // Several starts: every start is listed, and the pose is the one with the lowest loss.
    let out3 = dir.path("multi.json");
    let o = fit_cmd(
        &mesh,
        &target,
        &out3,
        &[
            "--iters",
            "10",
            "--starts",
            "3",
            "--candidates",
            "12",
            "--init-rotation",
            "0,150,0",
            "--no-schedule",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json = read_json(&out3);
    let starts = json["starts"].as_array().unwrap();
    assert_eq!(starts.len(), 3);
    let losses: Vec<f64> = starts.iter().map(|s| s["loss"].as_f64().unwrap()).collect();
    let best = json["best_start"].as_u64().unwrap() as usize;
    assert_eq!(json["loss"].as_f64().unwrap(), losses[best]);
    assert!(losses.iter().all(|&l| l >= losses[best]), "{losses:?}");
    assert_eq!(
        json_v3(&json, "rotation_axis_angle"),
        json_v3(&starts[best], "rotation_axis_angle")
    );
    // By default, 8 screened starts (from 32 × 8 candidates unless told), the winner refined.
    let out4 = dir.path("default.json");
    let o = fit_cmd(
        &mesh,
        &target,
        &out4,
        &[
            "--iters",
            "4",
            "--candidates",
            "16",
            "--init-rotation",
            "0,150,0",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json = read_json(&out4);
    assert_eq!(json["starts"].as_array().unwrap().len(), 8);
    assert!(json["iterations"].as_u64().unwrap() > 4, "refined: {json}");
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn json_v3(json: &serde_json::Value, key: &str) -> DVec3 {
    let a = json[key]
        .as_array()
        .unwrap_or_else(|| panic!("{key}: {json}"));
    DVec3::new(
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    )
}

#[test]
fn fit_pose_errors_are_one_line_and_write_nothing() {
    let dir = TempDir::new("cli-errors");
    let mesh = blob_obj(&dir);
    // An RGBA target of 16×16, and one without alpha.
    let target = dir.path("t.png");
    image::RgbaImage::from_pixel(16, 16, image::Rgba([10, 20, 30, 255]))
        .save(&target)
        .unwrap();
    let rgb = dir.path("rgb.png");
    image::RgbImage::from_pixel(16, 16, image::Rgb([10, 20, 30]))
        .save(&rgb)
        .unwrap();
    let nan = dir.path("nan.obj");
    std::fs::write(
        &nan,
        "v 0 0 0 1 1 1\nv nan 0 0 1 1 1\nv 0 1 0 1 1 1\nf 1 2 3\n",
    )
    .unwrap();
    let empty = dir.path("empty.obj");
    std::fs::write(&empty, "v 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
    let out = dir.path("p.json");
    let before = dir.entries();
    let missing = dir.path("missing.png");
    let cases: Vec<(&str, &Path, &Path, Vec<&str>, &str)> = vec![
        ("missing target", &mesh, &missing, vec![], "missing.png"),
        (
            "size mismatch",
            &mesh,
            &target,
            vec!["--size", "24"],
            "16x16",
        ),
        ("no alpha", &mesh, &rgb, vec![], "alpha"),
        ("NaN vertex", &nan, &target, vec![], "nan.obj"),
        ("no faces", &empty, &target, vec![], "empty.obj"),
        ("bad tile", &mesh, &target, vec!["--tile", "12"], "12"),
        (
            "candidates without starts",
            &mesh,
            &target,
            vec!["--candidates", "8", "--starts", "1"],
            "--starts",
        ),
        (
            "starts with a checkpoint",
            &mesh,
            &target,
            vec!["--starts", "2", "--checkpoint", "ck"],
            "one fit",
        ),
        (
            "zero iterations",
            &mesh,
            &target,
            vec!["--iters", "0"],
            "iteration",
        ),
        (
            "init rotation not a triple",
            &mesh,
            &target,
            vec!["--init-rotation", "1,2"],
            "three",
        ),
        (
            "NaN init translation",
            &mesh,
            &target,
            vec!["--init-translation", "0,nan,0"],
            "finite",
        ),
        (
            "schedule flags without a schedule",
            &mesh,
            &target,
            vec!["--no-schedule", "--sigma-start", "1e-2"],
            "--sigma-start",
        ),
        (
            "render path is not a PNG",
            &mesh,
            &target,
            vec!["--render", "r.exr"],
            "r.exr",
        ),
    ];
    for (what, m, t, args, needle) in cases {
        let o = fit_cmd(m, t, &out, &args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{what}: succeeded");
        assert_eq!(stderr.lines().count(), 1, "{what}: {stderr}");
        assert!(stderr.starts_with("softvk: error: "), "{what}: {stderr}");
        assert!(
            stderr.contains(needle),
            "{what}: `{needle}` not in {stderr}"
        );
        assert!(o.stdout.is_empty(), "{what}: printed on stdout");
        assert_eq!(dir.entries(), before, "{what}: wrote something");
    }
}
