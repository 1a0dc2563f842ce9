//! The GPU forward against the f64 CPU twin `raster::reference`, on lavapipe with validation on.
//! Every GPU render here goes through [`render_all`]: the brute-force kernel (one invocation per
//! pixel over every face) and the tiled one (binning → per-tile faces) at tile sizes 8, 16 and
//! 32 must agree bit for bit, images and aux, before the brute image is compared with the twin.
//!
//! How "equal" is judged: the GPU works in f32, so its screen positions carry a rounding of a
//! few 1e-7. Where the forward is continuous that moves a pixel by far less than 1e-4; where it
//! jumps (hard coverage and hard colour at an edge, the coverage cut-off, texel boundaries, a
//! near/far drop) no tolerance helps. So the twin is also evaluated at pixel centres shifted by
//! ±[`JITTER`] in x and y. Where it moves by at most [`TOL`] under those shifts, the GPU must be
//! within [`TOL`] of the twin at the centre; where it moves more (a discontinuity), the GPU must
//! lie within [`TOL`] of the range the twin spans. Such pixels are counted, and each check bounds
//! how many there may be, so the rule cannot quietly excuse everything.

mod common;

use glam::DVec3;
use rand::RngExt;
use softvk::camera::{Camera, Projection, pixel_center};
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::primitives::binning::{self, TileGrid};
use softvk::raster::gpu::{Frames, Method, Renderer};
use softvk::raster::reference::{self, FaceColors, project_faces, setup_face, shade_pixel};
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};
use softvk::raster::setup::{FACE_DEGENERATE, FACE_FINITE, FACE_FRONT, GpuFaceSetup};

/// Absolute tolerance per channel.
const TOL: f64 = 1e-4;
/// Tolerance at γ = 1e-6, where f32 depth rounding alone moves colours by ~1e-4 (see
/// `tiny_gamma_does_not_overflow_and_matches_the_twin`).
const TINY_GAMMA_TOL: f64 = 5e-4;
/// Shift of the pixel centre that models the GPU's f32 rounding of screen positions.
const JITTER: f64 = 1e-6;

/// Tile sizes every test scene is rendered with.
const TILES: [u32; 3] = [8, 16, 32];

/// Bit patterns of a frame set, so that -0.0 vs 0.0 and NaN payloads count as differences.
/// The face setups of `mesh` seen from `cams` (view-major), read back after a forward.
fn face_setups(
    r: &Renderer,
    gpu: &common::Gpu,
    mesh: &Mesh,
    cams: &[Camera],
    s: &RasterSettings,
) -> Vec<GpuFaceSetup> {
    let mut scene = r.prepare(gpu, mesh, cams, &Lighting::unlit(), s).unwrap();
    r.run(gpu, &mut scene, Method::default()).unwrap();
    scene.read_setups(gpu).unwrap()
}

fn bits(f: &Frames) -> (Vec<u32>, Vec<u32>) {
    (
        f.images.iter().flatten().map(|c| c.to_bits()).collect(),
        f.aux
            .iter()
            .flat_map(|a| {
                [
                    a.softmax_ref_depth.to_bits(),
                    a.softmax_sum.to_bits(),
                    a.alpha_acc.to_bits(),
                    a.alpha_zeros,
                    a.hard_face,
                ]
            })
            .collect(),
    )
}

/// Renders with the brute-force kernel and with the tiled one at every size of [`TILES`],
/// asserts that all agree bit for bit (images and aux), and returns the frames.
fn render_all(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    cams: &[Camera],
    lit: &Lighting,
    s: &RasterSettings,
) -> Frames {
    let brute = r
        .render_views(gpu, mesh, cams, lit, s, Method::Brute)
        .unwrap_or_else(|e| panic!("{what}: brute: {e}"));
    let want = bits(&brute);
    for tile in TILES {
        let tiled = r
            .render_views(gpu, mesh, cams, lit, s, Method::Tiled { tile })
            .unwrap_or_else(|e| panic!("{what}: tiled {tile}: {e}"));
        let got = bits(&tiled);
        if got != want {
            let px = got.0.iter().zip(&want.0).position(|(a, b)| a != b);
            let ax = got.1.iter().zip(&want.1).position(|(a, b)| a != b);
            panic!(
                "{what}: tiled ({tile}) differs from brute force: first image word {px:?} \
                 (tiled {:?} vs brute {:?}), first aux word {ax:?}\nsettings {s:?}",
                px.map(|i| f32::from_bits(got.0[i])),
                px.map(|i| f32::from_bits(want.0[i])),
            );
        }
    }
    brute
}

