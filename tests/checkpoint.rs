//! Checkpoints and resume: a fit stopped at a checkpoint and resumed ends bit for bit as the
//! fit that never stopped, for every fit a session runs (mesh, field, pose, articulated), in
//! the library and through `softvk fit-mesh` (`--checkpoint`, `--resume`, also after a real
//! Ctrl-C); checkpoints of other inputs, other kinds or no checkpoint at all are refused with
//! one clear error.

mod common;

use std::cell::RefCell;
use std::path::Path;
use std::rc::Rc;
use std::time::Duration;

use common::{TempDir, softvk};
use softvk::camera::Camera;
use softvk::fit::checkpoint::{Checkpoint, Fingerprint, FitKind, Writer};
use softvk::fit::mesh_fit::{
    FitLog, MeshFit, MeshFitOptions, MeshFitResult, fit_mesh, icosphere_template,
};
use softvk::fit::session::{CheckpointPlan, LogRow, Progress, Resume, Session, Trainee};
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

/// A session that checkpoints into `path` (for inputs of `fingerprint`) and stops after
/// iteration `stop`, leaving its checkpoint there.
fn stopping_at<'h, F: Trainee>(stop: u32, path: &Path, fingerprint: u64) -> Session<'h, F> {
    Session::new()
        .checkpoint(Some(CheckpointPlan {
            path: path.to_path_buf(),
            fingerprint,
            every: 1000,
        }))
        .hooks(move |p: &Progress<'_, '_, F>| Ok(p.last < stop))
}

/// A session resumed from the checkpoint at `path`, which must be after iteration `at`,
/// recording the iterations its hooks see into `logged`.
fn resumed_from<'h, F: Trainee>(
    path: &Path,
    fingerprint: u64,
    at: u32,
    logged: &Rc<RefCell<Vec<u32>>>,
) -> Session<'h, F> {
    let logged = Rc::clone(logged);
    let resume = Resume::read(path, F::KIND, fingerprint).unwrap();
    assert_eq!(resume.iteration, at, "the checkpoint's iteration");
    assert_eq!(
        resume.log.last().map(LogRow::iteration),
        Some(at),
        "the checkpoint's log"
    );
    Session::new()
        .resume(Some(resume))
        .hooks(move |p: &Progress<'_, '_, F>| {
            logged.borrow_mut().push(p.last);
            Ok(true)
        })
}

#[test]
fn a_mesh_fit_resumed_from_any_checkpoint_ends_bit_for_bit_as_the_uninterrupted_fit() {
    let Some(gpu) = common::gpu() else { return };
    let template = icosphere_template();
    let cams: Vec<Camera> = rows().iter().map(CameraRow::camera).collect();
    let targets = masks();
    let fit = |session| fit_mesh(&gpu, &template, &cams, &targets, &options(8), session);
    let whole = fit(Session::new()).unwrap();
    let dir = TempDir::new("ckpt-lib");
    let fingerprint = MeshFit::fingerprint(&template, &cams, &targets, &options(8));
    for stop in [2u32, 4, 6] {
        // Run to `stop`, with the checkpoint written there; resume from the file.
        let path = dir.path(&format!("at-{stop}.ckpt"));
        fit(stopping_at(stop, &path, fingerprint)).unwrap();
        // The resumed fit runs only the iterations after the checkpoint's (a fit that started
        // again from 1 would end the same, deterministic as it is, but not log these).
        let logged = Rc::default();
        let resumed = fit(resumed_from(&path, fingerprint, stop, &logged)).unwrap();
        assert_eq!(resumed.first_iteration, stop + 1);
        // Logged every 2: the submissions after the checkpoint, not from 1.
        let rest: Vec<u32> = (stop + 2..=8).step_by(2).collect();
        assert_eq!(*logged.borrow(), rest, "stopped at {stop}");
        assert_same_fit(&format!("stopped at {stop}"), &whole, &resumed);
    }
    // A state of another template size is refused when the fit starts.
    let path = dir.path("at-2.ckpt");
    let mut small = Mesh::icosphere(1);
    for c in small.positions.iter_mut().flatten() {
        *c = if *c == 0.0 { 1e-3 } else { 0.5 * *c };
    }
    let fp = MeshFit::fingerprint(&small, &cams, &targets, &options(8));
    let c = Checkpoint::read(&path, FitKind::Mesh, fingerprint).unwrap();
    Checkpoint {
        fingerprint: fp,
        ..c
    }
    .write(&path)
    .unwrap();
    let resume = Resume::read(&path, FitKind::Mesh, fp).unwrap();
    let e = fit_mesh(
        &gpu,
        &small,
        &cams,
        &targets,
        &options(8),
        Session::new().resume(Some(resume)),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("parameters") || e.contains("at most"), "{e}");
}

