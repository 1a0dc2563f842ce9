//! Checkpoints and resume: a mesh fit stopped at a checkpoint and resumed ends bit
//! for bit as the fit that never stopped, in the library and through `softvk fit-mesh`
//! (`--checkpoint`, `--resume`, also after a real Ctrl-C); checkpoints of other inputs, other
//! kinds or no checkpoint at all are refused with one clear error.

mod common;

use std::path::Path;
use std::time::Duration;

use common::{TempDir, softvk};
use softvk::camera::Camera;
use softvk::fit::checkpoint::{Checkpoint, Fingerprint, FitKind};
use softvk::fit::mesh_fit::{
    FitLog, MeshFitOptions, MeshFitResult, MeshFitState, fit_mesh, fit_mesh_resumable,
    icosphere_template,
};
use softvk::io::CameraRow;
use softvk::mesh::Mesh;
use softvk::raster::settings::RasterSettings;

const SIZE: u32 = 16;

fn rows() -> Vec<CameraRow> {
    common::disc_camera_rows()
}

fn masks() -> Vec<f32> {
    common::disc_masks(SIZE)
}

fn options(iterations: u32) -> MeshFitOptions {
    MeshFitOptions {
        iterations,
        log_every: 2,
        settings: RasterSettings {
            width: SIZE,
            height: SIZE,
            ..MeshFitOptions::default().settings
        },
        ..MeshFitOptions::default()
    }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// The log without its wall times.
fn losses(log: &[FitLog]) -> Vec<(u32, u32, u32, u32, u32, u64)> {
    log.iter()
        .map(|l| {
            (
                l.iteration,
                l.silhouette.to_bits(),
                l.laplacian.to_bits(),
                l.flatten.to_bits(),
                l.total.to_bits(),
                l.entries,
            )
        })
        .collect()
}

fn assert_same_fit(what: &str, a: &MeshFitResult, b: &MeshFitResult) {
    assert_eq!(bits(&a.params), bits(&b.params), "{what}: parameters");
    let pos = |m: &Mesh| {
        m.positions
            .iter()
            .flatten()
            .map(|x| x.to_bits())
            .collect::<Vec<_>>()
    };
    assert_eq!(pos(&a.mesh), pos(&b.mesh), "{what}: positions");
    assert_eq!(losses(&a.log), losses(&b.log), "{what}: logged losses");
}

#[test]
fn a_mesh_fit_resumed_from_any_checkpoint_ends_bit_for_bit_as_the_uninterrupted_fit() {
    let Some(gpu) = common::gpu() else { return };
    let template = icosphere_template();
    let cams: Vec<Camera> = rows().iter().map(CameraRow::camera).collect();
    let targets = masks();
    let whole = fit_mesh(&gpu, &template, &cams, &targets, &options(8), |_, _, _| {
        true
    })
    .unwrap();
    let dir = TempDir::new("ckpt-lib");
    let fingerprint = MeshFitState::fingerprint(&template, &cams, &targets, &options(8));
    for stop in [2u32, 4, 6] {
        // Run to `stop`, take the state there (through a file, as the CLI does), resume.
        let mut state = None;
        fit_mesh_resumable(
            &gpu,
            &template,
            &cams,
            &targets,
            &options(8),
            None,
            |l, _, _, snapshot| {
                if l.iteration == stop {
                    state = Some(snapshot.state()?);
                    return Ok(false);
                }
                Ok(true)
            },
        )
        .unwrap();
        let state = state.unwrap();
        assert_eq!(state.iteration, stop);
        let path = dir.path(&format!("at-{stop}.ckpt"));
        state.to_checkpoint(fingerprint).write(&path).unwrap();
        let read = Checkpoint::read(&path, FitKind::Mesh, fingerprint).unwrap();
        let back = MeshFitState::from_checkpoint(&read, &template).unwrap();
        assert_eq!(back, state, "the checkpoint file round trip");
        // The resumed fit runs only the iterations after the checkpoint's (a fit that started
        // again from 1 would end the same, deterministic as it is, but not log these).
        let mut logged = Vec::new();
        let resumed = fit_mesh_resumable(
            &gpu,
            &template,
            &cams,
            &targets,
            &options(8),
            Some(&back),
            |l, _, _, _| {
                logged.push(l.iteration);
                Ok(true)
            },
        )
        .unwrap();
        assert_eq!(resumed.first_iteration, stop + 1);
        // Logged every 2: the submissions after the checkpoint, not from 1.
        let rest: Vec<u32> = (stop + 2..=8).step_by(2).collect();
        assert_eq!(logged, rest, "stopped at {stop}");
        assert_same_fit(&format!("stopped at {stop}"), &whole, &resumed);
    }
}

#[test]
fn foreign_or_broken_checkpoints_are_refused_with_one_line() {
    let template = icosphere_template();
    let cams: Vec<Camera> = rows().iter().map(CameraRow::camera).collect();
    let targets = masks();
    let fp = MeshFitState::fingerprint(&template, &cams, &targets, &options(8));
    // Only the iteration count and the logging may differ.
    assert_eq!(
        fp,
        MeshFitState::fingerprint(&template, &cams, &targets, &options(3000))
    );
    let mut other = targets.clone();
    other[5] = 1.0 - other[5];
    assert_ne!(
        fp,
        MeshFitState::fingerprint(&template, &cams, &other, &options(8))
    );
    let dir = TempDir::new("ckpt-bad");
    let n = 3 * template.vertex_count() + 3;
    let state = MeshFitState {
        iteration: 2,
        params: vec![0.5; n],
        adam_m: vec![0.25; n],
        adam_v: vec![0.125; n],
        log: Vec::new(),
        seconds: 1.0,
    };
    let path = dir.path("c.ckpt");
    state.to_checkpoint(fp).write(&path).unwrap();
    let refused = |path: &Path, kind: FitKind, fp: u64, needle: &str| {
        let e = Checkpoint::read(path, kind, fp)
            .err()
            .unwrap_or_else(|| panic!("{needle}: accepted"))
            .to_string();
        assert!(e.contains(needle) && !e.contains('\n'), "{needle}: {e}");
    };
    refused(&path, FitKind::Mesh, fp ^ 1, "another fit");
    let bytes = std::fs::read(&path).unwrap();
    let garbage = dir.path("garbage.ckpt");
    std::fs::write(&garbage, b"P6 not a checkpoint").unwrap();
    refused(&garbage, FitKind::Mesh, fp, "not a softvk checkpoint");
    let short = dir.path("short.ckpt");
    std::fs::write(&short, &bytes[..20]).unwrap();
    refused(&short, FitKind::Mesh, fp, "truncated");
    // Any damaged byte: the checksum (the last 8 bytes) refuses the file.
    let mut damaged = bytes.clone();
    damaged[bytes.len() / 2] ^= 0x10;
    let d = dir.path("damaged.ckpt");
    std::fs::write(&d, &damaged).unwrap();
    refused(&d, FitKind::Mesh, fp, "damaged");
    // The checks behind the checksum, on files resealed with a right one.
    let body = &bytes[..bytes.len() - 8];
    let sealed = |body: &[u8]| {
        let mut b = body.to_vec();
        b.extend(Fingerprint::default().add(body).value().to_le_bytes());
        b
    };
    assert_eq!(sealed(body), bytes, "the checksum is FNV-1a of the rest");
    let mut version = body.to_vec();
    version[16] ^= 0x01; // a byte of the version string
    let v = dir.path("version.ckpt");
    std::fs::write(&v, sealed(&version)).unwrap();
    refused(&v, FitKind::Mesh, fp, "written by softvk");
    refused(&dir.path("missing.ckpt"), FitKind::Mesh, fp, "missing.ckpt");
    // A payload cut short after a valid header.
    let cut = dir.path("cut.ckpt");
    std::fs::write(&cut, sealed(&body[..body.len() - 9])).unwrap();
    let c = Checkpoint::read(&cut, FitKind::Mesh, fp).unwrap();
    let e = MeshFitState::from_checkpoint(&c, &template)
        .unwrap_err()
        .to_string();
    assert!(e.contains("truncated"), "{e}");
    // A state of another template size.
    let c = Checkpoint::read(&path, FitKind::Mesh, fp).unwrap();
    let e = MeshFitState::from_checkpoint(&c, &Mesh::icosphere(1))
        .unwrap_err()
        .to_string();
    assert!(e.contains("parameters") || e.contains("at most"), "{e}");
}

fn fit_cmd(sil: &Path, cams: &Path, out: &Path, args: &[&str]) -> std::process::Command {
    let mut cmd = softvk();
    cmd.args([
        "fit-mesh",
        "--log-every",
        "2",
        "--quiet",
        "--template",
        "icosphere",
    ])
    .arg("--silhouettes")
    .arg(sil)
    .arg("--cameras")
    .arg(cams)
    .arg("--out")
    .arg(out)
    .args(args);
    cmd
}

fn run(what: &str, mut cmd: std::process::Command) {
    let o = cmd.output().unwrap();
    assert!(
        o.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn fit_mesh_checkpoints_and_resumes_to_the_same_bytes_even_after_ctrl_c() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("ckpt-cli");
    let (sil, cams) = common::write_disc_inputs(&dir, SIZE);
    let whole = dir.path("whole.obj");
    run("whole", fit_cmd(&sil, &cams, &whole, &["--iters", "10"]));

    // Stopped by its iteration count at 6, with a checkpoint every 4 (and at the end), resumed.
    let ck = dir.path("ck");
    let part = dir.path("part.obj");
    let ck_arg = ck.to_str().unwrap();
    run(
        "first part",
        fit_cmd(
            &sil,
            &cams,
            &part,
            &[
                "--iters",
                "6",
                "--checkpoint",
                ck_arg,
                "--checkpoint-every",
                "4",
            ],
        ),
    );
    run(
        "resumed",
        fit_cmd(&sil, &cams, &part, &["--iters", "10", "--resume", ck_arg]),
    );
    assert_eq!(
        std::fs::read(&whole).unwrap(),
        std::fs::read(&part).unwrap(),
        "resumed at 6"
    );

    // Interrupted by a real Ctrl-C (its checkpoint is written as it stops), resumed. The run
    // asks for far more iterations than it gets: the signal goes once its first checkpoint
    // (every 2 iterations) is on disk, so it always lands mid-fit, however fast the device.
    let ck2 = dir.path("ck2");
    let ck2_arg = ck2.to_str().unwrap();
    let long = dir.path("long.obj");
    let whole_long = dir.path("whole-long.obj");
    run(
        "whole, longer",
        fit_cmd(&sil, &cams, &whole_long, &["--iters", "400"]),
    );
    let mut child = fit_cmd(
        &sil,
        &cams,
        &long,
        &[
            "--iters",
            "1000000",
            "--checkpoint",
            ck2_arg,
            "--checkpoint-every",
            "2",
        ],
    )
    .stdout(std::process::Stdio::null())
    .stderr(std::process::Stdio::null())
    .spawn()
    .unwrap();
    let saved = ck2.join("mesh-fit.ckpt");
    let start = std::time::Instant::now();
    while !saved.is_file() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the fit ended before its first checkpoint"
        );
        assert!(start.elapsed() < Duration::from_secs(120), "no checkpoint");
        std::thread::sleep(Duration::from_millis(20));
    }
    // SAFETY: kill(2) on our own child's pid.
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    let note = dir.path("long-report").join("interrupted.txt");
    assert!(note.is_file(), "the interrupted run's report says so");
    let o = fit_cmd(&sil, &cams, &long, &["--iters", "400", "--resume", ck2_arg])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // It went on after the saved iteration and ran only the rest.
    let said = String::from_utf8_lossy(&o.stdout);
    let after: u32 = said
        .split("resumed after iteration ")
        .nth(1)
        .and_then(|r| r.split(':').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("the resumed run does not say where it went on: {said}"));
    assert!((2..400).contains(&after), "{said}");
    assert!(
        said.contains(&format!("ran iterations {}..400;", after + 1)),
        "{said}"
    );
    assert_eq!(
        std::fs::read(&whole_long).unwrap(),
        std::fs::read(&long).unwrap(),
        "resumed after Ctrl-C"
    );
    assert!(
        !note.exists(),
        "the finished report still says it was interrupted"
    );

    // Another template: refused before anything is written.
    let other = dir.path("other.obj");
    let o = softvk()
        .args(["fit-mesh", "--log-every", "2", "--quiet", "--iters", "10"])
        .arg("--silhouettes")
        .arg(&sil)
        .arg("--cameras")
        .arg(&cams)
        .arg("--out")
        .arg(&other)
        .args(["--resume", ck_arg])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.contains("another fit"), "{stderr}");
    assert!(!other.exists() && !dir.path("other-report").exists());
}