/// The twin at every pixel centre shifted by `(dx, dy)` (anti-aliasing as `reference::render`).
fn twin(
    mesh: &Mesh,
    cam: &Camera,
    lit: &Lighting,
    s: &RasterSettings,
    (dx, dy): (f64, f64),
) -> Vec<[f64; 4]> {
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

/// What one comparison found.
#[derive(Debug, Default)]
struct Stats {
    /// Largest |GPU − twin| over pixels where the twin is continuous.
    max_err: f64,
    /// Largest distance of a GPU value outside the twin's jitter range.
    worst: f64,
    /// Pixels where the twin spans more than TOL under the jitter.
    steep: usize,
    /// Pixels the twin covers with alpha > 0.5.
    covered: usize,
    pixels: usize,
}

/// Compares a GPU image with the twin as the module doc says; panics with the first offender.
fn compare(
    what: &str,
    tol: f64,
    gpu: &[[f32; 4]],
    mesh: &Mesh,
    cam: &Camera,
    lit: &Lighting,
    s: &RasterSettings,
) -> Stats {
    let centre = twin(mesh, cam, lit, s, (0.0, 0.0));
    let shifted: Vec<Vec<[f64; 4]>> =
        [(JITTER, 0.0), (-JITTER, 0.0), (0.0, JITTER), (0.0, -JITTER)]
            .into_iter()
            .map(|d| twin(mesh, cam, lit, s, d))
            .collect();
    assert_eq!(gpu.len(), centre.len(), "{what}: image size");
    let mut stats = Stats {
        pixels: gpu.len(),
        ..Stats::default()
    };
    for (i, (g, c)) in gpu.iter().zip(&centre).enumerate() {
        let mut steep = false;
        for k in 0..4 {
            let g = f64::from(g[k]);
            let (mut lo, mut hi) = (c[k], c[k]);
            for img in &shifted {
                lo = lo.min(img[i][k]);
                hi = hi.max(img[i][k]);
            }
            // Continuous here: the plain tolerance. At a discontinuity: the twin's range.
            let ok = if hi - lo <= tol {
                (g - c[k]).abs() <= tol
            } else {
                g >= lo - tol && g <= hi + tol
            };
            assert!(
                ok,
                "{what}: pixel {i} (col {}, row {}) channel {k}: GPU {g} vs twin {} (range \
                 [{lo}, {hi}] under ±{JITTER} shifts)\nsettings {s:?}",
                i as u32 % s.width,
                i as u32 / s.width,
                c[k]
            );
            stats.worst = stats.worst.max(lo - g).max(g - hi);
            if hi - lo <= tol {
                stats.max_err = stats.max_err.max((g - c[k]).abs());
            } else {
                steep = true;
            }
        }
        stats.steep += usize::from(steep);
        stats.covered += usize::from(c[3] > 0.5);
    }
    stats
}

/// Renders on the GPU, compares, and bounds the share of pixels at discontinuities.
fn check(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    cam: &Camera,
    lit: &Lighting,
    s: &RasterSettings,
) -> Stats {
    let img = render_all(r, gpu, what, mesh, std::slice::from_ref(cam), lit, s).images;
    let stats = compare(what, TOL, &img, mesh, cam, lit, s);
    assert!(
        stats.steep * 10 <= stats.pixels.max(10),
        "{what}: {} of {} pixels sit at discontinuities; the comparison says too little",
        stats.steep,
        stats.pixels
    );
    stats
}

fn random_colors(n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = common::rng(seed);
    (0..n)
        .map(|_| std::array::from_fn(|_| rng.random_range(0.0..1.0f32)))
        .collect()
}

/// Hand-made triangles: two overlapping faces of different colours at different depths, a
/// third intersecting the first, a face crossing the image border, one wound backwards, one
/// behind the camera, one beyond the far plane, and a zero-area face (two coincident vertices).
fn triangles(res: u32) -> Mesh {
    let positions = vec![
        // 0: big, z = 0
        [-0.6, -0.5, 0.0],
        [-0.1, 0.6, 0.0],
        [0.5, -0.4, 0.0],
        // 1: overlapping, nearer (z = -0.3)
        [-0.2, -0.2, -0.3],
        [0.1, 0.4, -0.3],
        [0.6, 0.0, -0.3],
        // 2: intersecting face 0 (z from -0.2 to 0.2)
        [-0.5, 0.1, -0.2],
        [0.0, 0.2, 0.2],
        [0.1, -0.3, 0.0],
        // 3: crossing the image border
        [0.6, 0.5, 0.1],
        [1.5, 0.9, 0.1],
        [1.2, -0.2, 0.1],
        // 4: back-facing (wound the other way)
        [-0.9, -0.9, 0.05],
        [-0.5, -0.3, 0.05],
        [-0.3, -0.8, 0.05],
        // 5: behind the camera (camera at z = -2.732 looks along +z)
        [-0.5, 0.5, -3.5],
        [0.5, 0.5, -3.5],
        [0.0, -0.5, -3.5],
        // 6: beyond far (z = 150 > 100)
        [-20.0, -20.0, 150.0],
        [-10.0, 30.0, 150.0],
        [30.0, -10.0, 150.0],
        // 7: zero area: two coincident vertices
        [-0.7, 0.7, 0.0],
        [-0.7, 0.7, 0.0],
        [-0.2, 0.8, 0.0],
    ];
    let faces = vec![
        [0, 1, 2],
        [3, 4, 5],
        [6, 7, 8],
        [9, 10, 11],
        [12, 14, 13],
        [15, 16, 17],
        [18, 19, 20],
        [21, 22, 23],
    ];
    let mut mesh = Mesh::new(positions, faces, res).unwrap();
    mesh.textures = random_colors(mesh.textures.len(), 7);
    mesh.vertex_colors = Some(random_colors(mesh.vertex_count(), 8));
    mesh
}

fn icosphere(res: u32) -> Mesh {
    let mut mesh = Mesh::icosphere(2);
    mesh.texture_res = res;
    mesh.textures = random_colors(mesh.face_count() * (res * res) as usize, 11);
    mesh.vertex_colors = Some(random_colors(mesh.vertex_count(), 12));
    mesh.positions.iter_mut().for_each(|p| {
        p.iter_mut().for_each(|c| *c *= 0.8);
    });
    mesh
}

fn lighting() -> Lighting {
    Lighting {
        ambient_intensity: 0.4,
        ambient_color: [1.0, 0.9, 0.8],
        directionals: vec![Directional {
            intensity: 0.6,
            color: [1.0, 1.0, 1.0],
            direction: [0.3, 0.8, -0.5],
        }],
    }
}

const DISTS: [Dist; 3] = [Dist::Euclidean, Dist::Barycentric, Dist::Hard];
const ALPHAS: [Alpha; 3] = [Alpha::Prod, Alpha::Sum, Alpha::Hard];
const RGBS: [Rgb; 2] = [Rgb::Softmax, Rgb::Hard];
const COLOR_MODES: [ColorMode; 2] = [ColorMode::Surface, ColorMode::Vertex];

/// Every combination of distance, alpha, colour aggregation, colour source and sidedness, with
/// the other settings varied round-robin: σ default and large, γ small, default and large,
/// near/far, background, anti-aliasing, image shape.
fn all_modes(base: RasterSettings, shapes: &[(u32, u32)]) -> Vec<RasterSettings> {
    let variants: [(f64, f64, f64, f64, [f64; 3], bool); 6] = [
        (1e-5, 1e-4, 1.0, 100.0, [0.0; 3], false),
        (1e-2, 1e-4, 1.0, 100.0, [0.2, 0.4, 0.6], false),
        (1e-4, 1e-2, 2.0, 3.0, [1.0, 1.0, 1.0], true),
        (1e-3, 1e-5, 0.5, 50.0, [0.1, 0.0, 0.3], false),
        (3e-3, 0.3, 1.0, 100.0, [0.0; 3], true),
        (1e-5, 1e-4, 2.75, 100.0, [0.5; 3], false),
    ];
    let mut out = Vec::new();
    let mut i = 0;
    for dist in DISTS {
        for alpha in ALPHAS {
            for rgb in RGBS {
                for color_mode in COLOR_MODES {
                    for double_sided in [true, false] {
                        let (sigma, gamma, near, far, background, antialias) =
                            variants[i % variants.len()];
                        let (width, height) = shapes[i % shapes.len()];
                        out.push(RasterSettings {
                            width,
                            height,
                            sigma,
                            gamma,
                            near,
                            far,
                            background,
                            antialias,
                            dist,
                            alpha,
                            rgb,
                            color_mode,
                            double_sided,
                            ..base
                        });
                        i += 1;
                    }
                }
            }
        }
    }
    out
}

/// Prints the totals of a family of comparisons and checks that they were not vacuous.
fn report(what: &str, all: &[Stats]) {
    let max = all.iter().map(|s| s.max_err).fold(0.0, f64::max);
    let worst = all.iter().map(|s| s.worst).fold(0.0, f64::max);
    let steep: usize = all.iter().map(|s| s.steep).sum();
    let covered: usize = all.iter().map(|s| s.covered).sum();
    let pixels: usize = all.iter().map(|s| s.pixels).sum();
    eprintln!(
        "{what}: {} renders, {pixels} pixels ({covered} covered): max |GPU - twin| {max:.2e} where \
         continuous; {steep} pixels at discontinuities, worst excess over the twin's range \
         {worst:.2e}",
        all.len()
    );
    assert!(
        covered * 10 >= pixels,
        "{what}: the scenes cover too little to prove much"
    );
}

#[test]
fn hand_made_triangles_match_the_twin_in_every_mode() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let lit = lighting();
    let shapes = [(24, 16), (17, 17), (16, 24), (1, 1), (31, 9)];
    let mut all = Vec::new();
    for res in [1, 3] {
        let mesh = triangles(res);
        for (i, s) in all_modes(RasterSettings::default(), &shapes)
            .iter()
            .enumerate()
        {
            let cam = if i % 4 == 3 {
                Camera {
                    projection: Projection::Orthographic { scale: 0.9 },
                    ..Camera::default()
                }
            } else {
                Camera::default()
            };
            all.push(check(
                &r,
                &gpu,
                &format!("triangles R={res} #{i}"),
                &mesh,
                &cam,
                &lit,
                s,
            ));
        }
    }
    report("triangles", &all);
}

