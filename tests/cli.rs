//! The `softvk` binary as scripts call it (SPEC §6).

mod common;

use common::{TempDir, softvk};

use std::path::{Path, PathBuf};
use std::process::Output;

use glam::DVec3;
use softvk::camera::{Camera, Projection, pixel_center};
use softvk::fit::mesh_fit::default_template;
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::raster::reference::{self, FaceColors, project_faces, setup_face, shade_pixel};
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};

/// `softvk info | head -1`: a closed stdout ends the process by SIGPIPE, as any Unix tool,
/// with nothing on stderr (it used to panic with a backtrace).
#[test]
fn a_closed_stdout_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    use std::os::fd::FromRawFd;
    // A pipe whose read end is closed before the process starts: its first write fails.
    let mut fds = [0; 2];
    assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
    unsafe { libc::close(fds[0]) };
    // SAFETY: fds[1] is the pipe's open write end, owned by nothing else.
    let write_end = unsafe { std::process::Stdio::from_raw_fd(fds[1]) };
    let out = softvk().arg("info").stdout(write_end).output().unwrap();
    assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{:?}", out.status);
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn info_names_the_device_and_the_validation_state() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let out = softvk()
        .arg("info")
        .env("SOFTVK_VALIDATION", "1")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "softvk info failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    for field in [
        "device",
        "driver",
        "vulkan",
        "subgroup size",
        "maxStorageBufferRange",
        "VK_KHR_push_descriptor",
    ] {
        assert!(stdout.contains(field), "`{field}` missing from:\n{stdout}");
    }
    assert!(stdout.contains("validation         on"), "{stdout}");
}

#[test]
fn no_vulkan_driver_gives_one_clear_error_line() {
    // Point the loader at a driver manifest that does not exist: no physical device at all.
    let out = softvk()
        .arg("info")
        .env("VK_ICD_FILENAMES", "/nonexistent/softvk-test-icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/softvk-test-icd.json")
        .env_remove("SOFTVK_VALIDATION")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let ours: Vec<_> = stderr
        .lines()
        .filter(|l| l.starts_with("softvk:"))
        .collect();
    assert_eq!(ours.len(), 1, "expected one error line, got:\n{stderr}");
    assert!(
        ours[0].contains("Vulkan"),
        "the error should say what is missing: {}",
        ours[0]
    );
    assert!(out.stdout.is_empty(), "nothing may be printed on failure");
}

#[test]
fn unknown_device_selection_is_an_error_naming_the_choices() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let out = softvk()
        .arg("info")
        .env("SOFTVK_DEVICE", "no-such-gpu-anywhere")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("SOFTVK_DEVICE=no-such-gpu-anywhere matches none of"),
        "{stderr}"
    );
}

// `softvk render`: PNG and EXR outputs, the flags against the f64 twin, and every error class.

fn spot() -> PathBuf {
    softvk::assets::dir().join("spot_triangulated.obj")
}

/// `softvk render --mesh MESH --out OUT ARGS...`, validated as the tests are.
fn render(mesh: &Path, out: &Path, args: &[&str]) -> Output {
    softvk()
        .arg("render")
        .arg("--mesh")
        .arg(mesh)
        .arg("--out")
        .arg(out)
        .args(args)
        .env("SOFTVK_VALIDATION", common::validation_env())
        .output()
        .unwrap()
}

fn assert_success(what: &str, out: &Output) {
    assert!(
        out.status.success(),
        "{what}: softvk render failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// RGBA f32 pixels of an EXR, row 0 at the top, after checking it holds exactly the float32
/// channels R, G, B, A.
fn read_exr(path: &Path) -> (usize, usize, Vec<[f32; 4]>) {
    use exr::prelude::*;
    let meta = exr::meta::MetaData::read_from_file(path, false).unwrap();
    assert_eq!(meta.headers.len(), 1, "one layer");
    let mut names: Vec<String> = meta.headers[0]
        .channels
        .list
        .iter()
        .map(|c| {
            assert_eq!(c.sample_type, SampleType::F32, "channel {}", c.name);
            c.name.to_string()
        })
        .collect();
    names.sort();
    assert_eq!(names, ["A", "B", "G", "R"]);
    let image = read_first_rgba_layer_from_file(
        path,
        |size, _| (size.width(), vec![[0f32; 4]; size.area()]),
        |(w, px), p, (r, g, b, a): (f32, f32, f32, f32)| px[p.y() * *w + p.x()] = [r, g, b, a],
    )
    .unwrap();
    let size = image.layer_data.size;
    let (_, pixels) = image.layer_data.channel_data.pixels;
    (size.width(), size.height(), pixels)
}

#[test]
fn render_writes_png_and_exr_of_the_same_rgba() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("formats");
    let args = [
        "--size",
        "32",
        "--elevation",
        "30",
        "--azimuth",
        "-45",
        "--sigma",
        "1e-4",
    ];
    let (png, exr) = (dir.path("spot.png"), dir.path("spot.EXR"));
    assert_success("png", &render(&spot(), &png, &args));
    assert_success("exr", &render(&spot(), &exr, &args));
    assert_eq!(
        dir.entries(),
        ["spot.EXR", "spot.png"],
        "no temporaries left"
    );

    let (w, h, floats) = read_exr(&exr);
    assert_eq!((w, h), (32, 32));
    let covered = floats.iter().filter(|p| p[3] > 0.5).count();
    assert!(
        covered > 50 && covered < 32 * 32 - 50,
        "spot should cover part of the image, covers {covered} pixels"
    );

    let decoded = image::open(&png).unwrap();
    assert_eq!(decoded.color(), image::ColorType::Rgba8);
    let decoded = decoded.to_rgba8();
    assert_eq!(decoded.dimensions(), (32, 32));
    // The PNG is the EXR clamped to [0, 1] and rounded to 8 bits, pixel for pixel: same
    // orientation, same straight alpha.
    for (i, (p, f)) in decoded.pixels().zip(&floats).enumerate() {
        let expected = f.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8);
        assert_eq!(p.0, expected, "pixel {i}: PNG {:?} vs EXR {f:?}", p.0);
    }
}

