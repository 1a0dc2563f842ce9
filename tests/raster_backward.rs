//! The GPU backward (tiled at 8, 16, 32, and brute force) against the f64 twin
//! `raster::reference_grad` (itself checked against central finite differences), on lavapipe
//! with validation on; determinism; and gradient descent on one triangle's silhouette.
//!
//! Bound: every component within 1e-3 of the largest component's magnitude, for
//! positions, colours and cameras separately; tiled and brute agree to the same bound. That
//! bound alone lets a component a thousand times smaller than the largest be wholly wrong, so
//! every component is also held to its own size ([`Bars`], set from measurement). The split
//! paths (partials in several chunks, brute-force bands, crowded tiles over several workgroups)
//! are checked against the twin and, where splitting must not change a single sum, against the
//! unsplit run bit for bit.

mod common;

use glam::DVec3;
use rand::RngExt;
use softvk::camera::{Camera, Projection};
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::primitives::binning::MASK_MAX_TILES_PER_VIEW;
use softvk::raster::backward::{GradBuffers, GradSplit};
use softvk::raster::gpu::{ExactRun, GpuScene, Method, Renderer};
use softvk::raster::reference_grad::{self, Gradients};
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};

const REL: f64 = 1e-3;
const METHODS: [Method; 4] = [
    Method::Brute,
    Method::Tiled { tile: 8 },
    Method::Tiled { tile: 16 },
    Method::Tiled { tile: 32 },
];

fn lighting() -> Lighting {
    Lighting {
        ambient_intensity: 0.4,
        ambient_color: [1.0, 0.9, 0.8],
        directionals: vec![Directional {
            intensity: 0.6,
            color: [1.0, 1.0, 0.9],
            direction: [0.3, 0.5, -0.8],
        }],
    }
}

fn random_colors(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = common::rng(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(0.1..0.9)))
        .collect()
}

/// A jittered icosphere(1) (80 faces) plus two triangles in front of and behind it, random
/// texels at resolution `res` and random vertex colours.
fn scene(res: u32, seed: u64) -> Mesh {
    let mut rng = common::rng(seed);
    let ico = Mesh::icosphere(1);
    let mut positions: Vec<[f32; 3]> = ico
        .positions
        .iter()
        .map(|p| p.map(|c| c * 0.6 + rng.random_range(-0.03..0.03)))
        .collect();
    let mut faces = ico.faces.clone();
    for (z, flip) in [(-0.7f32, false), (0.5, true)] {
        let base = positions.len() as u32;
        positions.extend([
            [-0.8 + rng.random_range(-0.05..0.05), -0.3, z],
            [0.1, 0.7 + rng.random_range(-0.05..0.05), z],
            [0.5, -0.6, z + 0.1],
        ]);
        faces.push(if flip {
            [base, base + 2, base + 1]
        } else {
            [base, base + 1, base + 2]
        });
    }
    let mut mesh = Mesh::new(positions, faces, res).unwrap();
    mesh.textures = random_colors(mesh.textures.len(), seed + 1);
    mesh.vertex_colors = Some(random_colors(mesh.vertex_count(), seed + 2));
    mesh
}

fn weights(n: usize, seed: u64) -> Vec<[f32; 4]> {
    let mut rng = common::rng(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)))
        .collect()
}

/// Largest |a − b| relative to the largest |b| of a component family.
fn rel_err(a: &[[f64; 3]], b: &[[f64; 3]]) -> (f64, f64) {
    common::rel_err3(a, b)
}

/// Per-component bars: `|got − want| ≤ rel·|want| + abs·scale`, `scale` the family's largest
/// |want|. Above `abs / rel` of the largest a component is held to `rel` of itself; below that
/// `abs` is the floor, where an error is judged against the largest instead.
#[derive(Clone, Copy, Debug)]
struct Bars {
    rel: f64,
    abs: f64,
}

/// Faces a few pixels wide or more, Euclidean or hard distance: what is left is f32 rounding in
/// the GPU's sums against the twin's f64. Measured over this file's scenes (every method), the
/// worst component uses a fifth of these bars, e.g. 1.3e-6 of the largest on a component of
/// 3e-3 of it; the floor is about 8 f32 ulps of the largest, under which a sum of terms as large
/// as the largest cannot resolve a component. Tiled against brute force (both f32) uses these
/// too, with a margin over 60.
const SMOOTH: Bars = Bars {
    rel: 2e-3,
    abs: 1e-6,
};

/// Where the distance's kinks matter: the barycentric clip, and sub-pixel faces (most pixels lie
/// near a vertex, where the nearest point leaves an edge for its end). A pixel near a kink gives
/// its term to one vertex in f32 and to another in f64, so a component fed by few pixels is off
/// by about one pixel's term, whatever its own size: moving the positions by one f32 ulp moves
/// the twin itself by 2.8e-4 of the largest (barycentric scene #10), as much as the GPU differs
/// from it there (2 % of a component of 1.3e-2 of the largest). These bars leave a margin of 3
/// over that, and of 7 over the 4 624 tiny faces, where the GPU gives 0 for two components of
/// 2.8e-5 of the largest.
const KINKED: Bars = Bars {
    rel: 5e-2,
    abs: 2e-4,
};

/// The largest share of its bar any component uses (≤ 1 passes), with where and how.
fn worst_component(a: &[[f64; 3]], b: &[[f64; 3]], bars: Bars) -> (f64, String) {
    let scale = b.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    let mut worst = (0.0, String::new());
    for (i, (x, y)) in a.iter().flatten().zip(b.iter().flatten()).enumerate() {
        let share = (x - y).abs() / (bars.rel * y.abs() + bars.abs * scale);
        if share > worst.0 {
            worst = (
                share,
                format!(
                    "component [{}][{}]: {x:.6e} against {y:.6e}, {:.2e} of itself, \
                     {:.2e} of the largest ({scale:.3e})",
                    i / 3,
                    i % 3,
                    (x - y).abs() / y.abs(),
                    (x - y).abs() / scale
                ),
            );
        }
    }
    worst
}

fn camera_rows(g: &Gradients) -> Vec<[f64; 3]> {
    g.cameras.iter().flat_map(|c| [c.eye, c.at, c.up]).collect()
}