#[test]
fn icosphere_matches_the_twin_in_every_mode() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let lit = lighting();
    let mesh = icosphere(2);
    let cam = Camera::from_angles(2.732, 20.0, 35.0);
    let mut all = Vec::new();
    for (i, s) in all_modes(RasterSettings::default(), &[(17, 17), (24, 16)])
        .iter()
        .enumerate()
    {
        all.push(check(
            &r,
            &gpu,
            &format!("icosphere #{i}"),
            &mesh,
            &cam,
            &lit,
            s,
        ));
    }
    report("icosphere", &all);
}

#[test]
fn spot_matches_the_twin_at_32x32() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let path = softvk::assets::dir().join("spot_triangulated.obj");
    let cam = Camera::from_angles(2.732, 30.0, -45.0);
    let lit = Lighting::default();
    let mut all = Vec::new();
    for res in [1, 2] {
        let mesh = Mesh::load_obj(&path, res).unwrap();
        for (i, s) in [
            RasterSettings::default(),
            RasterSettings {
                dist: Dist::Barycentric,
                alpha: Alpha::Sum,
                double_sided: false,
                ..RasterSettings::default()
            },
            RasterSettings {
                sigma: 1e-2,
                gamma: 0.3,
                antialias: true,
                ..RasterSettings::default()
            },
            RasterSettings {
                dist: Dist::Hard,
                rgb: Rgb::Hard,
                alpha: Alpha::Hard,
                color_mode: ColorMode::Vertex,
                ..RasterSettings::default()
            },
        ]
        .into_iter()
        .enumerate()
        {
            let s = RasterSettings {
                width: 32,
                height: 32,
                ..s
            };
            all.push(check(
                &r,
                &gpu,
                &format!("spot R={res} #{i}"),
                &mesh,
                &cam,
                &lit,
                &s,
            ));
        }
    }
    report("spot", &all);
}

#[test]
fn two_runs_are_bit_identical() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = icosphere(3);
    let cam = Camera::from_angles(2.5, 10.0, 60.0);
    let s = RasterSettings {
        width: 24,
        height: 16,
        sigma: 1e-3,
        antialias: true,
        ..RasterSettings::default()
    };
    // Fresh renderers, fresh scenes: nothing carried over but the inputs.
    for method in [
        Method::Brute,
        Method::Tiled { tile: 8 },
        Method::Tiled { tile: 16 },
    ] {
        let a = r
            .render_views(&gpu, &mesh, &[cam], &lighting(), &s, method)
            .unwrap();
        let b = Renderer::new(&gpu)
            .unwrap()
            .render_views(&gpu, &mesh, &[cam], &lighting(), &s, method)
            .unwrap();
        assert!(bits(&a) == bits(&b), "{method:?}");
    }
}

/// Slivers, near-degenerate and collinear faces, a point: culling by the f32 grown boxes must
/// change no bit, in every distance mode and for σ from tiny to huge.
#[test]
fn culling_by_the_f32_boxes_changes_no_bit() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mut rng = common::rng(3);
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    let mut push = |tri: [[f32; 3]; 3], positions: &mut Vec<[f32; 3]>| {
        let base = positions.len() as u32;
        positions.extend_from_slice(&tri);
        faces.push([base, base + 1, base + 2]);
    };
    for i in 0..60 {
        let mut v: [[f32; 3]; 3] = std::array::from_fn(|_| {
            [
                rng.random_range(-1.0..1.0f32),
                rng.random_range(-1.0..1.0f32),
                rng.random_range(-0.3..0.3f32),
            ]
        });
        match i % 5 {
            0 => {
                // Sliver: third vertex within 1e-4 of the first edge's line.
                let t = rng.random_range(-0.5..1.5f32);
                v[2] = std::array::from_fn(|k| v[0][k] + t * (v[1][k] - v[0][k]));
                v[2][1] += rng.random_range(-1e-4..1e-4f32);
            }
            1 => {
                // Near-degenerate: within a few ulp of collinear.
                let t = rng.random_range(0.2..0.8f32);
                v[2] = std::array::from_fn(|k| v[0][k] + t * (v[1][k] - v[0][k]));
                v[2][0] += rng.random_range(-1e-7..1e-7f32);
            }
            2 => {
                // Small.
                let base = v[0];
                for p in &mut v[1..] {
                    for k in 0..2 {
                        p[k] = base[k] + rng.random_range(-0.02..0.02f32);
                    }
                }
            }
            _ => {}
        }
        push(v, &mut positions);
    }
    push([[0.1, 0.1, 0.0]; 3], &mut positions);
    let mut mesh = Mesh::new(positions, faces, 1).unwrap();
    mesh.textures = random_colors(mesh.face_count(), 5);
    let cam = Camera::from_angles(2.732, 5.0, 10.0);
    for dist in DISTS {
        for sigma in [1e-5, 1e-3, 3e-2] {
            let s = RasterSettings {
                width: 40,
                height: 36,
                sigma,
                gamma: 1e-2,
                dist,
                alpha: Alpha::Sum,
                ..RasterSettings::default()
            };
            let run = |cull| {
                r.render_brute_views_with_cull(&gpu, &mesh, &[cam], &Lighting::default(), &s, cull)
                    .unwrap()
            };
            let (culled, brute) = (run(true), run(false));
            let bits = |f: &softvk::raster::gpu::Frames| -> Vec<u32> {
                f.images.iter().flatten().map(|c| c.to_bits()).collect()
            };
            assert!(
                bits(&culled) == bits(&brute),
                "{dist:?} σ = {sigma}: culling changed the image"
            );
        }
    }
}

#[test]
fn face_setup_matches_the_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = triangles(1);
    let cams = [
        Camera::default(),
        Camera::from_angles(3.0, 25.0, -40.0),
        Camera {
            projection: Projection::Orthographic { scale: 0.7 },
            ..Camera::from_angles(2.0, -10.0, 20.0)
        },
    ];
    for dist in DISTS {
        let s = RasterSettings {
            dist,
            sigma: 1e-3,
            ..RasterSettings::default()
        };
        let setups = face_setups(&r, &gpu, &mesh, &cams, &s);
        assert_eq!(setups.len(), cams.len() * mesh.face_count());
        for (v, cam) in cams.iter().enumerate() {
            for (j, tri) in project_faces(&mesh, cam).into_iter().enumerate() {
                let twin = setup_face(tri, dist, s.cutoff());
                let g = &setups[v * mesh.face_count() + j];
                let what = format!("{dist:?} view {v} face {j}");
                for k in 0..3 {
                    for c in 0..3 {
                        let (a, b) = (f64::from(g.v[k][c]), twin.v[k][c]);
                        assert!(
                            (a - b).abs() <= 1e-6 * (1.0 + b.abs()),
                            "{what}: v {a} vs {b}"
                        );
                    }
                }
                assert_ne!(g.flags & FACE_FINITE, 0, "{what}");
                let degenerate = g.flags & FACE_DEGENERATE != 0;
                if j == 7 {
                    assert!(degenerate, "{what}: the zero-area face is degenerate");
                    assert!(g.bbox[0] == f32::NEG_INFINITY && g.bbox[3] == f32::INFINITY);
                    continue;
                }
                assert!(!degenerate, "{what}");
                assert_eq!(g.flags & FACE_FRONT != 0, twin.front, "{what}: facing");
                // M_j: relative to the row's scale.
                for k in 0..3 {
                    let scale = twin.inv[k].iter().map(|x| x.abs()).fold(0.0, f64::max);
                    for c in 0..3 {
                        let (a, b) = (f64::from(g.inv[k][c]), twin.inv[k][c]);
                        assert!((a - b).abs() <= 1e-4 * scale, "{what}: inv {a} vs {b}");
                    }
                }
                // The f32 box holds the twin's.
                let b = twin.bbox;
                let gb = g.bbox.map(f64::from);
                assert!(
                    gb[0] <= b[0] && gb[1] <= b[1] && gb[2] >= b[2] && gb[3] >= b[3],
                    "{what}: box {gb:?} does not hold {b:?}"
                );
            }
        }
    }
}

