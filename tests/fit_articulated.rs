//! Non-rigid pose estimation (`fit::rig`, `fit::articulated`, `softvk fit-articulated`): the
//! angle chain of the f64 twin against central finite differences of its forward,
//! the GPU's skinning and angle gradient against the twin's, a fit that recovers every joint
//! angle from a start at least 20° off on each, determinism, and the command line.

mod common;

use common::TempDir;

use std::path::Path;
use std::process::Command;

use softvk::camera::Camera;
use softvk::fit::articulated::{
    self, ArticulatedFit, ArticulatedFitOptions, ArticulatedFitter, fit_articulated,
};
use softvk::fit::checkpoint::FitKind;
use softvk::fit::pose::{PoseTarget, Schedule};
use softvk::fit::rig::Rig;
use softvk::fit::session::{CheckpointPlan, Progress, Resume, Session};
use softvk::lighting::Lighting;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::{ColorMode, RasterSettings};

fn camera() -> Camera {
    Camera::default()
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

/// Angles (radians) from degrees.
fn rad(deg: &[f64]) -> Vec<f64> {
    deg.iter().map(|d| d.to_radians()).collect()
}

/// A target pose of the figure and a start off by 20–28° on every joint, alternating signs.
fn poses() -> (Vec<f64>, Vec<f64>) {
    let target = rad(&[8.0, -15.0, 20.0, 12.0, -18.0, 10.0, -12.0, -8.0, 15.0]);
    let start = target
        .iter()
        .enumerate()
        .map(|(j, t)| {
            let off = (20.0 + j as f64).to_radians();
            if j % 2 == 0 { t + off } else { t - off }
        })
        .collect();
    (target, start)
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
fn angle_gradient_of_the_twin_matches_central_differences_of_its_forward() {
    let rig = Rig::figure();
    let (target_angles, at) = poses();
    for (mode, blur) in [
        (ColorMode::Surface, 0.0),
        (ColorMode::Vertex, 0.0),
        (ColorMode::Vertex, 2.0),
    ] {
        let s = settings(24, mode);
        let lighting = Lighting::default();
        let target =
            articulated::cpu::render(&rig, &camera(), &lighting, &s, &target_angles).unwrap();
        let (loss, analytic) =
            articulated::cpu::loss_and_gradient(&rig, &camera(), &lighting, &s, &target, &at, blur)
                .unwrap();
        assert!(
            loss > 1e-4,
            "{mode:?}: the start should not match the target"
        );
        let h = 1e-6;
        let fd: Vec<f64> = (0..at.len())
            .map(|k| {
                let f = |x: f64| {
                    let mut a = at.clone();
                    a[k] = x;
                    articulated::cpu::loss(&rig, &camera(), &lighting, &s, &target, &a, blur)
                        .unwrap()
                };
                (f(at[k] + h) - f(at[k] - h)) / (2.0 * h)
            })
            .collect();
        let (err, scale) = rel_err(&analytic, &fd);
        eprintln!("{mode:?}: analytic {analytic:?}\n fd {fd:?}");
        assert!(
            analytic.iter().all(|g| g.abs() > 1e-3 * scale),
            "every joint should feel the loss"
        );
        assert!(err < 1e-5, "{mode:?}: differs by {err:.2e} of {scale:.3e}");
    }
}

#[test]
fn a_gpu_fit_iteration_equals_the_twin_chain() {
    // Forward kinematics, skinning, lighting, loss and the chain to the angles all on the GPU in
    // f32 (`ArticulatedFitter`), against the f64 twin of the same iteration.
    let Some(gpu) = common::gpu() else { return };
    let rig = Rig::figure();
    let (target_angles, at) = poses();
    let lighting = Lighting::default();
    for (mode, blur) in [
        (ColorMode::Surface, 0.0),
        (ColorMode::Vertex, 0.0),
        (ColorMode::Surface, 2.0),
    ] {
        let s = settings(24, mode);
        let target =
            articulated::cpu::render(&rig, &camera(), &lighting, &s, &target_angles).unwrap();
        let (loss, want) =
            articulated::cpu::loss_and_gradient(&rig, &camera(), &lighting, &s, &target, &at, blur)
                .unwrap();
        let target32: Vec<[f32; 4]> = target.iter().map(|p| p.map(|c| c as f32)).collect();
        for tile in [8, 16] {
            let opts = ArticulatedFitOptions {
                iterations: 1,
                schedule: None,
                blur: Some(articulated::BlurSchedule {
                    start: blur,
                    stages: 1,
                }),
                settings: s,
                tile,
                ..ArticulatedFitOptions::default()
            };
            let mut fitter =
                ArticulatedFitter::new(&gpu, &rig, &camera(), &lighting, &target32, &at, &opts)
                    .unwrap();
            assert_eq!(fitter.run(1, 1, None).unwrap(), None);
            // The skinned positions of the iteration against the twin's.
            let posed = fitter.posed_positions().unwrap();
            let twin = rig.skin(&at);
            let worst = posed
                .iter()
                .zip(&twin)
                .map(|(p, q)| {
                    (0..3)
                        .map(|k| (f64::from(p[k]) - q[k]).abs())
                        .fold(0.0, f64::max)
                })
                .fold(0.0, f64::max);
            assert!(
                worst < 2e-6,
                "{mode:?}: skinned positions differ by {worst:.2e}"
            );
            let log = fitter.log(1, 1, 0.0).unwrap();
            let got = fitter.gradient().unwrap();
            let (err, scale) = rel_err(&got, &want);
            eprintln!(
                "{mode:?} tile {tile}: loss {} vs {loss}, gradient error {err:.2e} of {scale:.3e}",
                log[0].loss
            );
            assert!((log[0].loss - loss).abs() <= 1e-4 * loss, "{mode:?}: loss");
            assert!(err <= 1e-3, "{mode:?} tile {tile}: {got:?} vs {want:?}");
            // The log holds the angles the iteration evaluated (f32).
            for (a, b) in log[0].angles.iter().zip(&at) {
                assert!((a - b).abs() <= 1e-7 * (1.0 + b.abs()));
            }
            // And the step moved every angle against its gradient.
            let after = fitter.angles().unwrap();
            for j in 0..at.len() {
                assert!(
                    (after[j] - at[j]) * want[j] < 0.0,
                    "joint {j}: {} → {} with gradient {}",
                    at[j],
                    after[j],
                    want[j]
                );
            }
        }
    }
}

fn gpu_render(gpu: &common::Gpu, rig: &Rig, s: &RasterSettings, angles: &[f64]) -> Vec<[f32; 4]> {
    Renderer::new(gpu)
        .unwrap()
        .render_views(
            gpu,
            &rig.posed_mesh(angles),
            &[camera()],
            &Lighting::default(),
            s,
            Method::Tiled { tile: 8 },
        )
        .unwrap()
        .images
}

#[test]
fn a_fit_from_20_degrees_off_on_every_joint_recovers_every_angle_within_2_degrees() {
    // The target rendered from known angles at each stage's σ/γ with that case's defaults (as
    // `fit-articulated --target-angles` does): every joint starts 20–28° off, alternating signs.
    let Some(gpu) = common::gpu() else { return };
    let rig = Rig::figure();
    let (target_angles, start) = poses();
    let opts = ArticulatedFitOptions::for_rendered_target();
    let mut per_stage = |sigma, gamma| {
        let s = RasterSettings {
            sigma,
            gamma,
            ..opts.settings
        };
        Ok(gpu_render(&gpu, &rig, &s, &target_angles))
    };
    let mut calls = 0;
    let r = fit_articulated(
        &gpu,
        &rig,
        &camera(),
        &Lighting::default(),
        PoseTarget::PerStage(&mut per_stage),
        &start,
        &opts,
        Session::new().hooks(|_: &Progress<'_, '_, ArticulatedFit<'_>>| {
            calls += 1;
            Ok(true)
        }),
    )
    .unwrap();
    let errors: Vec<f64> = r
        .angles
        .iter()
        .zip(&target_angles)
        .map(|(a, b)| (a - b).to_degrees())
        .collect();
    eprintln!(
        "errors {errors:?}, loss {:.3e} → {:.3e}",
        r.log[0].loss, r.loss
    );
    assert_eq!(r.iterations, opts.iterations);
    assert_eq!(r.log.len(), opts.iterations as usize);
    assert!(calls >= (opts.iterations / opts.log_every) as usize);
    for (j, e) in errors.iter().enumerate() {
        assert!(
            e.abs() <= 2.0,
            "joint {} off by {e:.2}°",
            rig.joints[j].name
        );
    }
    // The log's first row holds the start; the loss fell.
    for (a, b) in r.log[0].angles.iter().zip(&start) {
        assert!((a - b).abs() < 1e-6);
    }
    assert!(r.loss < 0.05 * r.log[0].loss);
    // The stages: the blur falls to 0 and σ to the sharp value by the last iteration.
    let last = r.log.last().unwrap();
    assert_eq!((last.blur, last.sigma), (0.0, opts.settings.sigma));
    assert!(r.log[0].blur > 0.0 && r.log[0].sigma > opts.settings.sigma);
}

#[test]
fn repeated_fits_are_bit_identical_stop_when_asked_and_resume_to_the_same_bits() {
    let Some(gpu) = common::gpu() else { return };
    let rig = Rig::figure();
    let (target_angles, start) = poses();
    let opts = ArticulatedFitOptions {
        iterations: 12,
        log_every: 4,
        settings: settings(32, ColorMode::Surface),
        ..ArticulatedFitOptions::default()
    };
    let target = gpu_render(&gpu, &rig, &opts.settings, &target_angles);
    let fit = |session| {
        fit_articulated(
            &gpu,
            &rig,
            &camera(),
            &Lighting::default(),
            PoseTarget::Fixed(&target),
            &start,
            &opts,
            session,
        )
        .unwrap()
    };
    let (a, b) = (fit(Session::new()), fit(Session::new()));
    assert_eq!(a.angles, b.angles);
    // Every logged loss and angle too (the seconds differ).
    let rows = |r: &articulated::ArticulatedFitResult| -> Vec<(u32, u64, Vec<u64>)> {
        r.log
            .iter()
            .map(|l| {
                let angles = l.angles.iter().map(|a| a.to_bits()).collect();
                (l.iteration, l.loss.to_bits(), angles)
            })
            .collect()
    };
    assert_eq!(rows(&a), rows(&b));
    assert_ne!(a.angles, start);
    // Stopped by its hooks after iteration 4, with a checkpoint written there.
    let dir = TempDir::new("articulated-resume");
    let path = dir.path("a.ckpt");
    let fp = ArticulatedFit::fingerprint(
        &rig,
        &camera(),
        &Lighting::default(),
        &target,
        &start,
        &opts,
    );
    let stopped = fit(Session::new()
        .checkpoint(Some(CheckpointPlan {
            path: path.clone(),
            fingerprint: fp,
            every: 100,
        }))
        .hooks(|p: &Progress<'_, '_, ArticulatedFit<'_>>| Ok(p.last < 4)));
    assert_eq!(stopped.iterations, 4);
    assert_eq!(stopped.log.len(), 4);
    // Resumed from it (inside the first of four stages of three iterations: across the stage
    // changes), it runs only the rest and ends bit for bit as the fit that never stopped.
    let resume = Resume::read(&path, FitKind::Articulated, fp).unwrap();
    assert_eq!(resume.iteration, 4);
    let mut logged = Vec::new();
    let resumed = fit(Session::new().resume(Some(resume)).hooks(
        |p: &Progress<'_, '_, ArticulatedFit<'_>>| {
            logged.push(p.last);
            Ok(true)
        },
    ));
    assert_eq!(
        logged,
        [6, 8, 9, 12],
        "submissions end at logs and stage ends"
    );
    assert_eq!(resumed.iterations, 12);
    assert_eq!(
        a.angles.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        resumed
            .angles
            .iter()
            .map(|x| x.to_bits())
            .collect::<Vec<_>>()
    );
    assert_eq!(a.loss.to_bits(), resumed.loss.to_bits());
    assert_eq!(rows(&a), rows(&resumed));
    // Another start is another fit's checkpoint.
    let e = Resume::<articulated::ArticulatedLog>::read(&path, FitKind::Articulated, fp ^ 1)
        .unwrap_err()
        .to_string();
    assert!(e.contains("another fit"), "{e}");
}

#[test]
fn bad_inputs_to_the_library_are_errors() {
    let Some(gpu) = common::gpu() else { return };
    let rig = Rig::figure();
    let (_, start) = poses();
    let opts = ArticulatedFitOptions {
        iterations: 2,
        settings: settings(16, ColorMode::Surface),
        ..ArticulatedFitOptions::default()
    };
    let target = vec![[0.0f32; 4]; 16 * 16];
    let fit = |rig: &Rig, init: &[f64], target: &[[f32; 4]], opts: &ArticulatedFitOptions| {
        ArticulatedFitter::new(
            &gpu,
            rig,
            &camera(),
            &Lighting::default(),
            target,
            init,
            opts,
        )
        .map(|_| ())
    };
    fit(&rig, &start, &target, &opts).unwrap();
    assert!(
        fit(&rig, &start[1..], &target, &opts).is_err(),
        "too few angles"
    );
    let mut nan = start.clone();
    nan[3] = f64::NAN;
    assert!(fit(&rig, &nan, &target, &opts).is_err(), "NaN angle");
    assert!(
        fit(&rig, &start, &target[1..], &opts).is_err(),
        "short target"
    );
    let mut bad_target = target.clone();
    bad_target[5][1] = f32::INFINITY;
    assert!(
        fit(&rig, &start, &bad_target, &opts).is_err(),
        "non-finite target"
    );
    let mut bad_rig = rig.clone();
    bad_rig.skin[0].weights = [0.5, 0.0, 0.0, 0.0];
    assert!(fit(&bad_rig, &start, &target, &opts).is_err(), "weights");
    for bad in [
        ArticulatedFitOptions {
            iterations: 0,
            ..opts.clone()
        },
        ArticulatedFitOptions {
            lr: -1.0,
            ..opts.clone()
        },
        ArticulatedFitOptions {
            blur: Some(articulated::BlurSchedule {
                start: 100.0,
                stages: 2,
            }),
            ..opts.clone()
        },
        ArticulatedFitOptions {
            schedule: Some(Schedule {
                sigma_start: 0.0,
                gamma_start: 1e-3,
                stages: 2,
            }),
            ..opts.clone()
        },
        ArticulatedFitOptions {
            tile: 12,
            ..opts.clone()
        },
    ] {
        assert!(fit(&rig, &start, &target, &bad).is_err(), "{bad:?}");
    }
}

// The command line.

fn softvk() -> Command {
    let mut c = common::softvk();
    c.env("SOFTVK_VALIDATION", common::validation_env());
    c
}

fn degrees(angles: &[f64]) -> String {
    angles
        .iter()
        .map(|a| format!("{}", a.to_degrees()))
        .collect::<Vec<_>>()
        .join(",")
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn joint_angles(json: &serde_json::Value) -> Vec<f64> {
    json["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j["angle_degrees"].as_f64().unwrap())
        .collect()
}

#[test]
fn fit_articulated_writes_the_angles_the_images_and_the_posed_mesh() {
    if common::no_gpu() {
        return;
    }
    let dir = TempDir::new("fit-articulated");
    let (target_angles, start) = poses();
    let out = dir.path("a.json");
    let o = softvk()
        .args(["fit-articulated", "--quiet", "--target-angles"])
        .arg(degrees(&target_angles))
        .arg("--init-angles")
        .arg(degrees(&start))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json = read_json(&out);
    let joints = json["joints"].as_array().unwrap();
    assert_eq!(joints.len(), 9);
    assert_eq!(joints[2]["name"], "l_elbow");
    for (j, t) in joints.iter().zip(&target_angles) {
        assert!((j["target_degrees"].as_f64().unwrap() - t.to_degrees()).abs() < 1e-9);
        let e = j["error_degrees"].as_f64().unwrap();
        assert!(e.abs() <= 2.0, "{j}");
        assert!(
            (j["angle_degrees"].as_f64().unwrap() - t.to_degrees() - e).abs() < 1e-9,
            "{j}"
        );
    }
    assert!(json["worst_error_degrees"].as_f64().unwrap() <= 2.0);
    assert_eq!(json["iterations"], 240);
    // (The initial loss is of blurred images, the final one sharp: both shown, not compared.)
    assert!(json["loss"].as_f64().unwrap() < 1e-3);
    let render = image::open(dir.path("a-render.png")).unwrap();
    assert_eq!((render.width(), render.height()), (64, 64));
    let compare = image::open(dir.path("a-compare.png")).unwrap();
    assert!(compare.width() >= 3 * 64);
    // The posed mesh reads back with the figure's faces and the fitted pose's positions.
    let mesh = softvk::mesh::Mesh::load_obj(&dir.path("a-posed.obj"), 1).unwrap();
    let rig = Rig::figure();
    assert_eq!(mesh.faces, rig.mesh.faces);
    let want = rig.skin(
        &joint_angles(&json)
            .iter()
            .map(|d| d.to_radians())
            .collect::<Vec<_>>(),
    );
    for (p, q) in mesh.positions.iter().zip(&want) {
        assert!((0..3).all(|k| (f64::from(p[k]) - q[k]).abs() < 1e-5));
    }

    // The fitted render as an image target (8-bit, fixed: no re-rendering per stage): a fit
    // from 10° off on every joint closes the gap on all but the forearms, which a fixed sharp
    // target leaves in local minima 2.5° and 7° off (RESULTS.md, "Non-rigid pose"); none
    // diverges.
    let out2 = dir.path("b.json");
    let fitted = joint_angles(&json);
    let init: Vec<f64> = fitted
        .iter()
        .enumerate()
        .map(|(j, a)| (a + if j % 2 == 0 { 10.0 } else { -10.0 }).to_radians())
        .collect();
    let o = softvk()
        .args(["fit-articulated", "--quiet", "--target"])
        .arg(dir.path("a-render.png"))
        .arg("--init-angles")
        .arg(degrees(&init))
        .arg("--out")
        .arg(&out2)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json2 = read_json(&out2);
    assert_eq!(json2["target"], "image");
    assert!(json2.get("worst_error_degrees").is_none());
    let errors: Vec<f64> = joint_angles(&json2)
        .iter()
        .zip(&fitted)
        .map(|(a, b)| (a - b).abs())
        .collect();
    assert!(errors.iter().all(|e| *e < 8.0), "{errors:?}");
    assert!(
        errors.iter().filter(|e| **e < 2.0).count() >= 7,
        "{errors:?}"
    );
}

#[test]
fn fit_articulated_errors_are_one_line_and_write_nothing() {
    let dir = TempDir::new("fit-articulated-errors");
    let target = dir.path("t.png");
    image::RgbaImage::from_pixel(16, 16, image::Rgba([10, 20, 30, 255]))
        .save(&target)
        .unwrap();
    let rgb = dir.path("rgb.png");
    image::RgbImage::from_pixel(16, 16, image::Rgb([10, 20, 30]))
        .save(&rgb)
        .unwrap();
    let nine = "0,0,0,0,0,0,0,0,0";
    let t = target.to_str().unwrap();
    let cases: Vec<(&str, Vec<&str>, &str)> = vec![
        ("no target", vec![], "--target"),
        (
            "both targets",
            vec!["--target", t, "--target-angles", nine],
            "--target",
        ),
        (
            "missing target",
            vec!["--target", "missing.png"],
            "missing.png",
        ),
        ("no alpha", vec!["--target", rgb.to_str().unwrap()], "alpha"),
        (
            "size mismatch",
            vec!["--target", t, "--size", "24"],
            "16x16",
        ),
        (
            "eight angles",
            vec!["--target-angles", "0,0,0,0,0,0,0,0"],
            "9 joints",
        ),
        (
            "NaN angle",
            vec!["--target-angles", "0,0,0,nan,0,0,0,0,0"],
            "finite",
        ),
        (
            "bad init",
            vec!["--target", t, "--init-angles", "1,2"],
            "--init-angles",
        ),
        ("zero iterations", vec!["--target", t, "--iters", "0"], "0"),
        ("bad tile", vec!["--target", t, "--tile", "12"], "12"),
        (
            "blur too wide",
            vec!["--target", t, "--blur", "100"],
            "blur",
        ),
        ("negative blur", vec!["--target", t, "--blur", "-1"], "-1"),
        (
            "render not a PNG",
            vec!["--target", t, "--render", "r.exr"],
            "r.exr",
        ),
        (
            "schedule flags without a schedule",
            vec!["--target", t, "--no-schedule", "--sigma-start", "1e-2"],
            "--sigma-start",
        ),
    ];
    let before = dir.entries();
    for (what, args, needle) in cases {
        let o = softvk()
            .current_dir(dir.path(""))
            .args(["fit-articulated", "--quiet", "--out"])
            .arg(dir.path("a.json"))
            .args(&args)
            .output()
            .unwrap();
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