/// Asserts `got` within [`REL`] of `want` per family, and every component within `bars`;
/// returns the worst relative error and the largest share of its bar a component used.
fn assert_close(
    what: &str,
    got: &Gradients,
    want: &Gradients,
    cameras: bool,
    bars: Bars,
) -> (f64, f64) {
    let mut worst = (0.0f64, 0.0f64);
    let mut families = vec![
        ("positions", got.positions.clone(), want.positions.clone()),
        ("colours", got.colors.clone(), want.colors.clone()),
    ];
    if cameras {
        families.push(("cameras", camera_rows(got), camera_rows(want)));
    }
    for (family, got, want) in families {
        let (err, scale) = rel_err(&got, &want);
        assert!(scale > 0.0, "{what}: {family} gradient is all zero");
        assert!(
            err <= REL,
            "{what}: {family} differ by {err:.2e} of the largest ({scale:.3e})"
        );
        let (share, at) = worst_component(&got, &want, bars);
        assert!(
            share <= 1.0,
            "{what}: {family} {at}: {share:.2} times {bars:?}"
        );
        worst = (worst.0.max(err), worst.1.max(share));
    }
    worst
}

fn forward(
    r: &Renderer,
    gpu: &common::Gpu,
    mesh: &Mesh,
    cams: &[Camera],
    s: &RasterSettings,
    method: Method,
) -> GpuScene {
    let mut scene = r.prepare(gpu, mesh, cams, &lighting(), s).unwrap();
    r.run(gpu, &mut scene, method).unwrap();
    scene
}

/// GPU (every method) vs the twin, and tiled vs brute, on one configuration.
fn check(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    cams: &[Camera],
    s: &RasterSettings,
    bars: Bars,
) -> (f64, f64) {
    let n = (s.width * s.height) as usize * cams.len();
    let w = weights(n, 99);
    let w64: Vec<[f64; 4]> = w.iter().map(|g| g.map(f64::from)).collect();
    let want = reference_grad::grad(mesh, cams, &lighting(), s, &w64).unwrap();
    let cameras = cams
        .iter()
        .all(|c| !matches!(c.projection, Projection::Matrix { .. }));
    let mut worst = (0.0f64, 0.0f64);
    let mut brute: Option<Gradients> = None;
    for method in METHODS {
        let scene = forward(r, gpu, mesh, cams, s, method);
        let got = r
            .backward(gpu, &scene.last_run().unwrap().binned(), &w, cameras)
            .unwrap_or_else(|e| panic!("{what} {method:?}: {e}"));
        let (err, share) = assert_close(
            &format!("{what} {method:?} vs twin"),
            &got,
            &want,
            cameras,
            bars,
        );
        worst = (worst.0.max(err), worst.1.max(share));
        match &brute {
            None => brute = Some(got),
            Some(b) => {
                let what = format!("{what} {method:?} vs brute");
                assert_close(&what, &got, b, cameras, SMOOTH);
            }
        }
    }
    worst
}

fn settings(w: u32, h: u32) -> RasterSettings {
    RasterSettings {
        width: w,
        height: h,
        sigma: 2e-2,
        gamma: 5e-2,
        near: 0.5,
        far: 10.0,
        ..RasterSettings::default()
    }
}

#[test]
fn gpu_gradients_match_the_twin_in_every_differentiable_mode() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let cams = [
        Camera::from_angles(2.732, 15.0, 20.0),
        Camera::from_angles(2.5, -10.0, 150.0),
    ];
    let ortho = [Camera {
        projection: Projection::Orthographic { scale: 0.9 },
        ..Camera::from_angles(2.732, 25.0, -40.0)
    }];
    let mut worst = (0.0f64, 0.0f64);
    let mut i = 0;
    for dist in [Dist::Euclidean, Dist::Barycentric] {
        for alpha in [Alpha::Prod, Alpha::Sum] {
            // R ≤ 5: partials with masks of the texel slots they wrote; R = 7 (49 slots):
            // partials zeroed by a fill first.
            let wide = if alpha == Alpha::Prod { 2 } else { 7 };
            for (color_mode, res) in [
                (ColorMode::Surface, 1),
                (ColorMode::Surface, wide),
                (ColorMode::Vertex, 1),
            ] {
                let mesh = scene(res, 10 + i);
                let s = RasterSettings {
                    dist,
                    alpha,
                    color_mode,
                    double_sided: i % 2 == 0,
                    antialias: i % 5 == 1,
                    ..settings(if i % 3 == 0 { 20 } else { 16 }, 16)
                };
                let views: &[Camera] = if i % 4 == 3 { &ortho } else { &cams };
                let what = format!("#{i} {dist:?} {alpha:?} {color_mode:?} R={res}");
                let bars = if dist == Dist::Barycentric {
                    KINKED
                } else {
                    SMOOTH
                };
                let (err, share) = check(&r, &gpu, &what, &mesh, views, &s, bars);
                worst = (worst.0.max(err), worst.1.max(share));
                i += 1;
            }
        }
    }
    eprintln!(
        "worst difference to the twin: {:.2e} of the largest; {:.2} of a component's bar",
        worst.0, worst.1
    );
}

/// Hard colour, hard coverage and the matrix projection: the a.e. derivative, same bound.
#[test]
fn hard_modes_and_the_matrix_projection_match_the_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = scene(1, 3);
    let cams = [Camera::from_angles(2.732, 15.0, 20.0)];
    let hard_rgb = RasterSettings {
        rgb: Rgb::Hard,
        color_mode: ColorMode::Vertex,
        ..settings(16, 16)
    };
    check(&r, &gpu, "hard rgb", &mesh, &cams, &hard_rgb, SMOOTH);
    let hard_dist = RasterSettings {
        dist: Dist::Hard,
        alpha: Alpha::Sum,
        color_mode: ColorMode::Vertex,
        ..settings(16, 16)
    };
    check(&r, &gpu, "hard dist", &mesh, &cams, &hard_dist, SMOOTH);
    let cam = Camera::from_angles(2.732, 20.0, 35.0);
    let rot = softvk::camera::look_at(cam.eye, DVec3::ZERO, DVec3::Y);
    let t: Vec<f64> = rot
        .iter()
        .map(|row| -DVec3::from(*row).dot(cam.eye))
        .collect();
    let f = 8.0 / 30f64.to_radians().tan();
    let mut p = [[0.0; 4]; 3];
    for j in 0..3 {
        p[0][j] = f * rot[0][j] + 8.0 * rot[2][j];
        p[1][j] = f * rot[1][j] + 8.0 * rot[2][j];
        p[2][j] = rot[2][j];
    }
    p[0][3] = f * t[0] + 8.0 * t[2];
    p[1][3] = f * t[1] + 8.0 * t[2];
    p[2][3] = t[2];
    let matrix = [Camera {
        projection: Projection::Matrix {
            p,
            dist_coeffs: [1e-3, 0.0, 1e-4, -1e-4, 0.0],
            orig_size: 16.0,
        },
        ..cam
    }];
    let s = settings(16, 16);
    check(&r, &gpu, "matrix", &mesh, &matrix, &s, SMOOTH);
}

