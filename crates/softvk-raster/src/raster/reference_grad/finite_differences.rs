//! The f64 backward against central finite differences of the forward, parameter by
//! parameter (positions, colours, cameras, angles), on scenes that exercise every mode; a step
//! that crosses one of the forward's kinks is detected and another jitter seed is tried.

use glam::DVec3;

use super::pixel::{argmin3, nearest_edge};
use super::tests::{lights, rng, scene, settings};
use super::{Gradients, forward_view, grad_f64};
use crate::camera::{Camera, Projection, look_at, pixel_center};
use crate::lighting::{Lighting, face_normals_of, vertex_normals_of};
use crate::raster::reference::{
    self, FaceColors, FaceSetup, MeshF64, barycentric, clip_barycentric, coverage, depth,
    render_f64, surface_texel_index,
};
use crate::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};
use rand::RngExt;

/// A view as the tests parametrize it: a camera, or [`Camera::from_angles`]'s parameters.
#[derive(Clone, Copy, Debug)]
enum View {
    Camera(Camera),
    Angles {
        distance: f64,
        elevation: f64,
        azimuth: f64,
        projection: Projection,
    },
}

impl View {
    fn camera(&self) -> Camera {
        match *self {
            View::Camera(c) => c,
            View::Angles {
                distance,
                elevation,
                azimuth,
                projection,
            } => Camera {
                projection,
                ..Camera::from_angles(distance, elevation, azimuth)
            },
        }
    }
}

/// One finite-difference check: scene, views, lights, settings and the random dL/dImage.
struct Case {
    mesh: MeshF64,
    views: Vec<View>,
    lighting: Lighting,
    settings: RasterSettings,
    weights: Vec<[f64; 4]>,
}

impl Case {
    fn new(mesh: MeshF64, views: Vec<View>, lighting: Lighting, settings: RasterSettings) -> Case {
        let mut r = rng(0x5eed);
        let n = views.len() * (settings.width * settings.height) as usize;
        let weights = (0..n)
            .map(|_| std::array::from_fn(|_| r.random_range(-1.0..1.0)))
            .collect();
        Case {
            mesh,
            views,
            lighting,
            settings,
            weights,
        }
    }

    fn cameras(&self) -> Vec<Camera> {
        self.views.iter().map(View::camera).collect()
    }
}

/// A parameter of the loss that finite differences perturb.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Param {
    Position(usize, usize),
    Color(usize, usize),
    Eye(usize, usize),
    At(usize, usize),
    Up(usize, usize),
    Angle(usize, usize),
}

impl Param {
    fn group(&self) -> &'static str {
        match self {
            Param::Position(..) => "positions",
            Param::Color(..) => "colors",
            Param::Eye(..) => "eye",
            Param::At(..) => "at",
            Param::Up(..) => "up",
            Param::Angle(..) => "angles",
        }
    }

    /// Whether it moves geometry (colours move no kink).
    fn geometric(&self) -> bool {
        !matches!(self, Param::Color(..))
    }
}

fn params(case: &Case) -> Vec<Param> {
    let mut out = Vec::new();
    for i in 0..case.mesh.positions.len() {
        out.extend((0..3).map(|k| Param::Position(i, k)));
    }
    let colors = match case.settings.color_mode {
        ColorMode::Surface => case.mesh.textures.len(),
        ColorMode::Vertex => case.mesh.positions.len(),
    };
    for i in 0..colors {
        out.extend((0..3).map(|k| Param::Color(i, k)));
    }
    for (v, view) in case.views.iter().enumerate() {
        if matches!(view.camera().projection, Projection::Matrix { .. }) {
            continue;
        }
        for k in 0..3 {
            out.extend([Param::Eye(v, k), Param::At(v, k), Param::Up(v, k)]);
        }
        if matches!(view, View::Angles { .. }) {
            out.extend((0..3).map(|k| Param::Angle(v, k)));
        }
    }
    out
}