/// Largest |GPU − twin| allowed per channel.
const TOL: f64 = 1e-4;
/// Shift of the pixel centres that models the GPU's f32 rounding of screen positions.
const JITTER: f64 = 1e-6;

/// The f64 twin at every pixel centre shifted by `(dx, dy)`; `(0, 0)` is `reference::render`.
fn twin(
    mesh: &Mesh,
    cam: &Camera,
    lit: &Lighting,
    s: &RasterSettings,
    (dx, dy): (f64, f64),
) -> Vec<[f64; 4]> {
    if (dx, dy) == (0.0, 0.0) {
        return reference::render(mesh, cam, lit, s).unwrap();
    }
    let colors = FaceColors::new(mesh, lit, s.color_mode);
    let faces: Vec<_> = project_faces(mesh, cam)
        .into_iter()
        .map(|v| setup_face(v, s.dist, s.cutoff()))
        .collect();
    let k = if s.antialias { 2 } else { 1 };
    let (w, h) = (s.width * k, s.height * k);
    let mut img = Vec::with_capacity((w * h) as usize);
    for row in 0..h {
        for col in 0..w {
            let (x, y) = pixel_center(col, row, w, h);
            img.push(shade_pixel(&faces, &colors, x + dx, y + dy, s, true));
        }
    }
    if s.antialias {
        reference::downsample_2x2(&img, s.width, s.height)
    } else {
        img
    }
}

/// The EXR equals the twin within [`TOL`] per channel. Where the twin itself jumps within
/// ±[`JITTER`] of the pixel centre (a hard edge, the coverage cut-off, a texel border), no
/// tolerance can hold, so there the EXR must lie within [`TOL`] of the range the twin spans;
/// such pixels must stay a small minority (as in `tests/raster_brute.rs`).
fn assert_matches_twin(
    what: &str,
    exr: &Path,
    mesh: &Mesh,
    cam: &Camera,
    lit: &Lighting,
    s: &RasterSettings,
) {
    let (w, h, gpu) = read_exr(exr);
    assert_eq!(
        (w, h),
        (s.width as usize, s.height as usize),
        "{what}: size"
    );
    let centre = twin(mesh, cam, lit, s, (0.0, 0.0));
    let shifted: Vec<_> = [(JITTER, 0.0), (-JITTER, 0.0), (0.0, JITTER), (0.0, -JITTER)]
        .into_iter()
        .map(|d| twin(mesh, cam, lit, s, d))
        .collect();
    let (mut steep, mut covered, mut max_err) = (0, 0, 0.0f64);
    for (i, (g, c)) in gpu.iter().zip(&centre).enumerate() {
        let mut jumps = false;
        for k in 0..4 {
            let g = f64::from(g[k]);
            let (lo, hi) = shifted.iter().fold((c[k], c[k]), |(lo, hi), img| {
                (lo.min(img[i][k]), hi.max(img[i][k]))
            });
            let ok = if hi - lo <= TOL {
                max_err = max_err.max((g - c[k]).abs());
                (g - c[k]).abs() <= TOL
            } else {
                jumps = true;
                g >= lo - TOL && g <= hi + TOL
            };
            assert!(
                ok,
                "{what}: pixel (col {}, row {}) channel {k}: EXR {g} vs twin {} (range [{lo}, \
                 {hi}])\nsettings {s:?}",
                i % w,
                i / w,
                c[k]
            );
        }
        steep += usize::from(jumps);
        covered += usize::from(c[3] > 0.0);
    }
    eprintln!(
        "{what}: max |EXR - twin| {max_err:.2e} where continuous; {steep} of {} pixels at \
         discontinuities; {covered} covered",
        gpu.len()
    );
    assert!(
        steep * 10 <= gpu.len(),
        "{what}: {steep} pixels at discontinuities"
    );
    assert!(covered > 0, "{what}: the mesh is not in view");
}

/// An octahedron with a colour per vertex (`v x y z r g b`), faces wound outwards.
const OCTAHEDRON: &str = "\
v 0.8 0 0 1 0 0
v -0.8 0 0 0 1 0
v 0 0.8 0 0 0 1
v 0 -0.8 0 1 1 0
v 0 0 0.8 0 1 1
v 0 0 -0.8 1 0 1
f 1 3 5
f 3 2 5
f 2 4 5
f 4 1 5
f 3 1 6
f 2 3 6
f 4 2 6
f 1 4 6
";