/// The field fit, with the geometric regularizer (its own random candidates) and the samplers'
/// random rays and anchors, both keyed by (seed, iteration): resumed, it ends bit for bit as
/// the fit that never stopped.
#[test]
fn a_field_fit_resumed_from_a_checkpoint_ends_bit_for_bit_as_the_uninterrupted_fit() {
    use softvk::field::FieldKind;
    use softvk::fit::AdamOptions;
    use softvk::fit::field_fit::{
        FieldFitLog, FieldFitOptions, FieldFitState, fit_field, fit_field_resumable,
    };
    use softvk::probe::ProbeSettings;
    use softvk::probe::targets::sphere_silhouettes;
    let Some(gpu) = common::gpu() else { return };
    let cams = [
        Camera::from_angles(2.732, 20.0, 30.0),
        Camera::from_angles(2.732, -10.0, 130.0),
    ];
    let targets = sphere_silhouettes(&cams, 24, 24, 0.5).unwrap();
    let opts = FieldFitOptions {
        field: FieldKind::Grid { res: 8 },
        probe: ProbeSettings {
            rays_per_view: 96,
            anchors: 300,
            tau: 0.1,
            anchor_sigma: 0.08,
            hull_resolution: 16,
            geo_candidates: 12,
            geo_lambda: 0.1,
            seed: 7,
            ..ProbeSettings::default()
        },
        adam: AdamOptions {
            lr: 0.05,
            betas: (0.9, 0.99),
            eps: 1e-8,
        },
        iterations: 6,
        log_every: 2,
        init_logit: 0.0,
    };
    let losses = |log: &[FieldFitLog]| -> Vec<(u32, u32, u32, u32)> {
        log.iter()
            .map(|l| {
                (
                    l.iteration,
                    l.silhouette.to_bits(),
                    l.geo.to_bits(),
                    l.total.to_bits(),
                )
            })
            .collect()
    };
    let whole = fit_field(&gpu, &targets, &opts, |_| true).unwrap();
    let n = whole.field.param_count();
    let params = |f: &softvk::field::Field| -> Vec<u32> {
        bits(&gpu.read_buffer::<f32>(f.params(), 0, n).unwrap())
    };
    let fp = FieldFitState::fingerprint(&targets, &opts);
    let dir = TempDir::new("ckpt-field");
    let mut state = None;
    fit_field_resumable(&gpu, &targets, &opts, None, |l, snapshot| {
        if l.iteration == 4 {
            state = Some(snapshot.state()?);
            return Ok(false);
        }
        Ok(true)
    })
    .unwrap();
    let path = dir.path("f.ckpt");
    state.unwrap().to_checkpoint(fp).write(&path).unwrap();
    let c = Checkpoint::read(&path, FitKind::Field, fp).unwrap();
    let back = FieldFitState::from_checkpoint(&c, &opts).unwrap();
    assert_eq!(back.iteration, 4);
    // Only the rest runs: iterations 5 and 6, logged at 6.
    let mut logged = Vec::new();
    let resumed = fit_field_resumable(&gpu, &targets, &opts, Some(&back), |l, _| {
        logged.push(l.iteration);
        Ok(true)
    })
    .unwrap();
    assert_eq!(logged, [6], "a resumed fit logs only what it runs");
    assert_eq!(resumed.iterations, 6);
    assert_eq!(
        params(&whole.field),
        params(&resumed.field),
        "field parameters"
    );
    assert_eq!(losses(&whole.log), losses(&resumed.log), "logged losses");
    // A mesh fit's checkpoint is not a field fit's, and another field type is another fit.
    let e = Checkpoint::read(&path, FitKind::Mesh, fp)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("field fit checkpoint, not a mesh fit's"), "{e}");
    let other = FieldFitOptions {
        field: FieldKind::Grid { res: 9 },
        ..opts
    };
    assert_ne!(fp, FieldFitState::fingerprint(&targets, &other));
}