/// The case with one parameter moved by `delta`: its mesh and cameras.
fn perturbed(case: &Case, p: Param, delta: f64) -> (MeshF64, Vec<Camera>) {
    let mut mesh = case.mesh.clone();
    let mut views = case.views.clone();
    match p {
        Param::Position(i, k) => mesh.positions[i][k] += delta,
        Param::Color(i, k) => match case.settings.color_mode {
            ColorMode::Surface => mesh.textures[i][k] += delta,
            ColorMode::Vertex => mesh.vertex_colors.as_mut().unwrap()[i][k] += delta,
        },
        Param::Angle(v, k) => {
            if let View::Angles {
                distance,
                elevation,
                azimuth,
                ..
            } = &mut views[v]
            {
                *[distance, elevation, azimuth][k] += delta;
            }
        }
        _ => {}
    }
    let mut cameras: Vec<Camera> = views.iter().map(View::camera).collect();
    match p {
        Param::Eye(v, k) => cameras[v].eye[k] += delta,
        Param::At(v, k) => cameras[v].at[k] += delta,
        Param::Up(v, k) => cameras[v].up[k] += delta,
        _ => {}
    }
    (mesh, cameras)
}

fn param_value(case: &Case, p: Param) -> f64 {
    let cams = case.cameras();
    match p {
        Param::Position(i, k) => case.mesh.positions[i][k],
        Param::Color(i, k) => match case.settings.color_mode {
            ColorMode::Surface => case.mesh.textures[i][k],
            ColorMode::Vertex => case.mesh.vertex_colors.as_ref().unwrap()[i][k],
        },
        Param::Eye(v, k) => cams[v].eye[k],
        Param::At(v, k) => cams[v].at[k],
        Param::Up(v, k) => cams[v].up[k],
        Param::Angle(v, k) => match case.views[v] {
            View::Angles {
                distance,
                elevation,
                azimuth,
                ..
            } => [distance, elevation, azimuth][k],
            View::Camera(_) => unreachable!(),
        },
    }
}

fn analytic(case: &Case, g: &Gradients, p: Param) -> f64 {
    match p {
        Param::Position(i, k) => g.positions[i][k],
        Param::Color(i, k) => g.colors[i][k],
        Param::Eye(v, k) => g.cameras[v].eye[k],
        Param::At(v, k) => g.cameras[v].at[k],
        Param::Up(v, k) => g.cameras[v].up[k],
        Param::Angle(v, k) => match case.views[v] {
            View::Angles {
                distance,
                elevation,
                azimuth,
                ..
            } => g.cameras[v].angles(distance, elevation, azimuth)[k],
            View::Camera(_) => unreachable!(),
        },
    }
}

fn images(case: &Case, mesh: &MeshF64, cameras: &[Camera]) -> Vec<[f64; 4]> {
    cameras
        .iter()
        .flat_map(|c| render_f64(mesh, c, &case.lighting, &case.settings).unwrap())
        .collect()
}

/// Every discrete decision the forward takes, for the kink guard: per (rendered pixel,
/// face) whether the face is ignored, each barycentric's side of 0 and 1 (clip, inside
/// sign, hard tests), the clip floor, the near/far and facing tests, the nearest edge, the
/// smallest barycentric, the texel, the determinant clamp; per pixel the hard winner and
/// the count of coverages that round to 1; per normal and light the side of `max(0, ·)`.
/// Equal signatures at `p − h`, `p` and `p + h` mean the central difference crosses no kink.
fn signature(case: &Case, mesh: &MeshF64, cameras: &[Camera]) -> Vec<u64> {
    let s = &case.settings;
    let mut sig = Vec::new();
    let normals = match s.color_mode {
        ColorMode::Surface => face_normals_of(&mesh.positions, &mesh.faces),
        ColorMode::Vertex => vertex_normals_of(&mesh.positions, &mesh.faces),
    };
    for n in normals {
        for l in &case.lighting.directionals {
            sig.push(u64::from(n.dot(DVec3::from(l.direction)) > 0.0));
        }
    }
    let colors = FaceColors::of(mesh, &case.lighting, s.color_mode);
    let t = s.cutoff();
    for camera in cameras {
        let fwd = forward_view(mesh, camera, &colors, s);
        for row in 0..fwd.height {
            for col in 0..fwd.width {
                let i = (row * fwd.width + col) as usize;
                sig.push(u64::from(fwd.aux[i].hard_face));
                sig.push(u64::from(fwd.aux[i].alpha_zeros));
                let (xp, yp) = pixel_center(col, row, fwd.width, fwd.height);
                for face in &fwd.faces {
                    sig.push(pair_code(face, (xp, yp), s, t, mesh.texture_res));
                }
            }
        }
    }
    sig
}