#[test]
fn render_flags_map_to_the_settings_of_the_twin() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("twin");

    // Perspective from an explicit eye, non-square, and most raster flags off their defaults.
    let out = dir.path("perspective.exr");
    assert_success(
        "perspective",
        &render(
            &spot(),
            &out,
            &[
                "--width",
                "40",
                "--height",
                "24",
                "--eye",
                "1.2,0.9,-2.1",
                "--viewing-angle",
                "28",
                "--sigma",
                "3e-4",
                "--gamma",
                "3e-3",
                "--dist",
                "barycentric",
                "--alpha",
                "sum",
                "--near",
                "0.5",
                "--far",
                "8",
                "--background",
                "0.2,0.3,0.4",
                "--single-sided",
                "--antialias",
                "--texture-res",
                "2",
                "--ambient",
                "0.3",
                "--directional",
                "0.8",
                "--light-dir",
                "0.4,0.7,-0.6",
            ],
        ),
    );
    assert_matches_twin(
        "perspective",
        &out,
        &Mesh::load_obj(&spot(), 2).unwrap(),
        &Camera {
            eye: DVec3::new(1.2, 0.9, -2.1),
            at: DVec3::ZERO,
            up: DVec3::Y,
            projection: Projection::Perspective {
                viewing_angle_deg: 28.0,
            },
        },
        &Lighting {
            ambient_intensity: 0.3,
            ambient_color: [1.0; 3],
            directionals: vec![Directional {
                intensity: 0.8,
                color: [1.0; 3],
                direction: [0.4, 0.7, -0.6],
            }],
        },
        &RasterSettings {
            width: 40,
            height: 24,
            sigma: 3e-4,
            gamma: 3e-3,
            dist: Dist::Barycentric,
            alpha: Alpha::Sum,
            near: 0.5,
            far: 8.0,
            background: [0.2, 0.3, 0.4],
            double_sided: false,
            antialias: true,
            ..RasterSettings::default()
        },
    );

    // Orthographic from angles, portrait, hard colour and alpha.
    let out = dir.path("orthographic.exr");
    assert_success(
        "orthographic",
        &render(
            &spot(),
            &out,
            &[
                "--width",
                "20",
                "--height",
                "28",
                "--orthographic",
                "--scale",
                "0.9",
                "--distance",
                "3",
                "--elevation",
                "25",
                "--azimuth",
                "120",
                "--sigma",
                "1e-4",
                "--rgb",
                "hard",
                "--alpha",
                "hard",
                "--background",
                "1,1,1",
                "--light-dir",
                "0,0,-1",
            ],
        ),
    );
    assert_matches_twin(
        "orthographic",
        &out,
        &Mesh::load_obj(&spot(), 1).unwrap(),
        &Camera {
            projection: Projection::Orthographic { scale: 0.9 },
            ..Camera::from_angles(3.0, 25.0, 120.0)
        },
        &Lighting {
            directionals: vec![Directional {
                direction: [0.0, 0.0, -1.0],
                ..Directional::default()
            }],
            ..Lighting::default()
        },
        &RasterSettings {
            width: 20,
            height: 28,
            sigma: 1e-4,
            rgb: Rgb::Hard,
            alpha: Alpha::Hard,
            background: [1.0; 3],
            ..RasterSettings::default()
        },
    );

    // Vertex colours.
    let obj = dir.write("octahedron.obj", OCTAHEDRON);
    let out = dir.path("vertex.exr");
    assert_success(
        "vertex colours",
        &render(
            &obj,
            &out,
            &[
                "--size",
                "16",
                "--vertex-colors",
                "--elevation",
                "20",
                "--azimuth",
                "30",
                "--sigma",
                "1e-3",
                "--gamma",
                "1e-2",
                "--dist",
                "hard",
            ],
        ),
    );
    assert_matches_twin(
        "vertex colours",
        &out,
        &Mesh::load_obj(&obj, 1).unwrap(),
        &Camera::from_angles(2.732, 20.0, 30.0),
        &Lighting::default(),
        &RasterSettings {
            width: 16,
            height: 16,
            sigma: 1e-3,
            gamma: 1e-2,
            dist: Dist::Hard,
            color_mode: ColorMode::Vertex,
            ..RasterSettings::default()
        },
    );
}

/// The run failed with exactly one stderr line, `softvk: error: ...` containing `needle`, and
/// printed nothing on stdout.
fn assert_one_error_line(what: &str, out: &Output, needle: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{what}: succeeded");
    assert_eq!(
        stderr.lines().count(),
        1,
        "{what}: expected one line, got:\n{stderr}"
    );
    assert!(stderr.starts_with("softvk: error: "), "{what}: {stderr}");
    assert!(
        stderr.contains(needle),
        "{what}: the error should mention `{needle}`: {stderr}"
    );
    assert!(out.stdout.is_empty(), "{what}: printed on stdout");
}

const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";

/// The default (tiled) render and `--brute` write the same file, byte for byte, at two tile
/// sizes; a tile size that is not a multiple of 8 is one error line.
/// `--normalize` (SoftRas's `load_obj(normalization=True)`): a 81 920-face sphere as a scan is
/// distributed, 0.15 units across and off the origin, fills the frame at 64², centred, instead
/// of covering a few pixels.
#[test]
fn render_normalize_fills_the_frame_with_a_mesh_in_its_own_units() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("normalize");
    let mut sphere = softvk::mesh::Mesh::icosphere(6);
    assert_eq!(sphere.face_count(), 81_920);
    for p in &mut sphere.positions {
        *p = [0.075 * p[0] + 0.3, 0.075 * p[1] - 0.2, 0.075 * p[2] + 0.1];
    }
    let mesh = dir.path("small.obj");
    softvk::io::write_obj(&mesh, &sphere.positions, &sphere.faces).unwrap();
    let out = dir.path("normalized.exr");
    let done = render(&mesh, &out, &["--size", "64", "--normalize"]);
    assert_success("--normalize", &done);
    let (w, h, px) = read_exr(&out);
    let inside: Vec<(usize, usize)> = (0..w * h)
        .filter(|&i| px[i][3] > 0.5)
        .map(|i| (i % w, i / w))
        .collect();
    let span = |k: fn(&(usize, usize)) -> usize| {
        let (lo, hi) = (
            inside.iter().map(k).min().unwrap(),
            inside.iter().map(k).max().unwrap(),
        );
        (lo, hi)
    };
    // The unit sphere seen from SoftRas's default distance (2.732) through 30° spans
    // tan(asin(1 / 2.732)) / tan 30° ≈ 0.68 of the view: about 44 of 64 pixels, centred.
    for (lo, hi) in [span(|p| p.0), span(|p| p.1)] {
        assert!(
            hi - lo + 1 >= 40,
            "normalized sphere spans pixels {lo}..={hi}"
        );
        assert!(
            (lo as i64 - (63 - hi) as i64).abs() <= 1,
            "not centred: {lo}..={hi}"
        );
    }
}