/// A face seen nearly edge-on: spot's face 548 and three neighbours, through the eye of
/// SoftRas's `get_points_from_angles(2.5, 10, 120)` computed in f32. The sliver's screen
/// determinant is -3.2e-9 (1.2e-5 of its terms); taken from the f32 screen vertices it came
/// out positive, and the sign decides what the clipped barycentrics of a pixel beside the
/// sliver are, (1, 0, 0) or (0, ½, ½), so its depth and texel there: the face's softmax weight
/// at pixel (16, 24) moved by e^{0.37}, the neighbours' colour gradients by 7.5 %, the sliver's
/// own went to the other texel, and the positions' gradients were 9 % off. The setup now takes
/// a look-at view's determinant from the world vertices (`look_at_det` in `face_setup.comp`).
#[test]
fn a_face_seen_edge_on_differentiates_as_the_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let positions = vec![
        [0.228165, -0.692422, 0.147407],
        [0.276152, -0.679477, 0.14116],
        [0.227442, -0.724741, 0.0933852],
        [0.182766, -0.687312, 0.135767],
        [0.233064, -0.638226, 0.175543],
        [0.185474, -0.638484, 0.162245],
    ];
    // The sliver first.
    let faces = vec![[4, 5, 0], [0, 3, 2], [0, 1, 4], [3, 0, 5]];
    let mut mesh = Mesh::new(positions, faces, 2).unwrap();
    mesh.textures = random_colors(mesh.textures.len(), 5);
    let eye = DVec3::new(
        f64::from(2.1321714f32),
        f64::from(0.43412045f32),
        f64::from(1.2310098f32),
    );
    let cams = [Camera {
        eye,
        ..Camera::from_angles(2.5, 10.0, 120.0)
    }];
    let s = RasterSettings {
        width: 32,
        height: 32,
        sigma: 1e-4,
        gamma: 1e-3,
        ..RasterSettings::default()
    };
    check(&r, &gpu, "edge-on sliver", &mesh, &cams, &s, SMOOTH);
}

#[test]
fn repeated_backward_runs_are_bit_identical() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = scene(2, 5);
    let cams = [Camera::from_angles(2.732, 15.0, 20.0)];
    let s = settings(24, 16);
    let w = weights(24 * 16, 7);
    let bits = |g: &Gradients| -> Vec<u64> {
        g.positions
            .iter()
            .chain(&g.colors)
            .chain(&camera_rows(g))
            .flatten()
            .map(|x| x.to_bits())
            .collect()
    };
    for method in [
        Method::Brute,
        Method::Tiled { tile: 8 },
        Method::Tiled { tile: 16 },
    ] {
        let a_scene = forward(&r, &gpu, &mesh, &cams, &s, method);
        let a = r
            .backward(&gpu, &a_scene.last_run().unwrap().binned(), &w, true)
            .unwrap();
        let r2 = Renderer::new(&gpu).unwrap();
        let b_scene = forward(&r2, &gpu, &mesh, &cams, &s, method);
        let b = r2
            .backward(&gpu, &b_scene.last_run().unwrap().binned(), &w, true)
            .unwrap();
        assert!(bits(&a) == bits(&b), "{method:?}");
    }
}

/// Gradient descent on the GPU: one triangle's vertices move until its soft silhouette matches a
/// target triangle's (rendered with the same σ, annealed from 1e-2 to 1e-3), judged by the IoU of
/// the hard silhouettes (> 0.99).
#[test]
fn gradient_descent_on_one_triangle_matches_a_silhouette() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let cams = [Camera::default()];
    let size = 32;
    let target_mesh = Mesh::new(
        vec![[-0.5, -0.4, 0.0], [0.1, 0.55, 0.0], [0.6, -0.3, 0.0]],
        vec![[0, 1, 2]],
        1,
    )
    .unwrap();
    let hard = RasterSettings {
        width: size,
        height: size,
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..RasterSettings::default()
    };
    let silhouette = |mesh: &Mesh| -> Vec<bool> {
        r.render_views(
            &gpu,
            mesh,
            &cams,
            &Lighting::unlit(),
            &hard,
            Method::default(),
        )
        .unwrap()
        .images
        .iter()
        .map(|p| p[3] > 0.5)
        .collect()
    };
    let target = silhouette(&target_mesh);
    let mut mesh = Mesh::new(
        vec![[-0.3, -0.1, 0.0], [0.0, 0.3, 0.0], [0.2, -0.2, 0.0]],
        vec![[0, 1, 2]],
        1,
    )
    .unwrap();
    let iou = |a: &[bool], b: &[bool]| {
        let inter = a.iter().zip(b).filter(|(x, y)| **x && **y).count();
        let union = a.iter().zip(b).filter(|(x, y)| **x || **y).count();
        inter as f64 / union as f64
    };
    let start = iou(&silhouette(&mesh), &target);
    // Adam on the vertices, σ annealed from blurry to sharp.
    let (mut m, mut v) = ([[0.0f64; 3]; 3], [[0.0f64; 3]; 3]);
    let (b1, b2) = (0.9, 0.999);
    let mut step = 0;
    for (sigma, iters, lr) in [(1e-2, 120, 2e-2), (3e-3, 120, 1e-2), (1e-3, 120, 3e-3)] {
        let s = RasterSettings {
            width: size,
            height: size,
            sigma,
            ..RasterSettings::default()
        };
        let soft_target = r
            .render_views(
                &gpu,
                &target_mesh,
                &cams,
                &Lighting::unlit(),
                &s,
                Method::default(),
            )
            .unwrap()
            .images;
        for _ in 0..iters {
            step += 1;
            let mut scene = r
                .prepare(&gpu, &mesh, &cams, &Lighting::unlit(), &s)
                .unwrap();
            let run = r.run(&gpu, &mut scene, Method::default()).unwrap();
            let img = run.binned().scene().read_frames(&gpu).unwrap().images;
            // L = Σ (A − A_target)², the target's silhouette rendered with the same σ.
            let d: Vec<[f32; 4]> = img
                .iter()
                .zip(&soft_target)
                .map(|(p, t)| [0.0, 0.0, 0.0, 2.0 * (p[3] - t[3])])
                .collect();
            let g = r.backward(&gpu, &run.binned(), &d, false).unwrap();
            for k in 0..3 {
                for c in 0..2 {
                    let gk = g.positions[k][c];
                    m[k][c] = b1 * m[k][c] + (1.0 - b1) * gk;
                    v[k][c] = b2 * v[k][c] + (1.0 - b2) * gk * gk;
                    let mh = m[k][c] / (1.0 - b1.powi(step));
                    let vh = v[k][c] / (1.0 - b2.powi(step));
                    mesh.positions[k][c] -= (lr * mh / (vh.sqrt() + 1e-8)) as f32;
                }
            }
        }
    }
    let end = iou(&silhouette(&mesh), &target);
    eprintln!("IoU {start:.3} -> {end:.3} in {step} steps");
    assert!(end > 0.99, "IoU {start:.3} -> {end:.3}");
}