/// The aux buffer holds the forward's running aggregates: checked against the same loop as
/// `shade_pixel` in f64, at a γ where the softmax is well conditioned.
#[test]
fn aux_holds_the_softmax_and_alpha_aggregates() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = icosphere(1);
    let cam = Camera::from_angles(2.732, 20.0, 35.0);
    for (alpha, rgb) in [(Alpha::Prod, Rgb::Softmax), (Alpha::Sum, Rgb::Hard)] {
        let s = RasterSettings {
            width: 16,
            height: 12,
            sigma: 1e-3,
            gamma: 0.05,
            alpha,
            rgb,
            ..RasterSettings::default()
        };
        let frames = render_all(&r, &gpu, "aux", &mesh, &[cam], &lighting(), &s);
        let faces: Vec<_> = project_faces(&mesh, &cam)
            .into_iter()
            .map(|v| setup_face(v, s.dist, s.cutoff()))
            .collect();
        let t = s.cutoff();
        let range = s.far - s.near;
        for (i, a) in frames.aux.iter().enumerate() {
            let (xp, yp) = pixel_center(i as u32 % s.width, i as u32 / s.width, s.width, s.height);
            let mut acc = if alpha == Alpha::Prod { 1.0 } else { 0.0 };
            let mut zmin = s.far - s.eps * range;
            let mut terms = vec![(zmin, 1.0)];
            let mut hard: Option<(f64, usize)> = None;
            for (j, f) in faces.iter().enumerate() {
                let w = reference::barycentric(f, xp, yp);
                let Some(d) = reference::coverage(f, &w, xp, yp, s.dist, s.sigma, t) else {
                    continue;
                };
                acc = if alpha == Alpha::Prod {
                    acc * (1.0 - d)
                } else {
                    acc + d
                };
                let z = reference::depth(f, &reference::clip_barycentric(w));
                if !(z >= s.near && z <= s.far) {
                    continue;
                }
                zmin = zmin.min(z);
                terms.push((z, d));
                if reference::inside_closed(&w) && hard.is_none_or(|(hz, _)| z < hz) {
                    hard = Some((z, j));
                }
            }
            let sum: f64 = terms
                .iter()
                .map(|&(z, d)| d * ((zmin - z) / (s.gamma * range)).exp())
                .sum();
            let what = format!("{alpha:?} {rgb:?} pixel {i}: {a:?}");
            if a.alpha_zeros == 0 {
                assert!(
                    (f64::from(a.alpha_acc) - acc).abs() < 1e-4,
                    "{what} vs {acc}"
                );
            } else {
                // Some 1 − D rounded to 0 in f32: the f64 product holds a factor below 2^-23.
                assert!(alpha == Alpha::Prod && acc < 1.2e-7, "{what} vs {acc}");
            }
            if rgb == Rgb::Softmax {
                assert!(
                    (f64::from(a.softmax_ref_depth) - zmin).abs() < 1e-5,
                    "{what} vs {zmin}"
                );
                assert!(
                    (f64::from(a.softmax_sum) - sum).abs() < 1e-4 * sum,
                    "{what} vs {sum}"
                );
            } else {
                let expected = hard.map_or(u32::MAX, |(_, j)| j as u32);
                assert_eq!(a.hard_face, expected, "{what}");
            }
        }
    }
}

/// Icospheres of `subdivisions` shrunk to `radii` about (-0.79, 0.79, 0), one inside the
/// other: at 16² through the default camera they cover a few pixels in the top-left 8×8 tile,
/// so every face lands in one tile of any size.
fn crowded_spheres(subdivisions: u32, radii: &[f32]) -> Mesh {
    let ico = Mesh::icosphere(subdivisions);
    let (mut positions, mut faces) = (Vec::new(), Vec::new());
    for r in radii {
        let base = positions.len() as u32;
        positions.extend(
            ico.positions
                .iter()
                .map(|p| [r * p[0] - 0.79, r * p[1] + 0.79, r * p[2]]),
        );
        faces.extend(ico.faces.iter().map(|f| f.map(|i| i + base)));
    }
    let mut mesh = Mesh::new(positions, faces, 1).unwrap();
    mesh.textures = random_colors(mesh.face_count(), 61);
    mesh.vertex_colors = Some(random_colors(mesh.vertex_count(), 62));
    mesh
}

/// A tile just past the loop cap: 61 440 faces in one tile (three nested spheres) need more
/// iterations than one invocation of the tiled forward may run on llvmpipe (about 1.25 or 1.5
/// per face, with 8 or 4 lanes), so it is folded in two passes, while brute force (one per
/// face) still takes the face list in one. The split tiled render equals the unsplit brute-force one bit for bit,
/// images and aux ([`render_all`]), in every colour and alpha mode, and the twin.
#[test]
fn a_tile_just_past_the_loop_cap_renders_in_passes_as_brute_force_in_one() {
    let Some(gpu) = common::gpu() else { return };
    if let Some(limit) = gpu.info().shader_loop_limit() {
        assert!(61_440 + 61_440 / 4 > limit && 61_440 + 2 < limit);
    }
    let r = Renderer::new(&gpu).unwrap();
    let mesh = crowded_spheres(5, &[0.3, 0.27, 0.24]);
    assert_eq!(mesh.face_count(), 61_440);
    let cam = Camera::default();
    for (rgb, alpha, mode) in [
        (Rgb::Softmax, Alpha::Prod, ColorMode::Surface),
        (Rgb::Hard, Alpha::Sum, ColorMode::Vertex),
    ] {
        let s = RasterSettings {
            width: 16,
            height: 16,
            sigma: 1e-5,
            gamma: 1e-3,
            rgb,
            alpha,
            color_mode: mode,
            ..RasterSettings::default()
        };
        let stats = check(
            &r,
            &gpu,
            "61k faces in a tile",
            &mesh,
            &cam,
            &lighting(),
            &s,
        );
        // (Sum's alpha is the coverage summed over every face of the mesh, divided by their
        // count: small everywhere here.)
        assert!(alpha == Alpha::Sum || stats.covered >= 4, "{stats:?}");
    }
}