fn pair_code(
    face: &FaceSetup,
    (xp, yp): (f64, f64),
    s: &RasterSettings,
    t: f64,
    texture_res: u32,
) -> u64 {
    if !face.finite {
        return 0;
    }
    let w = barycentric(face, xp, yp);
    if coverage(face, &w, xp, yp, s.dist, s.sigma, t).is_none() {
        return 1;
    }
    let mut code = 2u64;
    let mut push = |value: u64, radix: u64| code = code * radix + value;
    for x in w {
        push(
            if x < 0.0 {
                0
            } else if x > 1.0 {
                2
            } else {
                1
            },
            3,
        );
    }
    let clamped = w.map(|x| x.clamp(0.0, 1.0));
    push(
        u64::from(clamped[0] + clamped[1] + clamped[2] < reference::CLIP_SUM_FLOOR),
        2,
    );
    let w_clip = clip_barycentric(w);
    let z = depth(face, &w_clip);
    push(u64::from(z >= s.near && z <= s.far), 2);
    push(u64::from(face.front), 2);
    // The nearest feature: a vertex (where two edges tie) or an edge's interior.
    let (_, a, b, t_edge) = nearest_edge(&face.v, [xp, yp]);
    push(
        if t_edge == 0.0 {
            a as u64
        } else if t_edge == 1.0 {
            b as u64
        } else {
            3 + a as u64
        },
        6,
    );
    push(argmin3(&w) as u64, 3);
    let det = reference::screen_det(&face.v);
    push(u64::from(reference::clamp_det(det) != det), 2);
    if s.color_mode == ColorMode::Surface {
        push(surface_texel_index(&w_clip, texture_res) as u64, 4096);
    }
    code
}

/// What one finite-difference comparison found for one group of parameters.
#[derive(Debug, Default)]
struct GroupReport {
    count: usize,
    significant: usize,
    max_fd: f64,
    worst_rel: f64,
    worst_small_abs: f64,
}

const FD_REL_STEP: f64 = 1e-6;

const REL_TOL: f64 = 1e-5;

const SIGNIFICANT: f64 = 1e-3;