#[test]
fn backward_input_errors() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = scene(1, 1);
    let cams = [Camera::default()];
    let s = settings(8, 8);
    let scene = forward(&r, &gpu, &mesh, &cams, &s, Method::Tiled { tile: 8 });
    let err = r
        .backward(
            &gpu,
            &scene.last_run().unwrap().binned(),
            &weights(10, 1),
            false,
        )
        .unwrap_err();
    assert!(matches!(err, softvk::Error::Input(_)), "{err}");
    let mut w = weights(64, 1);
    w[3][1] = f32::NAN;
    let err = r
        .backward(&gpu, &scene.last_run().unwrap().binned(), &w, false)
        .unwrap_err();
    assert!(err.to_string().contains("not finite"), "{err}");
}

/// A batch of two meshes of equal topology, four views: each mesh's gradients (positions,
/// colours, and every view's camera) equal those of the mesh rendered alone with its views.
#[test]
fn a_batch_differentiates_as_each_mesh_alone() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let a = scene(2, 21);
    let mut b = a.clone();
    let mut rng = common::rng(22);
    for p in &mut b.positions {
        p.iter_mut()
            .for_each(|c| *c *= 1.0 + rng.random_range(-0.1f32..0.1));
    }
    b.textures = random_colors(b.textures.len(), 23);
    let cams = [
        Camera::from_angles(2.732, 15.0, 20.0),
        Camera::from_angles(2.5, -10.0, 150.0),
    ];
    let views = [(0, cams[0]), (1, cams[0]), (1, cams[1]), (0, cams[1])];
    let meshes = [a, b];
    let s = settings(16, 16);
    let px = 16 * 16;
    let w = weights(px * views.len(), 24);
    for method in [Method::Brute, Method::Tiled { tile: 8 }] {
        let mut scene = r
            .prepare_batch(&gpu, &meshes, &views, &lighting(), &s)
            .unwrap();
        r.run(&gpu, &mut scene, method).unwrap();
        let batch = r
            .backward(&gpu, &scene.last_run().unwrap().binned(), &w, true)
            .unwrap();
        let nv = meshes[0].vertex_count();
        let nc = batch.colors.len() / 2;
        for (m, mesh) in meshes.iter().enumerate() {
            let mine: Vec<usize> = (0..views.len()).filter(|&v| views[v].0 == m).collect();
            let my_cams: Vec<Camera> = mine.iter().map(|&v| views[v].1).collect();
            let my_w: Vec<[f32; 4]> = mine
                .iter()
                .flat_map(|&v| w[v * px..(v + 1) * px].iter().copied())
                .collect();
            let alone_scene = forward(&r, &gpu, mesh, &my_cams, &s, method);
            let alone = r
                .backward(&gpu, &alone_scene.last_run().unwrap().binned(), &my_w, true)
                .unwrap();
            let what = format!("{method:?} mesh {m}");
            assert!(
                batch.positions[m * nv..(m + 1) * nv] == alone.positions[..],
                "{what}"
            );
            assert!(
                batch.colors[m * nc..(m + 1) * nc] == alone.colors[..],
                "{what}"
            );
            for (k, &v) in mine.iter().enumerate() {
                assert!(batch.cameras[v] == alone.cameras[k], "{what}: view {v}");
            }
        }
    }
}

/// A scene whose meshes are replaced (`update_meshes`: new positions and textures, the same
/// topology) renders and differentiates bit for bit as a scene prepared for the new meshes;
/// a mesh of another topology is refused, and the scene still renders its old meshes.
#[test]
fn updated_meshes_render_and_differentiate_as_a_fresh_scene() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let old = [scene(2, 31), scene(2, 32)];
    let mut new = old.clone();
    let mut rng = common::rng(33);
    for mesh in &mut new {
        for p in &mut mesh.positions {
            p.iter_mut()
                .for_each(|c| *c *= 1.0 + rng.random_range(-0.1f32..0.1));
        }
        mesh.textures = random_colors(mesh.textures.len(), 34);
    }
    let cams = [
        Camera::from_angles(2.732, 15.0, 20.0),
        Camera::from_angles(2.5, -10.0, 150.0),
    ];
    let views = [(0, cams[0]), (1, cams[1])];
    let s = settings(16, 16);
    let w = weights(16 * 16 * views.len(), 35);
    let method = Method::Tiled { tile: 8 };
    let render = |scene: &mut softvk::raster::gpu::GpuScene| {
        r.run(&gpu, scene, method).unwrap();
        let frames = scene.read_frames(&gpu).unwrap();
        let grads = r
            .backward(&gpu, &scene.last_run().unwrap().binned(), &w, true)
            .unwrap();
        (frames.images, grads)
    };
    let mut fresh = r
        .prepare_batch(&gpu, &new, &views, &lighting(), &s)
        .unwrap();
    let expected = render(&mut fresh);
    let mut reused = r
        .prepare_batch(&gpu, &old, &views, &lighting(), &s)
        .unwrap();
    let before = render(&mut reused);
    assert!(
        before.0 != expected.0,
        "the new meshes must render differently"
    );
    reused.update_meshes(&gpu, &new).unwrap();
    assert!(render(&mut reused) == expected);

    let mut other = new.clone();
    other[1].faces.swap(0, 1);
    let err = reused.update_meshes(&gpu, &other).unwrap_err();
    assert!(err.to_string().contains("topology"), "{err}");
    assert!(render(&mut reused) == expected);
    assert!(reused.update_meshes(&gpu, &new[..1]).is_err());
}