/// One tile holding over 200 000 faces (an icosphere of 327 680, a few pixels wide): the tiled
/// forward folds it in passes and brute force its face list (more than 150 000 faces), carrying
/// every pixel's alpha, softmax and hard-colour state between passes; both equal each other
/// bit for bit and the twin.
#[test]
fn a_tile_of_over_200k_faces_renders_by_both_methods_as_the_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = crowded_spheres(7, &[0.3]);
    assert!(mesh.face_count() >= 200_000);
    let cam = Camera::default();
    for (rgb, alpha) in [(Rgb::Softmax, Alpha::Prod), (Rgb::Hard, Alpha::Hard)] {
        let s = RasterSettings {
            width: 16,
            height: 16,
            sigma: 1e-5,
            gamma: 1e-3,
            rgb,
            alpha,
            ..RasterSettings::default()
        };
        let stats = check(
            &r,
            &gpu,
            "327k faces in a tile",
            &mesh,
            &cam,
            &lighting(),
            &s,
        );
        assert!(stats.covered >= 4, "{stats:?}");
    }
}

#[test]
fn several_views_render_as_one_view_each() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = icosphere(1);
    let cams = [
        Camera::from_angles(2.732, 0.0, 0.0),
        Camera::from_angles(2.732, 40.0, 90.0),
        Camera::from_angles(3.5, -20.0, 200.0),
    ];
    let s = RasterSettings {
        width: 13,
        height: 11,
        antialias: true,
        ..RasterSettings::default()
    };
    let all = render_all(&r, &gpu, "3 views", &mesh, &cams, &lighting(), &s);
    for (v, cam) in cams.iter().enumerate() {
        let one = render_all(
            &r,
            &gpu,
            "1 view",
            &mesh,
            std::slice::from_ref(cam),
            &lighting(),
            &s,
        );
        assert!(all.image(v) == one.images.as_slice(), "view {v}");
    }
}

/// γ = 1e-6 and 1e-9: the running maximum keeps every exponent ≤ 0, so nothing overflows; at
/// 1e-6 the image still matches the twin. This is where f32 is at its limit: half an ulp of a depth
/// near 2 is 1.2e-7, already 2.4e-3 of γ (far − near) ≈ 1e-4, so where two faces of different
/// colours meet at nearly equal depth (the shared edges of the icosphere) the weights carry a few
/// 1e-3 of relative error and the colour up to ~1e-4 (measured on lavapipe: 1.0e-4). The bound
/// here is [`TINY_GAMMA_TOL`].
#[test]
fn tiny_gamma_does_not_overflow_and_matches_the_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let cam = Camera::from_angles(2.732, 20.0, 35.0);
    let mut all = Vec::new();
    for (name, mesh) in [("triangles", triangles(2)), ("icosphere", icosphere(1))] {
        for gamma in [1e-6, 1e-9] {
            for dist in DISTS {
                let s = RasterSettings {
                    width: 20,
                    height: 20,
                    gamma,
                    sigma: 1e-3,
                    dist,
                    ..RasterSettings::default()
                };
                let what = format!("{name} γ = {gamma} {dist:?}");
                let img = render_all(&r, &gpu, &what, &mesh, &[cam], &lighting(), &s).images;
                assert!(
                    img.iter()
                        .flatten()
                        .all(|c| c.is_finite() && (0.0..=1.0).contains(c)),
                    "{what}"
                );
                // At γ = 1e-9 one ulp of depth is ~2 units of exponent: f32 cannot follow the
                // twin's mixing of faces at equal depth any more, only stay finite and in range.
                if gamma >= 1e-6 {
                    all.push(compare(
                        &what,
                        TINY_GAMMA_TOL,
                        &img,
                        &mesh,
                        &cam,
                        &lighting(),
                        &s,
                    ));
                }
            }
        }
    }
    report("tiny γ", &all);
}

/// A vertex exactly on the camera plane (camera z = 0 in f32 and f64 alike) has no screen
/// position: its face is skipped entirely, by the twin and the GPU.
#[test]
fn a_vertex_on_the_camera_plane_skips_its_face() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let cam = Camera {
        eye: DVec3::new(0.0, 0.0, -2.0),
        ..Camera::default()
    };
    let mut mesh = Mesh::new(
        vec![
            [-0.5, -0.5, 0.0],
            [0.0, 0.5, 0.0],
            [0.5, -0.5, 0.0],
            [0.3, 0.3, -2.0],
            [0.6, 0.2, 1.0],
            [0.2, -0.6, 0.5],
        ],
        vec![[0, 1, 2], [3, 4, 5]],
        1,
    )
    .unwrap();
    mesh.textures = vec![[0.9, 0.2, 0.1], [0.1, 0.8, 0.3]];
    let setups = face_setups(&r, &gpu, &mesh, &[cam], &RasterSettings::default());
    assert_ne!(setups[0].flags & FACE_FINITE, 0);
    assert_eq!(setups[1].flags & FACE_FINITE, 0);
    let s = RasterSettings {
        width: 12,
        height: 10,
        sigma: 1e-3,
        ..RasterSettings::default()
    };
    let stats = check(
        &r,
        &gpu,
        "camera plane",
        &mesh,
        &cam,
        &Lighting::unlit(),
        &s,
    );
    assert!(stats.covered > 0);
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = Mesh::icosphere(0);
    let lit = Lighting::default();
    let s = RasterSettings {
        width: 4,
        height: 4,
        ..RasterSettings::default()
    };
    let matrix = Camera {
        projection: Projection::Matrix {
            p: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
            ],
            dist_coeffs: [0.0; 5],
            orig_size: 0.0,
        },
        ..Camera::default()
    };
    let err = r
        .render_views(
            &gpu,
            &mesh,
            std::slice::from_ref(&matrix),
            &lit,
            &s,
            Method::Brute,
        )
        .unwrap_err();
    assert!(matches!(err, softvk::Error::Input(_)), "{err}");
    let bad = RasterSettings { sigma: -1.0, ..s };
    let err = r
        .render_views(
            &gpu,
            &mesh,
            std::slice::from_ref(&Camera::default()),
            &lit,
            &bad,
            Method::Brute,
        )
        .unwrap_err();
    assert!(matches!(err, softvk::Error::Render(_)), "{err}");
    let mut broken = mesh.clone();
    broken.faces[2][0] = 1000;
    let err = r
        .render_views(
            &gpu,
            &broken,
            std::slice::from_ref(&Camera::default()),
            &lit,
            &s,
            Method::Brute,
        )
        .unwrap_err();
    assert!(err.to_string().contains("face 2"), "{err}");
    let nan_eye = Camera {
        eye: DVec3::new(f64::NAN, 0.0, -2.0),
        ..Camera::default()
    };
    let err = r
        .render_views(
            &gpu,
            &mesh,
            std::slice::from_ref(&nan_eye),
            &lit,
            &s,
            Method::Brute,
        )
        .unwrap_err();
    assert!(matches!(err, softvk::Error::Input(_)), "{err}");
}

// ---- Adversarial binning -------------------------------------------------------------------
// The scenes above already hold faces across the image border, behind the camera, beyond far
// and of zero area, at 1×1 and non-square sizes, through every mode and three tile sizes. These
// push the binning itself: its capacities, its batches and its view groups.