#[test]
fn tiled_and_brute_renders_write_the_same_bytes() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("methods");
    let args = [
        "--width",
        "40",
        "--height",
        "24",
        "--sigma",
        "3e-4",
        "--antialias",
    ];
    let brute = dir.path("brute.exr");
    assert_success(
        "brute",
        &render(&spot(), &brute, &[&args[..], &["--brute"]].concat()),
    );
    for tile in ["8", "32"] {
        let tiled = dir.path(&format!("tiled{tile}.exr"));
        assert_success(
            tile,
            &render(&spot(), &tiled, &[&args[..], &["--tile", tile]].concat()),
        );
        assert!(
            std::fs::read(&tiled).unwrap() == std::fs::read(&brute).unwrap(),
            "tile {tile}: the EXR differs from the brute-force one"
        );
    }
    let bad = dir.path("bad.exr");
    let out = render(&spot(), &bad, &["--size", "8", "--tile", "12"]);
    assert_one_error_line("tile 12", &out, "tile size 12");
    assert!(!bad.exists());
}

#[test]
fn render_errors_are_one_line_and_write_nothing() {
    let dir = TempDir::new("errors");
    let triangle = dir.write("triangle.obj", TRIANGLE);
    let malformed = dir.write("malformed.obj", "v 0 0 zero\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let nan = dir.write("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
    let no_faces = dir.write("no_faces.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n");
    let missing = dir.path("missing.obj");
    dir.write("a_file", "");
    let before = dir.entries();

    let out_png = dir.path("out.png");
    let cases: Vec<(&str, &Path, PathBuf, Vec<&str>, &str)> = vec![
        (
            "missing mesh",
            &missing,
            out_png.clone(),
            vec![],
            "missing.obj",
        ),
        (
            "malformed OBJ",
            &malformed,
            out_png.clone(),
            vec![],
            "malformed.obj",
        ),
        ("NaN vertex", &nan, out_png.clone(), vec![], "NaN"),
        ("no faces", &no_faces, out_png.clone(), vec![], "no faces"),
        (
            "size 0",
            &triangle,
            out_png.clone(),
            vec!["--size", "0"],
            "--size",
        ),
        (
            "size 100000",
            &triangle,
            out_png.clone(),
            vec!["--width", "100000", "--height", "8"],
            "--width",
        ),
        (
            "bad enum",
            &triangle,
            out_png.clone(),
            vec!["--dist", "manhattan"],
            "possible values",
        ),
        (
            "sigma 0",
            &triangle,
            out_png.clone(),
            vec!["--sigma", "0"],
            "--sigma",
        ),
        (
            "gamma < 0",
            &triangle,
            out_png.clone(),
            vec!["--gamma", "-1"],
            "--gamma",
        ),
        (
            "NaN number",
            &triangle,
            out_png.clone(),
            vec!["--far", "nan"],
            "finite",
        ),
        (
            "near >= far",
            &triangle,
            out_png.clone(),
            vec!["--near", "5", "--far", "5"],
            "near",
        ),
        (
            "bad triple",
            &triangle,
            out_png.clone(),
            vec!["--background", "1,1"],
            "three",
        ),
        (
            "eye at the target",
            &triangle,
            out_png.clone(),
            vec!["--eye", "0,0,0"],
            "eye",
        ),
        (
            "size and width",
            &triangle,
            out_png.clone(),
            vec!["--size", "8", "--width", "8", "--height", "8"],
            "--size",
        ),
        (
            "no vertex colours",
            &triangle,
            out_png.clone(),
            vec!["--vertex-colors"],
            "vertex colours",
        ),
        (
            "missing output dir",
            &triangle,
            dir.path("nowhere/out.png"),
            vec![],
            "nowhere",
        ),
        (
            "output dir is a file",
            &triangle,
            dir.path("a_file/out.png"),
            vec![],
            "a_file",
        ),
        (
            "unknown extension",
            &triangle,
            dir.path("out.jpg"),
            vec![],
            ".png or .exr",
        ),
        (
            "no extension",
            &triangle,
            dir.path("out"),
            vec![],
            ".png or .exr",
        ),
    ];
    for (what, mesh, out, args, needle) in &cases {
        let result = render(mesh, out, args);
        assert_one_error_line(what, &result, needle);
        assert_eq!(dir.entries(), before, "{what}: a file was written");
    }

    // After the output's temporary file exists: scenes the device cannot hold (an image, and
    // per-face textures), and no device. Each names the buffer and the bytes it needs.
    if !common::no_gpu() {
        let result = render(&triangle, &out_png, &["--size", "16384", "--antialias"]);
        assert_one_error_line("too large for the device", &result, "too large");
        // 32768² pixels × RGBA f32.
        assert_one_error_line("too large for the device", &result, "image buffer");
        assert_one_error_line("too large for the device", &result, "17179869184 bytes");
        assert_eq!(dir.entries(), before, "too large: a file was written");

        let result = render(&spot(), &out_png, &["--size", "8", "--texture-res", "64"]);
        assert_one_error_line("textures too large", &result, "too large");
        // 5856 faces × 64² texels × RGB f32.
        assert_one_error_line("textures too large", &result, "colour buffer");
        assert_one_error_line("textures too large", &result, "287834112 bytes");
        assert_one_error_line("textures too large", &result, "--texture-res 64");
        assert_eq!(
            dir.entries(),
            before,
            "textures too large: a file was written"
        );
    }
    std::fs::write(&out_png, b"old").unwrap();
    let result = softvk()
        .args(["render", "--size", "8", "--mesh"])
        .arg(&triangle)
        .arg("--out")
        .arg(&out_png)
        .env("VK_ICD_FILENAMES", "/nonexistent/softvk-test-icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/softvk-test-icd.json")
        .env_remove("SOFTVK_VALIDATION")
        .output()
        .unwrap();
    assert!(!result.status.success());
    // The loader may print its own complaints; softvk says one thing.
    let stderr = String::from_utf8_lossy(&result.stderr);
    let ours: Vec<_> = stderr.lines().filter(|l| l.starts_with("softvk")).collect();
    assert_eq!(
        ours.len(),
        1,
        "no device: expected one error line, got:\n{stderr}"
    );
    assert!(
        ours[0].starts_with("softvk: error: ") && ours[0].contains("Vulkan"),
        "{}",
        ours[0]
    );
    assert_eq!(
        std::fs::read(&out_png).unwrap(),
        b"old",
        "no device: the old image was touched"
    );
    std::fs::remove_file(&out_png).unwrap();
    assert_eq!(dir.entries(), before, "no device: a temporary was left");
}

/// A mesh whose MTL or texture is missing renders (white, or the material's Kd) with one warning
/// line naming the missing file; a mesh with all its files renders with nothing on stderr.
#[test]
fn render_warns_once_about_a_missing_mtl_or_texture() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("warnings");
    dir.write("t.mtl", "newmtl skin\nKd 0.5 0.5 0.5\nmap_Kd gone.png\n");
    let textured = dir.write(
        "textured.obj",
        "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nusemtl skin\nf 1/1 2/1 3/1\n",
    );
    let sphere = softvk::assets::dir().join("sphere_642.obj");
    for (what, mesh, missing) in [
        ("missing MTL", &sphere, "sphere_642.mtl"),
        ("missing texture", &textured, "gone.png"),
    ] {
        let out = dir.path("out.png");
        let result = render(mesh, &out, &["--size", "8"]);
        assert_success(what, &result);
        assert!(out.is_file(), "{what}: no image");
        std::fs::remove_file(&out).unwrap();
        let stderr = String::from_utf8_lossy(&result.stderr);
        let lines: Vec<&str> = stderr.lines().collect();
        assert_eq!(
            lines.len(),
            1,
            "{what}: expected one warning line, got:\n{stderr}"
        );
        assert!(
            lines[0].starts_with("softvk: warning: ") && lines[0].contains("not found"),
            "{what}: {stderr}"
        );
        assert!(
            lines[0].contains(missing) && lines[0].contains(&*mesh.to_string_lossy()),
            "{what}: the warning should name {missing} and the mesh: {stderr}"
        );
    }
    let result = render(&spot(), &dir.path("spot.png"), &["--size", "8"]);
    assert_success("spot", &result);
    assert!(
        result.stderr.is_empty(),
        "spot has its MTL and texture: {}",
        String::from_utf8_lossy(&result.stderr)
    );
}