/// A loop keeps one set of backward buffers for its scene ([`GradBuffers::fits`]): after
/// `update_meshes`, the kept buffers give the gradients of new ones bit for bit; they do not
/// fit another method, a scene of other sizes, or entries that outgrew them.
#[test]
fn kept_backward_buffers_differentiate_an_updated_scene_as_new_ones() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let old = [scene(2, 41), scene(2, 42)];
    let mut new = old.clone();
    let mut rng = common::rng(43);
    for mesh in &mut new {
        for p in &mut mesh.positions {
            p.iter_mut()
                .for_each(|c| *c *= 1.0 + rng.random_range(-0.1f32..0.1));
        }
    }
    let views = [
        (0, Camera::from_angles(2.732, 15.0, 20.0)),
        (1, Camera::from_angles(2.5, -10.0, 150.0)),
    ];
    let s = settings(16, 16);
    let w = weights(16 * 16 * views.len(), 44);
    let method = Method::Tiled { tile: 8 };
    let backward = |scene: &GpuScene, gb: &GradBuffers| {
        gb.set_d_image(&gpu, scene, &w).unwrap();
        let binned = scene.last_run().unwrap().binned();
        let kernels = r.grad_kernels();
        gpu.submit_and_wait(|rec| kernels.record(rec, &binned, gb, &gb.io()))
            .unwrap();
        kernels.finish(&gpu, scene, gb, &gb.io(), true).unwrap()
    };

    let mut fresh = r
        .prepare_batch(&gpu, &new, &views, &lighting(), &s)
        .unwrap();
    let fresh_gb = GradBuffers::new(&gpu, &r.run(&gpu, &mut fresh, method).unwrap().binned());
    let expected = backward(&fresh, &fresh_gb.unwrap());

    let mut kept = r
        .prepare_batch(&gpu, &old, &views, &lighting(), &s)
        .unwrap();
    let gb = GradBuffers::new(&gpu, &r.run(&gpu, &mut kept, method).unwrap().binned()).unwrap();
    assert!(
        backward(&kept, &gb) != expected,
        "the new meshes must differentiate differently"
    );
    kept.update_meshes(&gpu, &new).unwrap();
    assert!(gb.fits(&r.run(&gpu, &mut kept, method).unwrap().binned()));
    assert!(backward(&kept, &gb) == expected);

    assert!(!gb.fits(&r.run(&gpu, &mut kept, Method::Brute).unwrap().binned()));
    r.run(&gpu, &mut kept, method).unwrap();
    let mut smaller = r
        .prepare_batch(&gpu, &new, &views, &lighting(), &settings(8, 8))
        .unwrap();
    assert!(!gb.fits(&r.run(&gpu, &mut smaller, method).unwrap().binned()));
    // Buffers made for the meshes shrunk to a tenth (most faces in one of 64 tiles, at a small
    // σ) are too small for the meshes at full size, which cross tiles.
    let sharp = RasterSettings {
        sigma: 1e-5,
        ..settings(64, 64)
    };
    let mut shrunk = new.clone();
    for mesh in &mut shrunk {
        for p in &mut mesh.positions {
            // Off the image's centre, which is a corner of four tiles.
            *p = [0.1 * p[0] + 0.3, 0.1 * p[1] + 0.3, 0.1 * p[2]];
        }
    }
    let mut grows = r
        .prepare_batch(&gpu, &shrunk, &views, &lighting(), &sharp)
        .unwrap();
    let small = GradBuffers::new(&gpu, &r.run(&gpu, &mut grows, method).unwrap().binned()).unwrap();
    assert!(small.fits(&grows.last_run().unwrap().binned()));
    grows.update_meshes(&gpu, &new).unwrap();
    let binned = r.run(&gpu, &mut grows, method).unwrap().binned();
    assert!(binned.entries() > small.entry_capacity());
    assert!(!small.fits(&binned));
}

/// One tile holding more faces than llvmpipe lets one shader invocation loop over (65 535
/// iterations): a tilted square of 204 800 triangles (a 320 × 320 grid), about 2.5 pixels
/// wide in a 16² image, all in one tile. The forward folds the tile (and brute force the face
/// list) in passes, the backward splits the tile over workgroups; both methods match the twin.
/// (A finely subdivided sphere would do for the forward, but its silhouette's edge-on faces
/// have gradients that f32 cannot match to 1e-3.)
#[test]
fn a_tile_of_over_200k_faces_differentiates_as_the_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    const N: u32 = 320;
    let mut positions = Vec::with_capacity(((N + 1) * (N + 1)) as usize);
    for j in 0..=N {
        for i in 0..=N {
            let (u, v) = (
                f64::from(i) / f64::from(N) - 0.5,
                f64::from(j) / f64::from(N) - 0.5,
            );
            positions.push([
                (0.5 * u - 0.79) as f32,
                (0.5 * v + 0.79) as f32,
                (0.15 * v) as f32,
            ]);
        }
    }
    let mut faces = Vec::with_capacity((2 * N * N) as usize);
    for j in 0..N {
        for i in 0..N {
            let a = j * (N + 1) + i;
            faces.push([a, a + 1, a + N + 2]);
            faces.push([a, a + N + 2, a + N + 1]);
        }
    }
    let mut mesh = Mesh::new(positions, faces, 1).unwrap();
    assert!(mesh.face_count() >= 200_000);
    mesh.textures = random_colors(mesh.textures.len(), 51);
    let s = RasterSettings {
        sigma: 1e-5,
        ..settings(16, 16)
    };
    let cams = [Camera::default()];
    let (err, share) = check(&r, &gpu, "crowded tile", &mesh, &cams, &s, KINKED);
    eprintln!("crowded tile: worst difference {err:.2e} of the largest; {share:.2} of a bar");
}

/// The backward of a scene already rendered, with its work split at most as `split` says;
/// returns the gradients, the units one chunk of partials holds, and the brute-force bands.
fn backward_split(
    r: &Renderer,
    gpu: &common::Gpu,
    scene: &GpuScene,
    w: &[[f32; 4]],
    method: Method,
    split: GradSplit,
) -> (Gradients, u64, u32) {
    // Brute force's backward reads only the forward's aux, which every method writes alike.
    let binned = match method {
        Method::Brute => ExactRun::brute(scene).binned(),
        Method::Tiled { .. } => scene.last_run().unwrap().binned(),
    };
    assert_eq!(binned.method(), method);
    let gb = GradBuffers::with_split(gpu, &binned, split).unwrap();
    gb.set_d_image(gpu, scene, w).unwrap();
    gpu.submit_and_wait(|rec| r.grad_kernels().record(rec, &binned, &gb, &gb.io()))
        .unwrap();
    let g = r
        .grad_kernels()
        .finish(gpu, scene, &gb, &gb.io(), true)
        .unwrap();
    (g, gb.chunk_units(), gb.bands())
}