/// `n` small random triangles at random depths, all inside a box of `extent` around (cx, cy)
/// (screen units at the default camera), with random colours.
fn cluster(n: usize, (cx, cy): (f32, f32), extent: f32, seed: u64) -> Mesh {
    let mut rng = common::rng(seed);
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    for f in 0..n {
        let z: f32 = rng.random_range(-0.1..0.1);
        for _ in 0..3 {
            positions.push([
                cx + rng.random_range(-extent..extent),
                cy + rng.random_range(-extent..extent),
                z,
            ]);
        }
        faces.push([3 * f as u32, 3 * f as u32 + 1, 3 * f as u32 + 2]);
    }
    let mut mesh = Mesh::new(positions, faces, 1).unwrap();
    mesh.textures = random_colors(mesh.textures.len(), seed + 1);
    mesh.vertex_colors = Some(random_colors(mesh.vertex_count(), seed + 2));
    mesh
}

/// Bins on the GPU, bins the GPU's own f32 boxes with the CPU twin, and asserts the two agree
/// exactly; then checks that every face whose box contains a pixel centre is in that pixel's
/// tile (the fine pass's cull test is that box test, so nothing it would visit is missing).
/// Returns the GPU binning.
fn check_binning(
    r: &Renderer,
    gpu: &common::Gpu,
    what: &str,
    mesh: &Mesh,
    cams: &[Camera],
    s: &RasterSettings,
    tile: u32,
) -> binning::cpu::Binned {
    let mut scene = r
        .prepare(gpu, mesh, cams, &Lighting::unlit(), s)
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    let run = r
        .run(gpu, &mut scene, Method::Tiled { tile })
        .unwrap_or_else(|e| panic!("{what}: {e}"))
        .binned();
    let mut groups = run.read_bins(gpu).unwrap();
    assert_eq!(groups.len(), 1, "{what}: one binning of every view");
    let binned = groups.pop().unwrap();
    let setups = run.scene().read_setups(gpu).unwrap();
    let k = if s.antialias { 2 } else { 1 };
    let grid = TileGrid::new(s.width * k, s.height * k, tile).unwrap();
    let boxes: Vec<Option<[f32; 4]>> = setups
        .iter()
        .map(|f| (f.flags & FACE_FINITE != 0).then_some(f.bbox))
        .collect();
    let twin = binning::cpu::bin(&boxes, mesh.face_count() as u32, &grid);
    assert!(
        binned == twin,
        "{what}: GPU binning differs from its CPU twin"
    );
    let f = mesh.face_count();
    let per_view = grid.tiles_per_view() as usize;
    for v in 0..cams.len() {
        for row in 0..grid.height {
            for col in 0..grid.width {
                let (x, y) = pixel_center(col, row, grid.width, grid.height);
                let (x, y) = (x as f32, y as f32);
                let (tx, ty) = binning::cpu::pixel_tile(col, row, &grid);
                let t = v * per_view + (ty * grid.tiles_x + tx) as usize;
                let listed = binned.tile_items(t);
                for (j, b) in boxes[v * f..(v + 1) * f].iter().enumerate() {
                    if let Some(b) = b {
                        if x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3] {
                            assert!(
                                listed.contains(&(j as u32)),
                                "{what}: face {j} of view {v} covers pixel ({col}, {row}) but is \
                                 not in its tile {t}"
                            );
                        }
                    }
                }
            }
        }
    }
    binned
}

/// 150 faces (over three shared-memory batches of 64) all inside one 8×8 tile.
#[test]
fn all_faces_in_one_tile() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    // 48×40 at the default camera: pixel (19.5, 19.5), the centre of tile (2, 2), is world
    // (-0.315, 0); one pixel is ~0.08 world units there, so the cluster spans ~3.5 pixels.
    let mesh = cluster(150, (-0.315, 0.0), 0.12, 21);
    let mut all = Vec::new();
    for (i, s) in all_modes(RasterSettings::default(), &[(48, 40)])
        .into_iter()
        .enumerate()
        .filter(|(i, _)| i % 3 == 0)
    {
        let s = RasterSettings {
            sigma: s.sigma.min(1e-4),
            antialias: false,
            ..s
        };
        let what = format!("one tile #{i}");
        let binned = check_binning(&r, &gpu, &what, &mesh, &[Camera::default()], &s, 8);
        let busy: Vec<usize> = (0..binned.ranges.len())
            .filter(|&t| binned.ranges[t][1] > binned.ranges[t][0])
            .collect();
        assert_eq!(busy, vec![2 * 6 + 2], "{what}: the tiles holding faces");
        assert_eq!(binned.total as usize, mesh.face_count(), "{what}");
        all.push(check(
            &r,
            &gpu,
            &what,
            &mesh,
            &Camera::default(),
            &lighting(),
            &s,
        ));
    }
    // A cluster of a few pixels: `report`'s coverage floor is for whole scenes; ask for some.
    let covered: usize = all.iter().map(|s| s.covered).sum();
    assert!(
        covered >= 4 * all.len(),
        "the cluster covers {covered} pixels"
    );
}

/// 12 000 faces over one tile: on llvmpipe the tiled forward's workgroup must widen past one
/// subgroup (at one subgroup a block, its invocation's loops would pass the driver's cap of
/// 65 535 iterations and quietly drop faces; `tiled_forward_workgroup`). Tiled equals brute
/// force bit for bit at every tile size, in a mode with colours and one without.
#[test]
fn a_crowded_tile_renders_every_face() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = cluster(12_000, (-0.315, 0.0), 0.3, 23);
    for rgb in [Rgb::Softmax, Rgb::Hard] {
        let s = RasterSettings {
            width: 48,
            height: 40,
            sigma: 1e-5,
            rgb,
            ..RasterSettings::default()
        };
        let frames = render_all(
            &r,
            &gpu,
            &format!("12 000 faces in one tile, {rgb:?}"),
            &mesh,
            &[Camera::default()],
            &lighting(),
            &s,
        );
        let covered = frames.images.iter().filter(|p| p[3] > 0.5).count();
        assert!(covered >= 4, "{rgb:?}: the cluster covers {covered} pixels");
    }
}

/// σ so large that every face covers every tile of a non-square image.
#[test]
fn huge_sigma_puts_every_face_in_every_tile() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = icosphere(1);
    let cam = Camera::from_angles(2.732, 15.0, 40.0);
    let mut all = Vec::new();
    for dist in [Dist::Euclidean, Dist::Barycentric] {
        for alpha in [Alpha::Prod, Alpha::Sum] {
            let s = RasterSettings {
                width: 40,
                height: 24,
                sigma: 5.0,
                gamma: 0.5,
                dist,
                alpha,
                ..RasterSettings::default()
            };
            let what = format!("huge σ {dist:?} {alpha:?}");
            for tile in TILES {
                let binned = check_binning(&r, &gpu, &what, &mesh, &[cam], &s, tile);
                if dist == Dist::Barycentric {
                    // Its reach scales with each face (SPEC: min w > -√T): not every tile.
                    continue;
                }
                let tiles = 40u32.div_ceil(tile) * 24u32.div_ceil(tile);
                assert_eq!(
                    binned.total as usize,
                    mesh.face_count() * tiles as usize,
                    "{what}: tile {tile}"
                );
            }
            all.push(check(&r, &gpu, &what, &mesh, &cam, &lighting(), &s));
        }
    }
    report("huge σ", &all);
}

