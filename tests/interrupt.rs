//! Ctrl-C and SIGTERM during the fits: a real signal to a real `softvk` child
//! process, then its files and exit status checked. A first signal ends the fit after the
//! submission in flight, writes the result and report as a normal end does (marked as
//! interrupted) and exits with 128 + the signal; a second one stops at once. Either way no
//! temporary (`.NAME.softvk-PID-N.tmp`) or partial file is left.

mod common;

use std::path::Path;
use std::process::{Child, ExitStatus};
use std::time::{Duration, Instant};

use common::{TempDir, softvk, write_disc_inputs};
use softvk::mesh::Mesh;

fn signal(child: &Child, sig: i32) {
    // SAFETY: kill(2) on our own child's pid, a plain signal number.
    let r = unsafe { libc::kill(child.id() as libc::pid_t, sig) };
    assert_eq!(r, 0, "kill({}, {sig})", child.id());
}

/// Waits for the child, failing the test (and killing it) after `limit`.
fn wait(child: &mut Child, limit: Duration) -> ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("softvk did not stop within {limit:?} of the signal");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Every file under `dir`, recursively, relative names.
fn files(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_dir() {
            let name = e.file_name().to_string_lossy().into_owned();
            out.extend(files(&e.path()).into_iter().map(|f| format!("{name}/{f}")));
        } else {
            out.push(e.file_name().to_string_lossy().into_owned());
        }
    }
    out.sort();
    out
}

fn assert_no_temporaries(what: &str, dir: &Path) {
    let left: Vec<String> = files(dir)
        .into_iter()
        .filter(|f| f.contains(".softvk-"))
        .collect();
    assert!(left.is_empty(), "{what}: temporary files left: {left:?}");
}

/// Lets the child start its fit (the signal handler is installed before any work), then sends
/// `sig` and waits.
fn interrupt(mut child: Child, sig: i32, after: Duration) -> (ExitStatus, String) {
    std::thread::sleep(after);
    assert!(
        child.try_wait().unwrap().is_none(),
        "softvk ended before the signal"
    );
    signal(&child, sig);
    let status = wait(&mut child, Duration::from_secs(120));
    let mut stderr = String::new();
    use std::io::Read as _;
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    (status, stderr)
}

fn spawn(cmd: &mut std::process::Command) -> Child {
    cmd.stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn ctrl_c_during_fit_mesh_writes_the_result_and_report_marked_interrupted() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("intr-mesh");
    let (sil, cams) = write_disc_inputs(&dir, 16);
    let out = dir.path("fitted.obj");
    let child = spawn(
        softvk()
            .args([
                "fit-mesh",
                "--iters",
                "1000000",
                "--log-every",
                "2",
                "--quiet",
            ])
            .arg("--silhouettes")
            .arg(&sil)
            .arg("--cameras")
            .arg(&cams)
            .arg("--out")
            .arg(&out),
    );
    let (status, stderr) = interrupt(child, libc::SIGINT, Duration::from_millis(2500));
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("SIGINT"), "{stderr}");
    assert_no_temporaries("fit-mesh", &dir.0);
    assert_eq!(Mesh::load_obj(&out, 1).unwrap().face_count(), 2700);
    let report = dir.path("fitted-report");
    for f in [
        "ious.csv",
        "contact_sheet.png",
        "loss.png",
        "progress.gif",
        "interrupted.txt",
    ] {
        assert!(report.join(f).is_file(), "{f} missing: {:?}", files(&dir.0));
    }
    let note = std::fs::read_to_string(report.join("interrupted.txt")).unwrap();
    assert!(
        note.contains("SIGINT") && note.contains("of 1000000"),
        "{note}"
    );
    image::open(report.join("contact_sheet.png")).unwrap();
    image::open(report.join("progress.gif")).unwrap();
}