/// Central differences of every parameter against [`grad_f64`]; `Err` names a parameter
/// whose step crosses a kink (the signature changed).
fn fd_compare(case: &Case) -> Result<Vec<(&'static str, GroupReport)>, Param> {
    let cams = case.cameras();
    let s = &case.settings;
    let base_sig = signature(case, &case.mesh, &cams);
    let g = grad_f64(&case.mesh, &cams, &case.lighting, s, &case.weights).unwrap();
    let mut rows = Vec::new();
    for p in params(case) {
        let h = FD_REL_STEP * param_value(case, p).abs().max(1.0);
        let (mesh_p, cams_p) = perturbed(case, p, h);
        let (mesh_m, cams_m) = perturbed(case, p, -h);
        if p.geometric()
            && (signature(case, &mesh_p, &cams_p) != base_sig
                || signature(case, &mesh_m, &cams_m) != base_sig)
        {
            return Err(p);
        }
        // Differences per pixel first: pixels the step does not touch add exactly 0.
        let plus = images(case, &mesh_p, &cams_p);
        let minus = images(case, &mesh_m, &cams_m);
        let mut diff = 0.0;
        for ((a, b), w) in plus.iter().zip(&minus).zip(&case.weights) {
            for k in 0..4 {
                diff += w[k] * (a[k] - b[k]);
            }
        }
        rows.push((p, analytic(case, &g, p), diff / (2.0 * h)));
    }
    let mut groups: Vec<(&'static str, GroupReport)> = Vec::new();
    for &(p, _, fd) in &rows {
        match groups.iter_mut().find(|(n, _)| *n == p.group()) {
            Some((_, r)) => r.max_fd = r.max_fd.max(fd.abs()),
            None => groups.push((
                p.group(),
                GroupReport {
                    max_fd: fd.abs(),
                    ..GroupReport::default()
                },
            )),
        }
    }
    for &(p, an, fd) in &rows {
        let r = &mut groups.iter_mut().find(|(n, _)| *n == p.group()).unwrap().1;
        r.count += 1;
        let err = (an - fd).abs();
        if fd.abs() >= SIGNIFICANT * r.max_fd {
            r.significant += 1;
            if err / fd.abs() > r.worst_rel {
                r.worst_rel = err / fd.abs();
            }
            if err > REL_TOL * fd.abs() {
                eprintln!("  {p:?}: analytic {an:.12e} fd {fd:.12e}");
            }
        } else {
            r.worst_small_abs = r.worst_small_abs.max(err / r.max_fd.max(f64::MIN_POSITIVE));
        }
    }
    Ok(groups)
}

/// Tries jitter seeds until one has no kink within a finite-difference step, then asserts
/// the tolerance on every group.
fn check_case(name: &str, build: impl Fn(u64) -> Case) {
    for seed in 0..8 {
        let case = build(seed);
        match fd_compare(&case) {
            Err(p) => eprintln!("{name}: seed {seed} crosses a kink at {p:?}, next seed"),
            Ok(groups) => {
                for (group, r) in &groups {
                    eprintln!("{name} seed {seed} {group}: {r:?}");
                    assert!(r.significant > 0 && r.max_fd > 0.0, "{name} {group}: {r:?}");
                    assert!(r.worst_rel <= REL_TOL, "{name} {group}: {r:?}");
                    assert!(
                        r.worst_small_abs <= REL_TOL * SIGNIFICANT,
                        "{name} {group}: {r:?}"
                    );
                }
                return;
            }
        }
    }
    panic!("{name}: every seed crosses a kink");
}

#[test]
fn fd_euclidean_prod_softmax_surface_r1_perspective_double_sided_with_angles() {
    check_case("euclid/prod/R1/persp", |seed| {
        Case::new(
            scene(seed, true, 1),
            vec![
                View::Angles {
                    distance: 2.732,
                    elevation: 15.0,
                    azimuth: -20.0,
                    projection: Projection::default(),
                },
                View::Camera(Camera {
                    eye: DVec3::new(0.4, 0.5, -2.6),
                    at: DVec3::new(0.05, -0.02, 0.1),
                    up: DVec3::new(0.1, 1.0, 0.05),
                    projection: Projection::default(),
                }),
            ],
            lights(),
            settings(12, 12),
        )
    });
}

fn ortho() -> Projection {
    Projection::Orthographic { scale: 0.6 }
}

#[test]
fn fd_euclidean_sum_softmax_surface_r3_orthographic_single_sided() {
    check_case("euclid/sum/R3/ortho/single", |seed| {
        Case::new(
            scene(seed, false, 3),
            vec![
                View::Camera(Camera {
                    projection: ortho(),
                    ..Camera::default()
                }),
                View::Camera(Camera {
                    eye: DVec3::new(-0.5, 0.3, -2.5),
                    at: DVec3::new(0.0, 0.1, 0.0),
                    up: DVec3::Y,
                    projection: ortho(),
                }),
            ],
            lights(),
            RasterSettings {
                sigma: 1e-2,
                gamma: 5e-2,
                alpha: Alpha::Sum,
                double_sided: false,
                near: 0.5,
                far: 10.0,
                background: [0.2, 0.3, 0.4],
                ..settings(14, 12)
            },
        )
    });
}

#[test]
fn fd_barycentric_prod_softmax_vertex_colors_perspective_antialiased() {
    check_case("bary/prod/vertex/persp/aa", |seed| {
        Case::new(
            scene(seed, true, 1),
            vec![View::Camera(Camera {
                eye: DVec3::new(0.3, -0.4, -2.7),
                ..Camera::default()
            })],
            lights(),
            RasterSettings {
                dist: Dist::Barycentric,
                gamma: 2e-2,
                color_mode: ColorMode::Vertex,
                antialias: true,
                far: 10.0,
                ..settings(8, 8)
            },
        )
    });
}

#[test]
fn fd_barycentric_sum_softmax_surface_r2_orthographic_single_sided_with_angles() {
    check_case("bary/sum/R2/ortho/single", |seed| {
        Case::new(
            scene(seed, true, 2),
            vec![View::Angles {
                distance: 3.0,
                elevation: -10.0,
                azimuth: 25.0,
                projection: ortho(),
            }],
            lights(),
            RasterSettings {
                dist: Dist::Barycentric,
                alpha: Alpha::Sum,
                sigma: 3e-2,
                gamma: 1e-1,
                double_sided: false,
                ..settings(12, 12)
            },
        )
    });
}

/// The a.e. derivative of hard colour: the winner's colour through w̃ (vertex colours).
#[test]
fn fd_euclidean_prod_hard_rgb_vertex_colors_perspective() {
    check_case("euclid/prod/hard-rgb/vertex", |seed| {
        Case::new(
            scene(seed, true, 1),
            vec![View::Angles {
                distance: 2.732,
                elevation: 20.0,
                azimuth: 10.0,
                projection: Projection::default(),
            }],
            lights(),
            RasterSettings {
                rgb: Rgb::Hard,
                color_mode: ColorMode::Vertex,
                ..settings(12, 12)
            },
        )
    });
}

/// Hard coverage, softmax colour: only depth and colour through w̃ move with the vertices
/// (γ large enough for the depth to blend overlapping faces).
#[test]
fn fd_hard_dist_softmax_vertex_colors_single_sided() {
    check_case("hard-dist/softmax/vertex", |seed| {
        Case::new(
            scene(seed, true, 1),
            vec![View::Camera(Camera::default())],
            lights(),
            RasterSettings {
                dist: Dist::Hard,
                alpha: Alpha::Sum,
                gamma: 1e-1,
                far: 5.0,
                color_mode: ColorMode::Vertex,
                double_sided: false,
                ..settings(12, 12)
            },
        )
    });
}

#[test]
fn fd_euclidean_prod_softmax_matrix_projection_with_distortion() {
    // K [R | t] of the default camera, for a 64-pixel image, plus Brown distortion (SoftRas
    // applies it to pixel coordinates, r² ~ 10³, hence the small coefficients).
    let cam = Camera::default();
    let r = look_at(cam.eye, cam.at, cam.up).map(DVec3::from);
    let t = r.map(|row| -row.dot(cam.eye));
    let f = 32.0 / 30f64.to_radians().tan();
    let k = [[f, 0.0, 32.0], [0.0, f, 32.0], [0.0, 0.0, 1.0]];
    let p: [[f64; 4]; 3] = std::array::from_fn(|i| {
        let kr = (0..3).fold(DVec3::ZERO, |acc, j| acc + r[j] * k[i][j]);
        let kt: f64 = (0..3).map(|j| k[i][j] * t[j]).sum();
        [kr.x, kr.y, kr.z, kt]
    });
    check_case("euclid/prod/matrix", |seed| {
        Case::new(
            scene(seed, true, 1),
            vec![View::Camera(Camera {
                projection: Projection::Matrix {
                    p,
                    dist_coeffs: [5e-5, -1e-9, 1e-4, -1e-4, 1e-12],
                    orig_size: 64.0,
                },
                ..cam
            })],
            lights(),
            settings(12, 12),
        )
    });
}