/// A checkpoint of a mesh fit after iteration 2: a log row, no validations, then a state of `n`
/// parameters.
fn mesh_checkpoint(fingerprint: u64, n: usize) -> Checkpoint {
    let mut w = Writer::default();
    let row = FitLog {
        iteration: 2,
        silhouette: 0.5,
        laplacian: 0.25,
        flatten: 0.125,
        total: 0.875,
        entries: 40,
        seconds: 1.0,
    };
    softvk::fit::log::write_log(&mut w, &[row]);
    w.u32(0); // no validations
    for value in [0.5, 0.25, 0.125] {
        w.f32s(&vec![value; n]);
    }
    Checkpoint {
        kind: FitKind::Mesh,
        fingerprint,
        iteration: 2,
        seconds: 1.0,
        payload: w.0,
    }
}

#[test]
fn foreign_or_broken_checkpoints_are_refused_with_one_line() {
    let template = icosphere_template();
    let cams: Vec<Camera> = rows().iter().map(CameraRow::camera).collect();
    let targets = masks();
    let fp = MeshFit::fingerprint(&template, &cams, &targets, &options(8));
    // Only the iteration count and the logging may differ.
    assert_eq!(
        fp,
        MeshFit::fingerprint(&template, &cams, &targets, &options(3000))
    );
    let mut other = targets.clone();
    other[5] = 1.0 - other[5];
    assert_ne!(
        fp,
        MeshFit::fingerprint(&template, &cams, &other, &options(8))
    );
    let dir = TempDir::new("ckpt-bad");
    let n = 3 * template.vertex_count() + 3;
    let path = dir.path("c.ckpt");
    mesh_checkpoint(fp, n).write(&path).unwrap();
    let back = Resume::<FitLog>::read(&path, FitKind::Mesh, fp).unwrap();
    assert_eq!((back.iteration, back.log.len()), (2, 1), "the round trip");
    let refused = |path: &Path, kind: FitKind, fp: u64, needle: &str| {
        let e = Checkpoint::read(path, kind, fp)
            .err()
            .unwrap_or_else(|| panic!("{needle}: accepted"))
            .to_string();
        assert!(e.contains(needle) && !e.contains('\n'), "{needle}: {e}");
    };
    refused(&path, FitKind::Mesh, fp ^ 1, "another fit");
    refused(
        &path,
        FitKind::Pose,
        fp,
        "a mesh fit checkpoint, not a pose fit's",
    );
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
    // An earlier format (the format number follows the magic): 3 stored the log without its
    // columns.
    for format in [2u32, 3] {
        let mut old = body.to_vec();
        old[8..12].copy_from_slice(&format.to_le_bytes());
        let o = dir.path("old.ckpt");
        std::fs::write(&o, sealed(&old)).unwrap();
        refused(
            &o,
            FitKind::Mesh,
            fp,
            &format!("checkpoint format {format}, this softvk reads format 4 (written by another"),
        );
    }
    refused(&dir.path("missing.ckpt"), FitKind::Mesh, fp, "missing.ckpt");
    // A log cut short after a valid header.
    let cut = dir.path("cut.ckpt");
    let header = body.len() - mesh_checkpoint(fp, n).payload.len();
    std::fs::write(&cut, sealed(&body[..header + 20])).unwrap();
    let e = Resume::<FitLog>::read(&cut, FitKind::Mesh, fp)
        .unwrap_err()
        .to_string();
    assert!(e.contains("truncated"), "{e}");
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
    use softvk::fit::field_fit::{FieldFit, FieldFitLog, FieldFitOptions, fit_field};
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
    let whole = fit_field(&gpu, &targets, &opts, Session::new()).unwrap();
    let n = whole.field.param_count();
    let params = |f: &softvk::field::Field| -> Vec<u32> {
        bits(&gpu.read_buffer::<f32>(f.params(), 0, n).unwrap())
    };
    let fp = FieldFit::fingerprint(&targets, &opts);
    let dir = TempDir::new("ckpt-field");
    let path = dir.path("f.ckpt");
    fit_field(&gpu, &targets, &opts, stopping_at(4, &path, fp)).unwrap();
    // Only the rest runs: iterations 5 and 6, logged at 6.
    let logged = Rc::default();
    let resumed = fit_field(&gpu, &targets, &opts, resumed_from(&path, fp, 4, &logged)).unwrap();
    assert_eq!(
        *logged.borrow(),
        [6],
        "a resumed fit logs only what it runs"
    );
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
    assert_ne!(fp, FieldFit::fingerprint(&targets, &other));
}