#[test]
fn sigterm_during_fit_field_writes_the_surface_and_report_marked_interrupted() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("intr-field");
    let (sil, cams) = write_disc_inputs(&dir, 24);
    let out = dir.path("field.obj");
    let child = spawn(
        softvk()
            .args([
                "fit-field",
                "--iters",
                "1000000",
                "--log-every",
                "2",
                "--quiet",
            ])
            .args(["--grid-res", "8", "--rays", "64", "--anchors", "256"])
            .args([
                "--geo-candidates",
                "16",
                "--hull-res",
                "16",
                "--mc-res",
                "16",
            ])
            .args(["--preview-size", "32"])
            .arg("--silhouettes")
            .arg(&sil)
            .arg("--cameras")
            .arg(&cams)
            .arg("--out")
            .arg(&out),
    );
    let (status, stderr) = interrupt(child, libc::SIGTERM, Duration::from_millis(2500));
    assert_eq!(status.code(), Some(143), "{stderr}");
    assert!(stderr.contains("SIGTERM"), "{stderr}");
    assert_no_temporaries("fit-field", &dir.0);
    assert!(Mesh::load_obj(&out, 1).unwrap().face_count() > 0);
    let report = dir.path("field-report");
    for f in [
        "preview.png",
        "compare.png",
        "loss.png",
        "loss.csv",
        "interrupted.txt",
    ] {
        assert!(report.join(f).is_file(), "{f} missing: {:?}", files(&dir.0));
    }
    let note = std::fs::read_to_string(report.join("interrupted.txt")).unwrap();
    assert!(note.contains("SIGTERM"), "{note}");
}

#[test]
fn ctrl_c_during_fit_pose_writes_the_pose_marked_interrupted() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("intr-pose");
    // An icosphere with a colour per vertex, seen from one side, as the target.
    let ico = Mesh::icosphere(2);
    let mut text = String::new();
    for p in &ico.positions {
        let c = p.map(|x| 0.5 + 0.5 * x);
        text += &format!(
            "v {} {} {} {} {} {}\n",
            p[0] * 0.6,
            p[1] * 0.6,
            p[2] * 0.6,
            c[0],
            c[1],
            c[2]
        );
    }
    for f in &ico.faces {
        text += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    let mesh = dir.path("ball.obj");
    std::fs::write(&mesh, text).unwrap();
    let target = dir.path("target.png");
    let o = softvk()
        .args([
            "render",
            "--size",
            "24",
            "--vertex-colors",
            "--azimuth",
            "40",
        ])
        .arg("--mesh")
        .arg(&mesh)
        .arg("--out")
        .arg(&target)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = dir.path("pose.json");
    let child = spawn(
        softvk()
            .args([
                "fit-pose",
                "--iters",
                "1000000",
                "--vertex-colors",
                "--quiet",
            ])
            .arg("--mesh")
            .arg(&mesh)
            .arg("--target")
            .arg(&target)
            .arg("--out")
            .arg(&out),
    );
    let (status, stderr) = interrupt(child, libc::SIGINT, Duration::from_millis(2500));
    assert_eq!(status.code(), Some(130), "{stderr}");
    assert_no_temporaries("fit-pose", &dir.0);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let note = json["interrupted"].as_str().unwrap_or_default();
    assert!(
        note.contains("SIGINT") && note.contains("of 1000000"),
        "{json}"
    );
    for f in ["pose-render.png", "pose-error.png", "pose-compare.png"] {
        image::open(dir.path(f)).unwrap();
    }
}

/// A second Ctrl-C does not wait for the fit: the process ends at once with no output and no
/// temporary file (the progress GIF's was open).
#[test]
fn a_second_ctrl_c_stops_at_once_leaving_no_partial_or_temporary_file() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("intr-twice");
    let (sil, cams) = write_disc_inputs(&dir, 16);
    let out = dir.path("fitted.obj");
    // A first log (and so the first look at the interrupt) only after 100 000 iterations.
    let mut child = spawn(
        softvk()
            .args(["fit-mesh", "--iters", "1000000", "--log-every", "100000"])
            .arg("--silhouettes")
            .arg(&sil)
            .arg("--cameras")
            .arg(&cams)
            .arg("--out")
            .arg(&out),
    );
    std::thread::sleep(Duration::from_millis(2500));
    assert!(child.try_wait().unwrap().is_none());
    let report = dir.path("fitted-report");
    assert!(
        files(&report).iter().any(|f| f.contains(".softvk-")),
        "the progress GIF's temporary file should be open: {:?}",
        files(&dir.0)
    );
    signal(&child, libc::SIGINT);
    std::thread::sleep(Duration::from_millis(300));
    signal(&child, libc::SIGINT);
    let status = wait(&mut child, Duration::from_secs(10));
    assert_eq!(status.code(), Some(130));
    assert_no_temporaries("twice", &dir.0);
    assert!(!out.exists(), "the mesh was written");
    assert!(files(&report).is_empty(), "{:?}", files(&report));
}