fn bits(g: &Gradients) -> Vec<u64> {
    g.positions
        .iter()
        .chain(&g.colors)
        .chain(&camera_rows(g))
        .flatten()
        .map(|x| x.to_bits())
        .collect()
}

/// Texel gradients (R = 4: 76 floats per partial, with a mask of the slots written; R = 6: 156
/// floats, zeroed first) and vertex colours, with the partials in chunks of 7 units: many chunks, whose boundaries split faces' runs of units. Every method
/// matches the twin, is bit for bit the single-chunk result (the running sums add in unit order
/// whatever the chunking), and repeats bit for bit.
#[test]
fn partials_in_many_chunks_match_the_twin_and_one_chunk_bit_for_bit() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let cams = [
        Camera::from_angles(2.732, 15.0, 20.0),
        Camera::from_angles(2.5, -10.0, 150.0),
    ];
    let chunked = GradSplit {
        chunk_units: Some(7),
        ..GradSplit::default()
    };
    for (color_mode, res) in [
        (ColorMode::Surface, 4),
        (ColorMode::Surface, 6),
        (ColorMode::Vertex, 1),
    ] {
        let mesh = scene(res, 31);
        let s = RasterSettings {
            color_mode,
            ..settings(24, 16)
        };
        let w = weights(24 * 16 * cams.len(), 32);
        let w64: Vec<[f64; 4]> = w.iter().map(|g| g.map(f64::from)).collect();
        let want = reference_grad::grad(&mesh, &cams, &lighting(), &s, &w64).unwrap();
        for method in METHODS {
            let what = format!("{color_mode:?} R={res} {method:?}");
            let fwd = forward(&r, &gpu, &mesh, &cams, &s, method);
            let (one, one_chunk, bands) =
                backward_split(&r, &gpu, &fwd, &w, method, GradSplit::default());
            let units = match method {
                Method::Brute => u64::from(bands) * 2 * mesh.face_count() as u64,
                Method::Tiled { .. } => fwd.last_run().unwrap().binned().entries(),
            };
            assert!(
                one_chunk >= units,
                "{what}: one chunk holds {one_chunk} < {units}"
            );
            let (many, chunk, _) = backward_split(&r, &gpu, &fwd, &w, method, chunked);
            assert_eq!(chunk, 7, "{what}");
            assert!(units > 3 * chunk, "{what}: only {units} units");
            assert_close(
                &format!("{what} chunked vs twin"),
                &many,
                &want,
                true,
                SMOOTH,
            );
            assert!(bits(&many) == bits(&one), "{what}: chunking changed a sum");
            let (again, _, _) = backward_split(&r, &gpu, &fwd, &w, method, chunked);
            assert!(bits(&again) == bits(&many), "{what}: not deterministic");
        }
    }
}

/// A batch of two textured meshes, views interleaved, in chunks of 5 units: the texel sums of
/// both meshes, fed from views of either in one chunk, are bit for bit the single-chunk ones.
#[test]
fn a_chunked_batch_is_bit_for_bit_the_unchunked_batch() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let a = scene(3, 41);
    let mut b = a.clone();
    b.textures = random_colors(b.textures.len(), 42);
    for p in &mut b.positions {
        p[0] += 0.05;
    }
    let cams = [
        Camera::from_angles(2.732, 15.0, 20.0),
        Camera::from_angles(2.5, -10.0, 150.0),
    ];
    let views = [(0, cams[0]), (1, cams[0]), (1, cams[1]), (0, cams[1])];
    let s = settings(16, 16);
    let w = weights(16 * 16 * views.len(), 43);
    for method in [Method::Brute, Method::Tiled { tile: 8 }] {
        let mut fwd = r
            .prepare_batch(&gpu, &[a.clone(), b.clone()], &views, &lighting(), &s)
            .unwrap();
        r.run(&gpu, &mut fwd, method).unwrap();
        let (one, _, _) = backward_split(&r, &gpu, &fwd, &w, method, GradSplit::default());
        let split = GradSplit {
            chunk_units: Some(5),
            ..GradSplit::default()
        };
        let (many, _, _) = backward_split(&r, &gpu, &fwd, &w, method, split);
        assert!(bits(&many) == bits(&one), "{method:?}");
        assert!(one.colors.iter().flatten().any(|&c| c != 0.0));
    }
}

/// Brute force in bands of 3 rows (6 bands over 16 rows, the last of 1) and the tiled backward
/// with a crowded tile split into workgroups of 64 faces (one 32-pixel tile holding every face):
/// both match the twin and repeat bit for bit, and splitting a tile changes no sum.
#[test]
fn brute_bands_and_split_tiles_match_the_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = scene(2, 51);
    let cams = [Camera::from_angles(2.732, 15.0, 20.0)];
    let s = settings(16, 16);
    let w = weights(16 * 16, 52);
    let w64: Vec<[f64; 4]> = w.iter().map(|g| g.map(f64::from)).collect();
    let want = reference_grad::grad(&mesh, &cams, &lighting(), &s, &w64).unwrap();

    let fwd = forward(&r, &gpu, &mesh, &cams, &s, Method::Brute);
    let banded = GradSplit {
        band_rows: Some(3),
        ..GradSplit::default()
    };
    let (got, _, bands) = backward_split(&r, &gpu, &fwd, &w, Method::Brute, banded);
    assert_eq!(bands, 6);
    assert_close("brute in bands of 3 rows", &got, &want, true, SMOOTH);
    let (again, _, _) = backward_split(&r, &gpu, &fwd, &w, Method::Brute, banded);
    assert!(
        bits(&again) == bits(&got),
        "banded brute force is not deterministic"
    );

    let tile = Method::Tiled { tile: 32 };
    let fwd = forward(&r, &gpu, &mesh, &cams, &s, tile);
    let run = fwd.last_run().unwrap().binned().entries();
    assert!(run > 64, "the one tile holds only {run} faces");
    let parts = GradSplit {
        tile_faces: Some(64),
        ..GradSplit::default()
    };
    let (split, _, _) = backward_split(&r, &gpu, &fwd, &w, tile, parts);
    let (whole, _, _) = backward_split(&r, &gpu, &fwd, &w, tile, GradSplit::default());
    assert_close("tile split in 64-face parts", &split, &want, true, SMOOTH);
    assert!(
        bits(&split) == bits(&whole),
        "splitting the tile changed a sum"
    );
}