/// Writes an RGBA f32 EXR (row 0 at the top).
fn write_exr(path: &Path, w: usize, h: usize, px: &[[f32; 4]]) {
    exr::prelude::write_rgba_file(path, w, h, |x, y| {
        let p = px[y * w + x];
        (p[0], p[1], p[2], p[3])
    })
    .unwrap();
}

fn grad_cmd(mesh: &Path, weights: &Path, out: &Path, args: &[&str]) -> Output {
    softvk()
        .arg("grad")
        .arg("--mesh")
        .arg(mesh)
        .arg("--weights")
        .arg(weights)
        .arg("--out")
        .arg(out)
        .args(args)
        .output()
        .unwrap()
}

/// `softvk grad` writes `vertex,dx,dy,dz` for every vertex, equal to the f64 twin's gradient of
/// Σ W ⊙ image within 1e-3 of the largest component; the camera CSV likewise.
#[test]
fn grad_writes_the_twins_vertex_gradient_as_csv() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    use rand::RngExt;
    let dir = TempDir::new("grad");
    let (w, h) = (24usize, 20usize);
    let mut rng = common::rng(3);
    let weights: Vec<[f32; 4]> = (0..w * h)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect();
    let wpath = dir.path("w.exr");
    write_exr(&wpath, w, h, &weights);
    let sphere = softvk::assets::dir().join("sphere_642.obj");
    let out = dir.path("g.csv");
    let cam_out = dir.path("c.csv");
    let args = [
        "--sigma",
        "1e-2",
        "--gamma",
        "5e-2",
        "--elevation",
        "20",
        "--azimuth",
        "30",
        "--camera-out",
    ];
    let mut full: Vec<&str> = args.to_vec();
    full.push(cam_out.to_str().unwrap());
    let o = grad_cmd(&sphere, &wpath, &out, &full);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("vertex,dx,dy,dz"));
    let got: Vec<[f64; 3]> = lines
        .enumerate()
        .map(|(i, l)| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), 4, "{l}");
            assert_eq!(f[0].parse::<usize>().unwrap(), i);
            std::array::from_fn(|k| f[k + 1].parse::<f64>().unwrap())
        })
        .collect();

    let mesh = Mesh::load_obj(&sphere, 1).unwrap();
    assert_eq!(got.len(), mesh.vertex_count());
    let cam = Camera::from_angles(2.732, 20.0, 30.0);
    let s = RasterSettings {
        width: w as u32,
        height: h as u32,
        sigma: 1e-2,
        gamma: 5e-2,
        ..RasterSettings::default()
    };
    let w64: Vec<[f64; 4]> = weights.iter().map(|p| p.map(f64::from)).collect();
    let want = softvk::raster::reference_grad::grad(&mesh, &[cam], &Lighting::default(), &s, &w64)
        .unwrap();
    let scale = want
        .positions
        .iter()
        .flatten()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    assert!(scale > 0.0);
    for (v, (g, t)) in got.iter().zip(&want.positions).enumerate() {
        for k in 0..3 {
            assert!(
                (g[k] - t[k]).abs() <= 1e-3 * scale,
                "vertex {v}: {g:?} vs twin {t:?} (scale {scale})"
            );
        }
    }
    let cam_text = std::fs::read_to_string(&cam_out).unwrap();
    let rows: Vec<(String, f64)> = cam_text
        .lines()
        .skip(1)
        .map(|l| {
            let (k, v) = l.split_once(',').unwrap();
            (k.to_string(), v.parse().unwrap())
        })
        .collect();
    let angles = want.cameras[0].angles(2.732, 20.0, 30.0);
    let expect = [
        ("eye_x", want.cameras[0].eye[0]),
        ("eye_y", want.cameras[0].eye[1]),
        ("eye_z", want.cameras[0].eye[2]),
        ("distance", angles[0]),
        ("elevation", angles[1]),
        ("azimuth", angles[2]),
    ];
    let cscale = expect.iter().fold(0.0f64, |m, e| m.max(e.1.abs()));
    for ((name, value), (k, v)) in expect.iter().zip(&rows) {
        assert_eq!(name, k);
        assert!(
            (value - v).abs() <= 1e-3 * cscale,
            "{name}: {v} vs twin {value}"
        );
    }
}