/// The pose fit, across a σ/γ schedule stage change (stages follow from the iteration):
/// resumed, it ends bit for bit as the fit that never stopped.
#[test]
fn a_pose_fit_resumed_from_a_checkpoint_ends_bit_for_bit_as_the_uninterrupted_fit() {
    use glam::DVec3;
    use softvk::fit::pose::{Pose, PoseFit, PoseFitOptions, PoseTarget, Schedule, fit_pose};
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
        refine: None,
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
    let fit = |session| {
        fit_pose(
            &gpu,
            &mesh,
            &camera,
            &lighting,
            PoseTarget::Fixed(&target),
            &init,
            &opts,
            session,
        )
    };
    let whole = fit(Session::new()).unwrap();
    let fp = PoseFit::fingerprint(&mesh, &camera, &lighting, &target, &init, &opts);
    let dir = TempDir::new("ckpt-pose");
    // 5: inside the second of three stages (4 iterations each).
    let path = dir.path("p.ckpt");
    fit(stopping_at(5, &path, fp)).unwrap();
    let logged = Rc::default();
    let resumed = fit(resumed_from(&path, fp, 5, &logged)).unwrap();
    assert_eq!(
        *logged.borrow(),
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
        PoseFit::fingerprint(&mesh, &camera, &lighting, &target, &other, &opts)
    );
    // Stopped inside the refinement after the schedule and resumed, the stopping rule (which
    // reads the log the checkpoint carries) ends it where it ended the fit that never stopped.
    let refined = PoseFitOptions {
        refine: Some(softvk::fit::pose::Refine {
            iterations: 40,
            window: 3,
            min_improvement: 0.05,
        }),
        ..opts.clone()
    };
    let fit = |session| {
        fit_pose(
            &gpu,
            &mesh,
            &camera,
            &lighting,
            PoseTarget::Fixed(&target),
            &init,
            &refined,
            session,
        )
    };
    let whole = fit(Session::new()).unwrap();
    assert!(
        (15..refined.last_iteration()).contains(&whole.iterations),
        "the rule ended the refinement after {} iterations",
        whole.iterations
    );
    let fp = PoseFit::fingerprint(&mesh, &camera, &lighting, &target, &init, &refined);
    let path = dir.path("refined.ckpt");
    fit(stopping_at(14, &path, fp)).unwrap();
    let logged = Rc::default();
    let resumed = fit(resumed_from(&path, fp, 14, &logged)).unwrap();
    assert_eq!(resumed.iterations, whole.iterations);
    assert_eq!(
        pose_bits(&whole.pose),
        pose_bits(&resumed.pose),
        "refined pose"
    );
    assert_eq!(log(&whole), log(&resumed), "refined log");
    // The checkpoint written where the rule ended the fit ends it again: nothing more runs.
    let ended = dir.path("ended.ckpt");
    fit(stopping_at(u32::MAX, &ended, fp)).unwrap();
    let logged = Rc::default();
    let again = fit(resumed_from(&ended, fp, whole.iterations, &logged)).unwrap();
    assert!(logged.borrow().is_empty(), "ran {:?}", logged.borrow());
    assert_eq!(again.iterations, whole.iterations);
    assert_eq!(pose_bits(&whole.pose), pose_bits(&again.pose), "ended pose");
}