/// Under llvmpipe's real loop cap, the splits it forces: brute force over 256² pixels takes two
/// bands (254 rows fit), and a 32-pixel tile holding 4 624 faces takes two workgroups (about
/// 3 968 fit); both match the twin. (On drivers without the cap these run unsplit.)
#[test]
fn the_backward_splits_work_past_the_drivers_loop_cap() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let capped = gpu.info().shader_loop_limit().is_some();
    let cams = [Camera::default()];

    let s = settings(256, 256);
    let mesh = scene(1, 2);
    let w = weights(256 * 256, 3);
    let w64: Vec<[f64; 4]> = w.iter().map(|g| g.map(f64::from)).collect();
    let want = reference_grad::grad(&mesh, &cams, &lighting(), &s, &w64).unwrap();
    let fwd = forward(&r, &gpu, &mesh, &cams, &s, Method::Tiled { tile: 8 });
    let (got, _, bands) = backward_split(&r, &gpu, &fwd, &w, Method::Brute, GradSplit::default());
    assert_eq!(bands, if capped { 2 } else { 1 });
    assert_close("brute 256²", &got, &want, true, SMOOTH);

    // 68 × 68 small triangles over a 32×32 image: one tile of 32 holds them all.
    let n = 68;
    let mut positions = Vec::with_capacity(3 * n * n);
    let mut faces = Vec::with_capacity(n * n);
    for i in 0..n * n {
        let x = (i % n) as f32 / n as f32 - 0.5;
        let y = (i / n) as f32 / n as f32 - 0.5;
        let v = positions.len() as u32;
        positions.extend([[x, y, 0.0], [x + 0.012, y, 0.0], [x, y + 0.012, 0.0]]);
        faces.push([v, v + 1, v + 2]);
    }
    let mut crowded = Mesh::new(positions, faces, 1).unwrap();
    crowded.textures = random_colors(crowded.textures.len(), 4);
    let s = RasterSettings {
        sigma: 1e-4,
        ..settings(32, 32)
    };
    let w = weights(32 * 32, 5);
    let w64: Vec<[f64; 4]> = w.iter().map(|g| g.map(f64::from)).collect();
    let want = reference_grad::grad(&crowded, &cams, &lighting(), &s, &w64).unwrap();
    let tile = Method::Tiled { tile: 32 };
    let fwd = forward(&r, &gpu, &crowded, &cams, &s, tile);
    assert_eq!(fwd.last_run().unwrap().binned().entries(), (n * n) as u64);
    let (got, _, _) = backward_split(&r, &gpu, &fwd, &w, tile, GradSplit::default());
    assert_close(
        "4 624 faces in one 32-pixel tile",
        &got,
        &want,
        true,
        KINKED,
    );
}

/// An alpha-only backward (a silhouette scene, or one declared alpha-only) gives the full
/// backward's gradients when the upstream has no RGB part, in every differentiable distance and
/// alpha mode, tiled and brute force: the colour terms it leaves out only add zeros. (Leaving
/// out a term that is not zero — the barycentric coverage's d_w, say — fails here.)
#[test]
fn alpha_only_backwards_equal_the_full_backward_for_an_alpha_upstream() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = scene(2, 9);
    let cams = [
        Camera::from_angles(2.732, 15.0, 20.0),
        Camera::from_angles(2.5, -30.0, 140.0),
    ];
    let (w, h) = (24, 16);
    let alpha_upstream: Vec<[f32; 4]> = weights(2 * w * h, 11)
        .iter()
        .map(|g| [0.0, 0.0, 0.0, g[3]])
        .collect();
    let values = |g: &Gradients| -> Vec<f64> { g.positions.iter().flatten().copied().collect() };
    for dist in [Dist::Euclidean, Dist::Barycentric] {
        for alpha in [Alpha::Prod, Alpha::Sum] {
            let s = RasterSettings {
                dist,
                alpha,
                rgb: if alpha == Alpha::Sum {
                    Rgb::Hard
                } else {
                    Rgb::Softmax
                },
                ..settings(w as u32, h as u32)
            };
            for method in [Method::Brute, Method::Tiled { tile: 8 }] {
                let what = format!("{dist:?} {alpha:?} {method:?}");
                let full = forward(&r, &gpu, &mesh, &cams, &s, method);
                let want = r
                    .backward(
                        &gpu,
                        &full.last_run().unwrap().binned(),
                        &alpha_upstream,
                        false,
                    )
                    .unwrap();
                assert!(values(&want).iter().any(|&x| x != 0.0), "{what}");
                // Declared on the buffers, over the full render.
                let binned = full.last_run().unwrap().binned();
                let mut gb = GradBuffers::new(&gpu, &binned).unwrap();
                gb.set_alpha_only(true);
                gb.set_d_image(&gpu, &full, &alpha_upstream).unwrap();
                let k = r.grad_kernels();
                gpu.submit_and_wait(|rec| k.record(rec, &binned, &gb, &gb.io()))
                    .unwrap();
                let declared = k.finish(&gpu, &full, &gb, &gb.io(), false).unwrap();
                assert!(values(&declared) == values(&want), "{what}: declared");
                // A silhouette render's backward.
                let mut sil = r.prepare(&gpu, &mesh, &cams, &lighting(), &s).unwrap();
                sil.set_silhouette_only(true);
                r.run(&gpu, &mut sil, method).unwrap();
                let got = r
                    .backward(
                        &gpu,
                        &sil.last_run().unwrap().binned(),
                        &alpha_upstream,
                        false,
                    )
                    .unwrap();
                assert!(values(&got) == values(&want), "{what}: silhouette");
            }
        }
    }
}

fn frame_bits(f: &softvk::raster::gpu::Frames) -> Vec<u32> {
    f.images
        .iter()
        .flatten()
        .map(|c| c.to_bits())
        .chain(f.aux.iter().flat_map(|a| {
            [
                a.softmax_ref_depth.to_bits(),
                a.softmax_sum.to_bits(),
                a.alpha_acc.to_bits(),
                a.alpha_zeros,
                a.hard_face,
            ]
        }))
        .collect()
}