#[test]
fn grad_errors_are_one_line_and_write_nothing() {
    let dir = TempDir::new("grad-errors");
    let triangle = dir.write("triangle.obj", TRIANGLE);
    let w8 = dir.path("w8.exr");
    write_exr(&w8, 8, 8, &vec![[1.0; 4]; 64]);
    let nan = dir.path("nan.exr");
    let mut px = vec![[0.5f32; 4]; 64];
    px[9][2] = f32::NAN;
    write_exr(&nan, 8, 8, &px);
    let not_exr = dir.write("not.exr", "hello");
    let out = dir.path("g.csv");
    let cases: Vec<(&str, PathBuf, Vec<&str>, &str)> = vec![
        ("missing weights", dir.path("none.exr"), vec![], "none.exr"),
        ("not an EXR", not_exr, vec![], "not.exr"),
        ("NaN weight", nan, vec![], "not finite"),
        ("size mismatch", w8.clone(), vec!["--size", "16"], "8x8"),
        ("bad tile", w8.clone(), vec!["--tile", "12"], "tile size 12"),
    ];
    for (what, weights, args, needle) in cases {
        let o = grad_cmd(&triangle, &weights, &out, &args);
        assert_one_error_line(what, &o, needle);
        assert!(!out.exists(), "{what}: wrote {}", out.display());
    }
}

/// A tiny fit end to end: silhouettes and cameras written by the library's own writers, five
/// iterations; the mesh and every report file appear.
#[test]
fn fit_mesh_writes_the_mesh_and_its_report() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    use softvk::io::{self, CameraRow};
    let dir = TempDir::new("fit-mesh");
    let sil = dir.path("sil");
    let size = 16u32;
    let px = (size * size) as usize;
    // A centred disc in every view.
    let disc: Vec<f32> = (0..px)
        .map(|i| {
            let (x, y) = ((i % 16) as f32 - 7.5, (i / 16) as f32 - 7.5);
            f32::from(u8::from(x * x + y * y < 30.0))
        })
        .collect();
    let masks: Vec<f32> = (0..3).flat_map(|_| disc.iter().copied()).collect();
    io::write_silhouettes(&sil, &io::silhouette_names(3), size, size, &masks).unwrap();
    let rows: Vec<CameraRow> = (0..3)
        .map(|i| CameraRow {
            distance: 2.732,
            elevation: 30.0,
            azimuth: 120.0 * f64::from(i),
        })
        .collect();
    let cams = dir.path("cameras.csv");
    io::write_cameras(&cams, &rows).unwrap();
    let out = dir.path("fitted.obj");
    let o = softvk()
        .args(["fit-mesh", "--iters", "5", "--log-every", "2", "--quiet"])
        .arg("--silhouettes")
        .arg(&sil)
        .arg("--cameras")
        .arg(&cams)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mesh = Mesh::load_obj(&out, 1).unwrap();
    // SoftRas's sphere_1352 is the default template; the icosphere is one flag away.
    assert_eq!(mesh.face_count(), default_template().face_count());
    assert_eq!(mesh.face_count(), 2700);
    let ico = dir.path("ico.obj");
    let o = softvk()
        .args([
            "fit-mesh",
            "--iters",
            "1",
            "--quiet",
            "--template",
            "icosphere",
        ])
        .arg("--silhouettes")
        .arg(&sil)
        .arg("--cameras")
        .arg(&cams)
        .arg("--out")
        .arg(&ico)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        Mesh::load_obj(&ico, 1).unwrap().face_count(),
        Mesh::icosphere(3).face_count()
    );
    let report = dir.path("fitted-report");
    for f in ["ious.csv", "contact_sheet.png", "loss.png", "progress.gif"] {
        assert!(report.join(f).is_file(), "{f} missing");
    }
    let ious = std::fs::read_to_string(report.join("ious.csv")).unwrap();
    assert_eq!(ious.lines().count(), 1 + 3 + 1, "{ious}");
}