/// The binning of the hand-made scene (border-crossing, behind the camera, beyond far, zero
/// area, back-facing) and of spot-like dense meshes equals its CPU twin, at every tile size and
/// on odd image shapes.
#[test]
fn binning_matches_its_cpu_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let cams = [
        Camera::default(),
        Camera::from_angles(2.0, 30.0, 150.0),
        Camera {
            projection: Projection::Orthographic { scale: 0.9 },
            ..Camera::default()
        },
    ];
    for (name, mesh) in [("triangles", triangles(1)), ("icosphere", icosphere(1))] {
        for (w, h) in [(1, 1), (37, 19), (8, 64), (33, 33)] {
            for dist in DISTS {
                for tile in TILES {
                    let s = RasterSettings {
                        width: w,
                        height: h,
                        sigma: 3e-3,
                        dist,
                        antialias: w == 37,
                        ..RasterSettings::default()
                    };
                    let what = format!("{name} {w}x{h} {dist:?} tile {tile}");
                    check_binning(&r, &gpu, &what, &mesh, &cams, &s, tile);
                }
            }
        }
    }
}

/// Views binned in groups under an entry budget (split and re-counted on demand) render the
/// same bits as one group and as brute force; a budget below one view's needs is a clear error.
#[test]
fn view_groups_split_under_an_entry_budget() {
    let Some(gpu) = common::gpu() else { return };
    let mesh = icosphere(1);
    let cams: Vec<Camera> = (0..5)
        .map(|i| Camera::from_angles(2.732, 10.0 * i as f64, 70.0 * i as f64))
        .collect();
    let s = RasterSettings {
        width: 32,
        height: 24,
        sigma: 1e-3,
        ..RasterSettings::default()
    };
    let r = Renderer::new(&gpu).unwrap();
    let want = render_all(&r, &gpu, "budget", &mesh, &cams, &lighting(), &s);
    let mut scene = r.prepare(&gpu, &mesh, &cams, &lighting(), &s).unwrap();
    let one_group = r
        .run(&gpu, &mut scene, Method::Tiled { tile: 8 })
        .unwrap()
        .binned()
        .entries();
    let budget = one_group / 3;
    let small = Renderer::new(&gpu).unwrap().with_entry_budget(budget);
    let mut scene = small.prepare(&gpu, &mesh, &cams, &lighting(), &s).unwrap();
    let split = small
        .run(&gpu, &mut scene, Method::Tiled { tile: 8 })
        .unwrap()
        .binned();
    assert!(split.groups().len() > 1, "{:?}", split.groups());
    assert_eq!(split.entries(), one_group, "every entry binned once");
    let got = scene.read_frames(&gpu).unwrap();
    assert!(bits(&got) == bits(&want), "split groups differ");

    let tiny = Renderer::new(&gpu).unwrap().with_entry_budget(10);
    let err = tiny
        .render_views(
            &gpu,
            &mesh,
            &cams,
            &lighting(),
            &s,
            Method::Tiled { tile: 8 },
        )
        .unwrap_err();
    assert!(matches!(err, softvk::Error::Limit(_)), "{err}");
    assert!(err.to_string().contains("entries"), "{err}");
}

#[test]
fn bad_tile_sizes_are_errors() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let s = RasterSettings {
        width: 8,
        height: 8,
        ..RasterSettings::default()
    };
    for tile in [0, 4, 12] {
        let err = r
            .render_views(
                &gpu,
                &Mesh::icosphere(0),
                &[Camera::default()],
                &Lighting::default(),
                &s,
                Method::Tiled { tile },
            )
            .unwrap_err();
        assert!(matches!(err, softvk::Error::Input(_)), "{tile}: {err}");
    }
}

/// SoftRas's `projection` camera: P = K [R | t] for the look-at view at (2.732, 20°, 35°), K
/// mapping to an `orig`-pixel image with the 30° perspective's focal length, and Brown
/// distortion `dist`. Without distortion it is (up to SoftRas's 1e-5 in the divide) the
/// perspective camera.
fn matrix_camera(orig: f64, dist: [f64; 5]) -> Camera {
    let cam = Camera::from_angles(2.732, 20.0, 35.0);
    let r = softvk::camera::look_at(cam.eye, DVec3::ZERO, DVec3::Y);
    let t: Vec<f64> = r
        .iter()
        .map(|row| -DVec3::from(*row).dot(cam.eye))
        .collect();
    let (c, f) = (orig / 2.0, orig / 2.0 / 30f64.to_radians().tan());
    let k = [[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]];
    let rt = [
        [r[0][0], r[0][1], r[0][2], t[0]],
        [r[1][0], r[1][1], r[1][2], t[1]],
        [r[2][0], r[2][1], r[2][2], t[2]],
    ];
    let mut p = [[0.0; 4]; 3];
    for i in 0..3 {
        for j in 0..4 {
            p[i][j] = (0..3).map(|m| k[i][m] * rt[m][j]).sum();
        }
    }
    Camera {
        projection: Projection::Matrix {
            p,
            dist_coeffs: dist,
            orig_size: orig,
        },
        ..cam
    }
}

/// The largest deviation (8.8e-5, lavapipe) is the γ = 1e-5 softmax: P's third row adds the
/// translation in f32, and one ulp of depth there is 5e-4 of exponent at 1 / (γ (far − near)).
#[test]
fn matrix_projection_with_distortion_matches_the_twin() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = icosphere(2);
    let mut all = Vec::new();
    // SoftRas distorts *pixel* coordinates (r ~ 40 here), so sensible coefficients are small.
    for (d, dist) in [[0.0; 5], [2e-5, -1e-9, 1e-4, -1e-4, 1e-13]]
        .into_iter()
        .enumerate()
    {
        let cam = matrix_camera(64.0, dist);
        for (i, s) in all_modes(RasterSettings::default(), &[(17, 17), (24, 16)])
            .into_iter()
            .enumerate()
            .filter(|(i, _)| i % 3 == d)
        {
            let st = check(
                &r,
                &gpu,
                &format!("matrix {dist:?} #{i}"),
                &mesh,
                &cam,
                &lighting(),
                &s,
            );
            all.push(st);
        }
    }
    report("matrix projection", &all);
}