/// The pose fit, across a σ/γ schedule stage change (stages follow from the iteration):
/// resumed, it ends bit for bit as the fit that never stopped.
#[test]
fn a_pose_fit_resumed_from_a_checkpoint_ends_bit_for_bit_as_the_uninterrupted_fit() {
    use glam::DVec3;
    use softvk::fit::pose::{
        Pose, PoseFitOptions, PoseFitState, PoseTarget, Schedule, fit_pose, fit_pose_resumable,
    };
    use softvk::lighting::Lighting;
    use softvk::raster::gpu::{Method, Renderer};
    let Some(gpu) = common::gpu() else { return };
    let mut mesh = Mesh::cuboid([0.5, 0.32, 0.22]);
    mesh.textures = (0..mesh.textures.len())
        .map(|i| {
            let t = i as f32 / mesh.textures.len() as f32;
            [0.2 + 0.7 * t, 0.9 - 0.6 * t, 0.3 + 0.5 * (t * 7.0).fract()]
        })
        .collect();
    let camera = Camera::from_angles(2.732, 20.0, -30.0);
    let lighting = Lighting::default();
    let opts = PoseFitOptions {
        iterations: 12,
        lr_rotation: 0.05,
        lr_translation: 0.003,
        schedule: Some(Schedule {
            sigma_start: 1e-3,
            gamma_start: 1e-2,
            stages: 3,
        }),
        settings: RasterSettings {
            width: 24,
            height: 24,
            ..RasterSettings::default()
        },
        // Called back after every iteration, so that the fit can stop at 5.
        log_every: 1,
        ..PoseFitOptions::default()
    };
    let target = Renderer::new(&gpu)
        .unwrap()
        .render_views(
            &gpu,
            &mesh,
            &[camera],
            &lighting,
            &opts.settings,
            Method::default(),
        )
        .unwrap()
        .images;
    let init = Pose {
        rotation: DVec3::new(0.2, -0.3, 0.1),
        translation: DVec3::new(0.02, 0.0, -0.01),
    };
    let pose_bits = |p: &Pose| p.to_array().map(f64::to_bits);
    let whole = fit_pose(
        &gpu,
        &mesh,
        &camera,
        &lighting,
        PoseTarget::Fixed(&target),
        &init,
        &opts,
        |_| true,
    )
    .unwrap();
    let fp = PoseFitState::fingerprint(&mesh, &camera, &lighting, &target, &init, &opts);
    let dir = TempDir::new("ckpt-pose");
    // 5: inside the second of three stages (4 iterations each).
    let mut state = None;
    fit_pose_resumable(
        &gpu,
        &mesh,
        &camera,
        &lighting,
        PoseTarget::Fixed(&target),
        &init,
        &opts,
        None,
        |l, snapshot| {
            if l.iteration == 5 {
                state = Some(snapshot.state()?);
                return Ok(false);
            }
            Ok(true)
        },
    )
    .unwrap();
    let path = dir.path("p.ckpt");
    state.unwrap().to_checkpoint(fp).write(&path).unwrap();
    let c = Checkpoint::read(&path, FitKind::Pose, fp).unwrap();
    let back = PoseFitState::from_checkpoint(&c).unwrap();
    assert_eq!(back.iteration, 5);
    let mut logged = Vec::new();
    let resumed = fit_pose_resumable(
        &gpu,
        &mesh,
        &camera,
        &lighting,
        PoseTarget::Fixed(&target),
        &init,
        &opts,
        Some(&back),
        |l, _| {
            logged.push(l.iteration);
            Ok(true)
        },
    )
    .unwrap();
    assert_eq!(
        logged,
        (6..=12).collect::<Vec<_>>(),
        "a resumed fit runs only the rest"
    );
    assert_eq!(resumed.iterations, 12);
    assert_eq!(pose_bits(&whole.pose), pose_bits(&resumed.pose), "pose");
    assert_eq!(whole.loss.to_bits(), resumed.loss.to_bits(), "final loss");
    let log = |r: &softvk::fit::pose::PoseFitResult| -> Vec<(u32, u64, [u64; 6])> {
        r.log
            .iter()
            .map(|l| (l.iteration, l.loss.to_bits(), pose_bits(&l.pose)))
            .collect()
    };
    assert_eq!(log(&whole), log(&resumed), "log");
    // Another start is another fit.
    let other = Pose {
        rotation: DVec3::new(0.2, -0.3, 0.11),
        ..init
    };
    assert_ne!(
        fp,
        PoseFitState::fingerprint(&mesh, &camera, &lighting, &target, &other, &opts)
    );
}