/// A UV sphere of `lon` meridians and `rings` bands (`2 lon (rings − 1)` faces) as OBJ text.
fn uv_sphere_obj(lon: u32, rings: u32) -> String {
    use std::fmt::Write;
    let mut obj = String::from("v 0 1 0\n");
    for r in 1..rings {
        let th = std::f64::consts::PI * f64::from(r) / f64::from(rings);
        for k in 0..lon {
            let ph = std::f64::consts::TAU * f64::from(k) / f64::from(lon);
            let (x, y, z) = (th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin());
            writeln!(obj, "v {x:.6} {y:.6} {z:.6}").unwrap();
        }
    }
    obj.push_str("v 0 -1 0\n");
    // 1-based: the north pole, the rings, the south pole.
    let at = |r: u32, k: u32| 2 + (r - 1) * lon + k % lon;
    let south = 2 + (rings - 1) * lon;
    for k in 0..lon {
        writeln!(obj, "f 1 {} {}", at(1, k + 1), at(1, k)).unwrap();
        writeln!(
            obj,
            "f {south} {} {}",
            at(rings - 1, k),
            at(rings - 1, k + 1)
        )
        .unwrap();
    }
    for r in 1..rings - 1 {
        for k in 0..lon {
            let (a, b, c, d) = (at(r, k), at(r, k + 1), at(r + 1, k), at(r + 1, k + 1));
            writeln!(obj, "f {a} {b} {d}\nf {a} {d} {c}").unwrap();
        }
    }
    obj
}

/// A template of 100 000 faces at 64²: some tiles hold more faces than one shader invocation
/// may loop over on llvmpipe, as far as the guarded binning knows (its bound is the face
/// count), so the fit's forward folds them in passes, and the report's turntable renders its
/// 24 frames in as many batches as the face setups need. A few iterations run and write it.
#[test]
fn fit_mesh_takes_a_100k_face_template_at_64() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("fit-mesh-100k");
    let (sil, cams) = common::write_disc_inputs(&dir, 64);
    let template = dir.write("sphere_100k.obj", &uv_sphere_obj(250, 201));
    let out = dir.path("fitted.obj");
    let o = softvk()
        .args([
            "fit-mesh",
            "--iters",
            "3",
            "--log-every",
            "1",
            "--quiet",
            "--template",
        ])
        .arg(&template)
        .arg("--silhouettes")
        .arg(&sil)
        .arg("--cameras")
        .arg(&cams)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fitted = Mesh::load_obj(&out, 1).unwrap();
    assert_eq!(fitted.face_count(), 100_000);
    assert!(dir.path("fitted-report").join("turntable.gif").is_file());
    // Every iteration logged: the losses finite and the silhouette term falling, and 100 000
    // faces on 64 tiles of 8×8 pixels: far more (face, tile) entries than faces, so that faces
    // were split across tiles and tiles hold thousands of faces each (the crowded case the
    // passes fold). (The total rises over these three iterations: the flatten term of this
    // UV sphere, whose pole rows are slivers, starts near 8 000 and grows with the first Adam
    // steps; at weight 3e-4 it outweighs the silhouette's fall.)
    let log = std::fs::read_to_string(dir.path("fitted-report").join("loss.csv")).unwrap();
    let rows: Vec<Vec<f64>> = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 3, "{log}");
    assert!(
        rows.iter().all(|r| r.iter().all(|x| x.is_finite())),
        "{log}"
    );
    assert!(
        rows[2][2] < rows[0][2],
        "the silhouette loss does not fall: {log}"
    );
    assert!(rows.iter().all(|r| r[5] > 100_000.0), "{log}");
    // The vertices moved.
    let start = Mesh::load_obj(&template, 1).unwrap();
    let moved = start
        .positions
        .iter()
        .zip(&fitted.positions)
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        moved * 2 > start.positions.len(),
        "{moved} of {} vertices moved",
        start.positions.len()
    );
}