/// Two meshes of equal topology (different positions and colours) and four views in one batch
/// render, bit for bit, what each mesh renders alone.
#[test]
fn a_batch_of_meshes_renders_as_each_mesh_alone() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let a = icosphere(2);
    let mut b = a.clone();
    let mut rng = common::rng(5);
    for p in &mut b.positions {
        let k = 1.0 + rng.random_range(-0.2f32..0.2);
        p.iter_mut().for_each(|c| *c *= k);
    }
    b.textures = random_colors(b.textures.len(), 31);
    b.vertex_colors = Some(random_colors(b.vertex_count(), 32));
    let cams = [
        Camera::from_angles(2.732, 0.0, 0.0),
        Camera::from_angles(2.5, 30.0, 100.0),
        Camera::from_angles(3.0, -10.0, 250.0),
    ];
    let views = [(0, cams[0]), (1, cams[0]), (1, cams[1]), (0, cams[2])];
    let meshes = [a, b];
    for color_mode in COLOR_MODES {
        let s = RasterSettings {
            width: 20,
            height: 14,
            sigma: 1e-3,
            color_mode,
            antialias: true,
            ..RasterSettings::default()
        };
        for method in [
            Method::Brute,
            Method::Tiled { tile: 8 },
            Method::Tiled { tile: 32 },
        ] {
            let mut scene = r
                .prepare_batch(&gpu, &meshes, &views, &lighting(), &s)
                .unwrap();
            r.run(&gpu, &mut scene, method).unwrap();
            let batch = scene.read_frames(&gpu).unwrap();
            for (v, (m, cam)) in views.iter().enumerate() {
                let alone = render_all(&r, &gpu, "alone", &meshes[*m], &[*cam], &lighting(), &s);
                let bits = |img: &[[f32; 4]]| -> Vec<u32> {
                    img.iter().flatten().map(|c| c.to_bits()).collect()
                };
                assert!(
                    bits(batch.image(v)) == bits(&alone.images),
                    "{color_mode:?} {method:?}: view {v} (mesh {m}) differs from the mesh alone"
                );
            }
        }
    }
    let mut other = meshes[0].clone();
    other.faces.swap(0, 1);
    let err = r
        .prepare_batch(
            &gpu,
            &[meshes[0].clone(), other],
            &views,
            &lighting(),
            &RasterSettings::default(),
        )
        .err()
        .unwrap();
    assert!(matches!(err, softvk::Error::Input(_)), "{err}");
    let err = r
        .prepare_batch(
            &gpu,
            &meshes,
            &[(2, cams[0])],
            &lighting(),
            &RasterSettings::default(),
        )
        .err()
        .unwrap();
    assert!(matches!(err, softvk::Error::Input(_)), "{err}");
}

/// A silhouette render (alpha only) has the alpha and the alpha aggregates of the full render
/// bit for bit, by brute force and tiled, in every distance and alpha mode; its RGB is the
/// background. (Breaking the early return in `shade_face` for alpha-only pipelines, or letting
/// it skip `alpha_add`, fails here.)
#[test]
fn silhouette_renders_have_the_full_renders_alpha() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let mesh = icosphere(2);
    let cams = [
        Camera::from_angles(2.5, 10.0, 60.0),
        Camera::from_angles(2.2, -20.0, 200.0),
    ];
    let mut checked = 0;
    for dist in DISTS {
        for alpha in ALPHAS {
            let s = RasterSettings {
                width: 24,
                height: 16,
                sigma: 3e-3,
                dist,
                alpha,
                rgb: if checked % 2 == 0 {
                    Rgb::Softmax
                } else {
                    Rgb::Hard
                },
                background: [0.25, 0.5, 0.75],
                antialias: checked % 3 == 0,
                ..RasterSettings::default()
            };
            for method in [Method::Brute, Method::Tiled { tile: 8 }] {
                let render = |silhouette: bool| {
                    let mut scene = r.prepare(&gpu, &mesh, &cams, &lighting(), &s).unwrap();
                    scene.set_silhouette_only(silhouette);
                    r.run(&gpu, &mut scene, method).unwrap();
                    scene.read_frames(&gpu).unwrap()
                };
                let (full, sil) = (render(false), render(true));
                let what = format!("{dist:?} {alpha:?} {method:?}");
                assert_eq!(full.images.len(), sil.images.len());
                for (a, b) in full.images.iter().zip(&sil.images) {
                    assert_eq!(a[3].to_bits(), b[3].to_bits(), "{what}");
                    let bg = s.background.map(|c| c as f32);
                    assert_eq!([b[0], b[1], b[2]], bg, "{what}");
                }
                for (a, b) in full.aux.iter().zip(&sil.aux) {
                    assert_eq!(a.alpha_acc.to_bits(), b.alpha_acc.to_bits(), "{what}");
                    assert_eq!(a.alpha_zeros, b.alpha_zeros, "{what}");
                }
                assert!(
                    full.images.iter().any(|p| p[3] > 0.0),
                    "{what}: nothing drawn"
                );
                checked += 1;
            }
        }
    }
    gpu.check_validation().unwrap();
}

/// Errors are matched by kind: a call out of order is `Misuse` (a caller's bug, apart from bad
/// input and device limits), and a buffer that holds too little for a call is `BufferTooSmall`,
/// naming the buffer and both sizes.
#[test]
fn misuse_and_small_buffers_are_matchable_errors() {
    use softvk::Error;
    use softvk::primitives::binning::{BinJob, Binner, Bins, ItemLayout};
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let s = RasterSettings {
        width: 16,
        height: 16,
        ..RasterSettings::default()
    };
    let mut scene = r
        .prepare(
            &gpu,
            &Mesh::icosphere(1),
            &[Camera::default()],
            &lighting(),
            &s,
        )
        .unwrap();
    // A scene forgets its run when it changes: nothing replays or differentiates a binning
    // made for other settings (a forward that never ran does not compile).
    assert!(scene.last_run().is_none());
    r.run(&gpu, &mut scene, Method::Tiled { tile: 8 }).unwrap();
    assert!(scene.last_run().is_some());
    scene.set_blur(2e-4, 1e-4).unwrap();
    assert!(scene.last_run().is_none());
    // Guarded bins are for the scene they were reserved for.
    let other = r
        .prepare(
            &gpu,
            &Mesh::icosphere(1),
            &[Camera::default(); 2],
            &lighting(),
            &s,
        )
        .unwrap();
    let bins = r.reserve_guarded(&gpu, &other, 8, 100).unwrap();
    let err = bins.binned(&scene).unwrap_err();
    assert!(matches!(err, Error::Input(_)), "{err}");

    // Binning into bins never reserved, and sorting before the count is read.
    let binner = Binner::new(&gpu).unwrap();
    let items = gpu.upload_buffer("boxes", &[0.0f32; 10]).unwrap();
    let job = |items_per_view| BinJob {
        grid: TileGrid::new(16, 16, 8).unwrap(),
        layout: ItemLayout {
            stride_words: 5,
            box_offset: 0,
            flag_offset: 4,
            flag_mask: 0,
        },
        items_per_view,
        views: 1,
        first_item: 0,
    };
    let mut bins = Bins::new(&gpu).unwrap();
    let err = gpu
        .submit_and_wait(|rec| binner.record_count(rec, &bins, items.whole(), &job(2)))
        .unwrap_err();
    assert!(matches!(err, Error::Misuse(_)), "{err}");
    bins.reserve(&gpu, &job(2)).unwrap();
    let err = gpu
        .submit_and_wait(|rec| binner.record_sort(rec, &bins, items.whole(), &job(2)))
        .unwrap_err();
    assert!(matches!(err, Error::Misuse(_)), "{err}");

    // Four items of five words in a buffer of two (whose size is rounded up to 64 bytes).
    bins.reserve(&gpu, &job(4)).unwrap();
    let err = gpu
        .submit_and_wait(|rec| binner.record_count(rec, &bins, items.whole(), &job(4)))
        .unwrap_err();
    match &err {
        Error::BufferTooSmall {
            buffer, have, need, ..
        } => assert_eq!(
            (buffer.as_str(), *have, *need),
            ("boxes", items.size(), 4 * 5 * 4)
        ),
        other => panic!("not BufferTooSmall: {other}"),
    }
    assert!(!err.to_string().contains('\n'));
    gpu.check_validation().unwrap();
}