/// One view whose (face, tile) entries do not fit what one binding may hold (here an entry
/// budget of 60 % of them) is binned, rendered and differentiated window by window of tile
/// rows: each window binned alone, through masks (a 5×6-tile grid) or the sort (257 × 18 tiles,
/// windows of 9 rows, above the masks' 2 048 tiles), with every entry binned once. The image
/// and aux are bit for bit one binning's and brute force's; the gradients are bit for bit one
/// binning's (each face's running sums add its tiles in the same order), match brute force, and
/// the small case matches the twin.
#[test]
fn one_view_past_the_entry_budget_renders_and_differentiates_window_by_window() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let cams = [Camera::from_angles(2.732, 15.0, 20.0)];
    let tile = Method::Tiled { tile: 8 };
    for (w_px, h_px, color_mode, res) in [
        (40, 48, ColorMode::Surface, 3),
        (2056, 144, ColorMode::Vertex, 1),
    ] {
        let what = format!("{w_px}x{h_px} {color_mode:?}");
        let mesh = scene(res, 61);
        let s = RasterSettings {
            color_mode,
            ..settings(w_px, h_px)
        };
        let w = weights((w_px * h_px) as usize, 62);
        let whole = forward(&r, &gpu, &mesh, &cams, &s, tile);
        assert_eq!(
            whole.last_run().unwrap().binned().groups().len(),
            1,
            "{what}"
        );
        let entries = whole.last_run().unwrap().binned().entries();
        let budget = entries * 3 / 5;
        let windowed = Renderer::new(&gpu).unwrap().with_entry_budget(budget);
        let win = forward(&windowed, &gpu, &mesh, &cams, &s, tile);
        let groups = win.last_run().unwrap().binned().groups();
        assert!(groups.len() >= 2, "{what}: {groups:?}");
        let rows = s.height.div_ceil(8);
        let mut next_row = 0;
        for g in groups {
            assert_eq!((g.first, g.views), (0, 1), "{what}");
            assert_eq!(g.tile_rows.0, next_row, "{what}: windows in order, no gap");
            assert!(g.entries <= budget, "{what}: {g:?} over {budget}");
            next_row += g.tile_rows.1;
        }
        assert_eq!(next_row, rows, "{what}: windows cover every tile row");
        assert_eq!(
            win.last_run().unwrap().binned().entries(),
            entries,
            "{what}: each entry once"
        );
        assert_eq!(
            win.last_run().unwrap().binned().pair_counts(&gpu).unwrap(),
            whole
                .last_run()
                .unwrap()
                .binned()
                .pair_counts(&gpu)
                .unwrap(),
            "{what}: the same pairs visited"
        );
        // Which way the windows were binned: masks up to 2 048 tiles, the sort beyond.
        let window_tiles = u64::from(s.width.div_ceil(8)) * u64::from(groups[0].tile_rows.1);
        assert_eq!(
            window_tiles > MASK_MAX_TILES_PER_VIEW,
            w_px > 1000,
            "{what}: {window_tiles} tiles per window"
        );
        let brute = forward(&r, &gpu, &mesh, &cams, &s, Method::Brute);
        let frames = |scene: &GpuScene| frame_bits(&scene.read_frames(&gpu).unwrap());
        let want = frames(&whole);
        assert!(frames(&win) == want, "{what}: windows changed the forward");
        assert!(frames(&brute) == want, "{what}: tiled differs from brute");

        let (one, _, _) = backward_split(&r, &gpu, &whole, &w, tile, GradSplit::default());
        let (many, _, _) = backward_split(&windowed, &gpu, &win, &w, tile, GradSplit::default());
        assert!(bits(&many) == bits(&one), "{what}: windows changed a sum");
        let (b, _, _) = backward_split(&r, &gpu, &brute, &w, Method::Brute, GradSplit::default());
        assert_close(&format!("{what} windows vs brute"), &many, &b, true, SMOOTH);
        if w_px * h_px < 4096 {
            let w64: Vec<[f64; 4]> = w.iter().map(|g| g.map(f64::from)).collect();
            let twin = reference_grad::grad(&mesh, &cams, &lighting(), &s, &w64).unwrap();
            assert_close(
                &format!("{what} windows vs twin"),
                &many,
                &twin,
                true,
                SMOOTH,
            );
        }
    }
}

/// The workgroup shapes made for a GPU (64 invocations: a tile's faces round robin over the
/// subgroups, one pixel per forward invocation, one texel per texel-reduction invocation) and
/// those made for a CPU device (`Context::cpu_workgroups`) compute the same bits: images, aux
/// and gradients, with surface colours (masked texel slots at R = 4, zero-filled at R = 6) and
/// vertex colours, at tiles of 8 and 16. On a GPU both contexts take the GPU's shapes.
#[test]
fn gpu_and_cpu_workgroup_shapes_give_the_same_bits() {
    let Some(own) = common::gpu() else { return };
    let Some(gpu_shapes) = common::gpu_with(|o| o.gpu_workgroups = true) else {
        return;
    };
    assert!(!gpu_shapes.cpu_workgroups());
    let cams = [Camera::from_angles(2.732, 15.0, 20.0)];
    let w = weights(24 * 16, 13);
    for (res, color_mode) in [
        (4, ColorMode::Surface),
        (6, ColorMode::Surface),
        (2, ColorMode::Vertex),
    ] {
        let mesh = scene(res, 17);
        let s = RasterSettings {
            color_mode,
            ..settings(24, 16)
        };
        for tile in [8, 16] {
            let method = Method::Tiled { tile };
            let run = |gpu: &common::Gpu| {
                let r = Renderer::new(gpu).unwrap();
                let frames = r
                    .render_views(gpu, &mesh, &cams, &lighting(), &s, method)
                    .unwrap();
                let scene = forward(&r, gpu, &mesh, &cams, &s, method);
                let g = r
                    .backward(gpu, &scene.last_run().unwrap().binned(), &w, true)
                    .unwrap();
                (frame_bits(&frames), bits(&g))
            };
            let (a, b) = (run(&own), run(&gpu_shapes));
            let what = format!("R = {res}, {color_mode:?}, tile {tile}");
            assert!(a.0 == b.0, "{what}: forward bits differ");
            assert!(a.1 == b.1, "{what}: gradient bits differ");
        }
    }
}