#[test]
fn fit_mesh_errors_are_one_line_and_write_nothing() {
    use softvk::io::{self, CameraRow};
    let dir = TempDir::new("fit-errors");
    let sil = dir.path("sil");
    let disc: Vec<f32> = (0..64)
        .map(|i| f32::from(u8::from(i % 8 > 2 && i / 8 > 2)))
        .collect();
    io::write_silhouettes(
        &sil,
        &io::silhouette_names(2),
        8,
        8,
        &[disc.clone(), disc].concat(),
    )
    .unwrap();
    let empty = dir.path("empty_sil");
    io::write_silhouettes(&empty, &io::silhouette_names(1), 8, 8, &[0.0; 64]).unwrap();
    let row = CameraRow {
        distance: 2.732,
        elevation: 30.0,
        azimuth: 0.0,
    };
    let two = dir.path("two.csv");
    io::write_cameras(&two, &[row, row]).unwrap();
    let three = dir.path("three.csv");
    io::write_cameras(&three, &[row, row, row]).unwrap();
    let nan_template = dir.write("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
    let out = dir.path("m.obj");
    let no_dir = dir.path("none");
    let cases: Vec<(&str, &Path, &Path, Vec<&str>, &str)> = vec![
        ("missing silhouettes", &no_dir, &two, vec![], "none"),
        (
            "camera rows vs images",
            &sil,
            &three,
            vec![],
            "3 camera rows",
        ),
        ("empty silhouette", &empty, &two, vec![], "no pixel inside"),
        (
            "NaN template",
            &sil,
            &two,
            vec!["--template", nan_template.to_str().unwrap()],
            "NaN",
        ),
        (
            "size mismatch",
            &sil,
            &two,
            vec!["--size", "16"],
            "--size 16",
        ),
    ];
    for (what, s, c, args, needle) in cases {
        let o = softvk()
            .arg("fit-mesh")
            .arg("--silhouettes")
            .arg(s)
            .arg("--cameras")
            .arg(c)
            .arg("--out")
            .arg(&out)
            .args(&args)
            .output()
            .unwrap();
        assert_one_error_line(what, &o, needle);
        assert!(!out.exists(), "{what}: wrote the mesh");
        assert!(!dir.path("m-report").exists(), "{what}: wrote a report");
    }
}

/// `softvk bench` on a thin band of one scene writes the SPEC's JSON records for the forward,
/// the backward and forward+backward.
#[test]
fn bench_writes_json_records_for_every_pass() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("bench");
    let out = dir.path("b.json");
    let o = softvk()
        .args([
            "bench",
            "--scene",
            "spot-256",
            "--band",
            "8",
            "--repeat",
            "1",
            "--tile",
            "8",
            "--no-brute",
            "--json",
        ])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    for pass in ["\"forward\"", "\"backward\"", "\"forward+backward\""] {
        assert!(
            text.contains(&format!("\"pass\": {pass}")),
            "{pass} missing:\n{text}"
        );
    }
    for key in [
        "scene", "method", "tile", "gpu_ms", "wall_ms", "pairs", "device",
    ] {
        assert_eq!(
            text.matches(&format!("\"{key}\":")).count(),
            3,
            "{key} in every record:\n{text}"
        );
    }
}

/// `softvk demo`'s report is for people: a contact sheet at 3× the view size with each view's
/// IoU written under it, and a turntable of the fitted mesh beside the target's.
#[test]
fn demo_writes_a_labelled_contact_sheet_and_a_turntable() {
    use image::AnimationDecoder as _;
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("demo-report");
    let o = softvk()
        .args([
            "demo", "--views", "3", "--size", "16", "--iters", "2", "--quiet",
        ])
        .arg("--out")
        .arg(&dir.0)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = dir.path("report");
    let sheet = image::open(report.join("contact_sheet.png"))
        .unwrap()
        .to_rgb8();
    // Two columns (⌈√3⌉) of 48-pixel tiles, each with a label strip under it.
    assert!(sheet.width() >= 2 * 3 * 16, "{:?}", sheet.dimensions());
    assert!(
        sheet.height() >= 2 * 3 * 16 + 2 * 7,
        "{:?}",
        sheet.dimensions()
    );
    // The label strip under the first tile holds light text pixels.
    let strip = (1 + 48..1 + 48 + 10).flat_map(|y| (1..49).map(move |x| (x, y)));
    let lit = strip
        .filter(|&(x, y)| sheet.get_pixel(x, y)[0] > 200)
        .count();
    assert!(
        lit > 20,
        "no label under the first tile ({lit} light pixels)"
    );
    let gif = std::io::BufReader::new(std::fs::File::open(report.join("turntable.gif")).unwrap());
    let frames = image::codecs::gif::GifDecoder::new(gif)
        .unwrap()
        .into_frames()
        .collect_frames()
        .unwrap();
    assert_eq!(frames.len(), 24);
    let (w, h) = frames[0].buffer().dimensions();
    assert!(w >= 2 * 192 && h >= 192, "fitted beside target: {w}x{h}");
}

#[test]
fn dataset_writes_the_nmr_files_and_a_contact_sheet_and_refuses_bad_flags_writing_nothing() {
    use softvk::recon::dataset::{Dataset, Split};
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("dataset-cli");
    let out = dir.path("data");
    let run = softvk()
        .args(["dataset", "--out", out.to_str().unwrap()])
        .args([
            "--categories",
            "chair,04379243",
            "--train",
            "2",
            "--val",
            "0",
        ])
        .args(["--test", "1", "--seed", "5"])
        .env("SOFTVK_VALIDATION", "1")
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "softvk dataset failed: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "03001627_test_images.npz",
            "03001627_test_voxels.npz",
            "03001627_train_images.npz",
            "03001627_train_voxels.npz",
            "04379243_test_images.npz",
            "04379243_test_voxels.npz",
            "04379243_train_images.npz",
            "04379243_train_voxels.npz",
            "contact_sheet.png",
        ]
    );
    let train = Dataset::open(&out, Split::Train).unwrap();
    assert_eq!(train.classes.len(), 2);
    assert!(train.classes.iter().all(|c| c.count == 2));
    // Two classes × two objects, eight 64² views each.
    let sheet = image::open(out.join("contact_sheet.png")).unwrap();
    assert_eq!((sheet.width(), sheet.height()), (8 * 64, 4 * 64));

    for (flags, says) in [
        (vec!["--categories", "chair,spaceship"], "spaceship"),
        (
            vec!["--train", "0", "--val", "0", "--test", "0"],
            "at least one object",
        ),
        (vec!["--sigma=-1"], "sigma"),
    ] {
        let bad = dir.path("bad");
        let run = softvk()
            .args(["dataset", "--out", bad.to_str().unwrap()])
            .args(&flags)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{flags:?} succeeded");
        assert_eq!(stderr.lines().count(), 1, "{flags:?}: {stderr}");
        assert!(stderr.contains(says), "{flags:?}: {stderr}");
        let left = std::fs::read_dir(&bad).map_or(0, |d| d.count());
        assert_eq!(left, 0, "{flags:?} left files in {}", bad.display());
    }
}
