//! The f64 twin of PyTorch3D's `rasterize_meshes` (`softvk::raster::fragments`) against PyTorch3D
//! itself: golden files of its CPU rasterizer's fragments and gradients
//! (`tests/data/pytorch3d/*.npz`, made by `tests/data/pytorch3d/make_goldens.py`, PyTorch3D
//! 0.7.9; see the README there), one per scene: non-square images both ways, batches of meshes
//! of different sizes, culling, perspective-correct and clipped barycentrics (each alone and
//! both), K larger than the faces that reach a pixel, exactly equal depths (61 tied slot pairs),
//! faces skipped for zero area, a vertex behind the eye or a negative depth at a pixel; and
//! faces cut by PyTorch3D's near-plane clipping, halves of one face named as each other's
//! neighbours.
//!
//! PyTorch3D computes in f32 (its CPU kernels take float only), the twin in f64 from the same
//! f32 inputs. The random scenes were drawn clear of every decision f32 rounding could flip
//! (the script redraws one that is not), and the tied depths are exact in both, so
//! `pix_to_face` must be equal in every slot; the twin's `zbuf`, `bary_coords` and `dists`
//! within 1e-5 (measured: 2.8e-6 at most) and its vertex gradients within 1e-4 of each
//! component plus [`GRAD_FLOOR`] of the scene's largest. The kernels, f32 as PyTorch3D, must
//! give PyTorch3D's `zbuf`, `bary_coords` and `dists` bit for bit, and their vertex gradients
//! within [`KERNEL_GRAD_REL`] of each component plus [`KERNEL_GRAD_FLOOR`] of the largest.

mod common;

use std::path::{Path, PathBuf};

use softvk::raster::fragments::gpu::{FragmentPlan, FragmentRasterizer};
use softvk::raster::fragments::{self, FragmentSettings};
use softvk::recon::npz::{self, NpyArray, NpyData};

/// The golden files: the checkout's, or (a test binary moved to another machine, as
/// `.ci/gpu-check` moves them) `tests/data/pytorch3d` under the working directory.
fn golden_dir() -> PathBuf {
    let built = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/pytorch3d");
    if built.is_dir() {
        built
    } else {
        PathBuf::from("tests/data/pytorch3d")
    }
}

fn array(path: &Path, name: &str) -> NpyArray {
    npz::read_npz_array(path, name).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn floats(path: &Path, name: &str) -> Vec<f64> {
    match array(path, name).data {
        NpyData::F32(v) => v.into_iter().map(f64::from).collect(),
        NpyData::F64(v) => v,
        NpyData::I64(v) => v.into_iter().map(|x| x as f64).collect(),
        NpyData::I32(v) => v.into_iter().map(f64::from).collect(),
        NpyData::Bool(v) => v.into_iter().map(|x| f64::from(u8::from(x))).collect(),
        NpyData::U8(v) => v.into_iter().map(f64::from).collect(),
    }
}

fn ints(path: &Path, name: &str) -> Vec<i64> {
    floats(path, name).into_iter().map(|x| x as i64).collect()
}

fn flag(path: &Path, name: &str) -> bool {
    floats(path, name)[0] != 0.0
}

/// The kernels' vertex gradients against PyTorch3D's: each component within KERNEL_GRAD_REL of
/// itself plus KERNEL_GRAD_FLOOR of the scene's largest, about 3 times what the thirteen scenes
/// measure on lavapipe (7.6e-7 relative where |w| > 0.1 of the largest, 6.9e-8 of the largest
/// nearer zero: the f32 sums' rounding, PyTorch3D's and softvk's in their own orders).
const KERNEL_GRAD_REL: f64 = 2.4e-6;
const KERNEL_GRAD_FLOOR: f64 = 2.1e-7;

/// The f64 twin's bars (the twin is not f32: it differs from PyTorch3D's f32 sums by their
/// rounding alone). Components whose |PyTorch3D gradient| is below 0.1 of the scene's largest are held to this
/// fraction of the largest rather than to 1e-4 of themselves: PyTorch3D sums a vertex's terms
/// over pixels in f32, whose rounding where terms cancel is relative to the terms, not to the
/// sum. Measured over the twelve scenes: the worst component uses 3 % of these bars.
const GRAD_FLOOR: f64 = 1e-5;

struct Scene {
    name: String,
    /// PyTorch3D's `clipped_faces_neighbor_idx` (the near-plane scene's cut faces).
    neighbors: Option<Vec<i64>>,
    face_verts: Vec<[[f64; 3]; 3]>,
    faces: Vec<[usize; 3]>,
    vertex_count: usize,
    meshes: Vec<(usize, usize)>,
    settings: FragmentSettings,
}

fn scene(path: &Path) -> Scene {
    let verts = floats(path, "verts_packed");
    let faces: Vec<[usize; 3]> = ints(path, "faces_packed")
        .chunks_exact(3)
        .map(|f| [f[0] as usize, f[1] as usize, f[2] as usize])
        .collect();
    let vertex = |i: usize| [verts[3 * i], verts[3 * i + 1], verts[3 * i + 2]];
    let face_verts = faces.iter().map(|f| f.map(vertex)).collect();
    let first = ints(path, "mesh_to_face_first_idx");
    let count = ints(path, "num_faces_per_mesh");
    let size = ints(path, "image_size");
    Scene {
        name: path.file_stem().unwrap().to_string_lossy().into_owned(),
        neighbors: npz::read_npz_array(path, "clipped_faces_neighbor_idx")
            .ok()
            .map(|_| ints(path, "clipped_faces_neighbor_idx")),
        face_verts,
        faces,
        vertex_count: verts.len() / 3,
        meshes: first
            .iter()
            .zip(&count)
            .map(|(&f, &c)| (f as usize, c as usize))
            .collect(),
        settings: FragmentSettings {
            width: size[1] as u32,
            height: size[0] as u32,
            blur_radius: floats(path, "blur_radius")[0],
            faces_per_pixel: ints(path, "faces_per_pixel")[0] as usize,
            perspective_correct: flag(path, "perspective_correct"),
            clip_barycentric_coords: flag(path, "clip_barycentric_coords"),
            cull_backfaces: flag(path, "cull_backfaces"),
        },
    }
}

fn goldens() -> Vec<PathBuf> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(golden_dir())
        .expect("tests/data/pytorch3d holds the golden files")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "npz"))
        .collect();
    paths.sort();
    assert!(paths.len() >= 8, "golden files missing: {paths:?}");
    paths
}

#[test]
fn the_twin_gives_pytorch3d_fragments_on_every_golden_scene() {
    for path in goldens() {
        let s = scene(&path);
        let out = fragments::rasterize(
            &s.face_verts,
            &s.meshes,
            s.neighbors.as_deref(),
            &s.settings,
        );
        let want_faces = ints(&path, "pix_to_face");
        if s.neighbors.is_some() {
            // The near-plane scene: values are not comparable (see `f32_bound_scene`), and
            // f32 rounding reorders a few near-equal depths; the selection, cut faces' rule
            // included, must be PyTorch3D's elsewhere (measured: 8 of 614 filled slots differ).
            assert!(f32_bound_scene(&s));
            let differ = (0..want_faces.len())
                .filter(|&i| out.pix_to_face[i] != want_faces[i])
                .count();
            let filled = want_faces.iter().filter(|&&f| f >= 0).count();
            eprintln!("{}: {differ} of {filled} slots differ", s.name);
            assert!(
                differ * 50 <= filled,
                "{}: {differ} of {filled} slots differ",
                s.name
            );
            continue;
        }
        let want_z = floats(&path, "zbuf");
        let want_bary = floats(&path, "bary_coords");
        let want_dists = floats(&path, "dists");
        assert_eq!(out.pix_to_face.len(), want_faces.len(), "{}", s.name);
        // A slot whose face differs is a near-tie (counted); its values are not comparable.
        let mut differ = 0;
        let mut slots_with_faces = 0;
        for i in 0..want_faces.len() {
            if want_faces[i] >= 0 {
                slots_with_faces += 1;
            }
            if out.pix_to_face[i] != want_faces[i] {
                differ += 1;
                continue;
            }
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-5;
            assert!(close(out.zbuf[i], want_z[i]), "{} slot {i}: zbuf", s.name);
            assert!(
                close(out.dists[i], want_dists[i]),
                "{} slot {i}: dists",
                s.name
            );
            for c in 0..3 {
                let (got, want) = (out.bary_coords[i][c], want_bary[3 * i + c]);
                assert!(close(got, want), "{} slot {i}: bary {got} {want}", s.name);
            }
        }
        assert!(slots_with_faces > 0, "{}: no fragments", s.name);
        assert_eq!(differ, 0, "{}: {differ} slots hold another face", s.name);
    }
}

/// Whether PyTorch3D's own f32 values on the scene are too far from exact for the f64 twin to be
/// held to them: the near-plane scene, whose faces cut at z = 0.5 project to large NDC
/// coordinates and slivers, where f32 loses digits (measured: a barycentric 2.4e-5 from the
/// twin's, a vertex gradient −1 654 against −12.5 among components up to 3.9e4). The kernels,
/// PyTorch3D's arithmetic in f32 operation for operation, are held to it there as everywhere.
fn f32_bound_scene(s: &Scene) -> bool {
    s.neighbors.is_some()
}

#[test]
fn the_twins_backward_gives_pytorch3d_gradients_on_every_golden_scene() {
    for path in goldens() {
        let s = scene(&path);
        if f32_bound_scene(&s) {
            continue;
        }
        let pix_to_face = ints(&path, "pix_to_face");
        let grad_zbuf = floats(&path, "grad_zbuf");
        let grad_dists = floats(&path, "grad_dists");
        let grad_bary: Vec<[f64; 3]> = floats(&path, "grad_bary")
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let per_face = fragments::rasterize_grad(
            &s.face_verts,
            &pix_to_face,
            &grad_zbuf,
            &grad_bary,
            &grad_dists,
            &s.settings,
        );
        // Face corners to packed vertices, in face order.
        let mut got = vec![[0.0f64; 3]; s.vertex_count];
        for (f, corners) in s.faces.iter().enumerate() {
            for (c, &v) in corners.iter().enumerate() {
                for a in 0..3 {
                    got[v][a] += per_face[f][c][a];
                }
            }
        }
        let want = floats(&path, "grad_verts");
        let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0, "{}: no gradient", s.name);
        for (i, w) in want.iter().enumerate() {
            let g = got[i / 3][i % 3];
            assert!(
                (g - w).abs() <= 1e-4 * w.abs() + GRAD_FLOOR * scale,
                "{} vertex {} axis {}: {g} against PyTorch3D's {w} (largest {scale})",
                s.name,
                i / 3,
                i % 3
            );
        }
    }
}

/// The scene's faces as the kernels take them: nine f32 per face.
fn face_floats(face_verts: &[[[f64; 3]; 3]]) -> Vec<f32> {
    face_verts
        .iter()
        .flatten()
        .flatten()
        .map(|&x| x as f32)
        .collect()
}

/// Vertex gradients from per-face corner gradients (nine per face), in face order.
fn vertex_grads(s: &Scene, per_face: impl Fn(usize, usize, usize) -> f64) -> Vec<[f64; 3]> {
    let mut got = vec![[0.0f64; 3]; s.vertex_count];
    for (f, corners) in s.faces.iter().enumerate() {
        for (c, &v) in corners.iter().enumerate() {
            for (a, g) in got[v].iter_mut().enumerate() {
                *g += per_face(f, c, a);
            }
        }
    }
    got
}

#[test]
fn the_kernels_give_pytorch3d_fragments_and_gradients_on_every_golden_scene() {
    let Some(ctx) = common::gpu() else { return };
    let mut raster = FragmentRasterizer::new(&ctx).unwrap();
    let (mut worst_value, mut worst_grad) = (0.0f64, 0.0f64);
    let (mut differ_bits, mut worst_rel, mut worst_floor) = (0usize, 0.0f64, 0.0f64);
    for path in goldens() {
        let s = scene(&path);
        let plan = FragmentPlan::new(&ctx, s.face_verts.len(), &s.meshes, &s.settings).unwrap();
        let faces = face_floats(&s.face_verts);
        let out = raster
            .rasterize(&ctx, &plan, &faces, s.neighbors.as_deref())
            .unwrap();
        let want_faces = ints(&path, "pix_to_face");
        assert_eq!(out.pix_to_face, want_faces, "{}: pix_to_face", s.name);
        for (name, got, want) in [
            ("zbuf", &out.zbuf, floats(&path, "zbuf")),
            ("dists", &out.dists, floats(&path, "dists")),
            (
                "bary_coords",
                &out.bary_coords,
                floats(&path, "bary_coords"),
            ),
        ] {
            // PyTorch3D's outputs are f32: the same bits (README's claim), both NaN-free.
            for (i, (&g, &w)) in got.iter().zip(&want).enumerate() {
                let w32 = w as f32;
                if g.to_bits() != w32.to_bits() {
                    differ_bits += 1;
                    worst_value = worst_value.max((f64::from(g) - w).abs());
                    eprintln!("{} {name}[{i}]: {g:e} against PyTorch3D's {w32:e}", s.name);
                }
            }
        }
        let as_f32 = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect::<Vec<f32>>();
        let mut grad = vec![0.0f32; faces.len()];
        raster
            .rasterize_grad_into(
                &ctx,
                &plan,
                &faces,
                &out.pix_to_face,
                &as_f32(floats(&path, "grad_zbuf")),
                &as_f32(floats(&path, "grad_bary")),
                &as_f32(floats(&path, "grad_dists")),
                &mut grad,
            )
            .unwrap();
        let got = vertex_grads(&s, |f, c, a| f64::from(grad[9 * f + 3 * c + a]));
        let want = floats(&path, "grad_verts");
        let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (i, w) in want.iter().enumerate() {
            let g = got[i / 3][i % 3];
            let bar = KERNEL_GRAD_REL * w.abs() + KERNEL_GRAD_FLOOR * scale;
            worst_grad = worst_grad.max((g - w).abs() / bar);
            if w.abs() > 0.1 * scale {
                worst_rel = worst_rel.max((g - w).abs() / w.abs());
            } else {
                worst_floor = worst_floor.max((g - w).abs() / scale);
            }
            assert!(
                (g - w).abs() <= bar,
                "{} vertex {} axis {}: {g} against PyTorch3D's {w} (largest {scale})",
                s.name,
                i / 3,
                i % 3
            );
        }
    }
    eprintln!(
        "kernels against PyTorch3D: {differ_bits} values differ in their bits (worst {worst_value:.2e}), \
         gradients use {:.1} % of their bars; relative {worst_rel:.2e} (|w| > 0.1 of the largest), \
         near zero {worst_floor:.2e} of the largest",
        100.0 * worst_grad
    );
    assert_eq!(
        differ_bits, 0,
        "zbuf, dists and bary_coords are PyTorch3D's bits"
    );
}

/// Face vertices, meshes `(first, count)` and neighbours.
type CrowdedScene = (Vec<[[f64; 3]; 3]>, Vec<(usize, usize)>, Vec<i64>);

/// A crowded random scene: `faces` faces in two meshes of different sizes, small and large,
/// overlapping in depth, some of them halves of faces cut by the near plane (neighbours). The
/// faces are near-equilateral: beside a sliver, within the blur radius, barycentrics and the
/// perspective correction's denominator are ill-conditioned enough that f32 and f64 part ways
/// (PyTorch3D's own f32 as much as the kernels').
fn crowded_scene(faces: usize, seed: u64) -> CrowdedScene {
    use rand::RngExt;
    let mut rng = common::rng(seed);
    let mut fv = Vec::with_capacity(faces);
    for i in 0..faces {
        let size: f64 = if i % 7 == 0 { 0.8 } else { 0.15 };
        let c = [rng.random_range(-1.1..1.1), rng.random_range(-0.9..0.9)];
        let z0: f64 = rng.random_range(0.5..3.0);
        let turn: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        let face = [0.0, 1.0, 2.0].map(|k: f64| {
            let a = turn + k * std::f64::consts::TAU / 3.0 + rng.random_range(-0.3..0.3);
            let r = size * rng.random_range(0.8..1.2);
            // Grid-exact coordinates: f32 inputs, the same in the twin and the kernels.
            [
                c[0] + r * a.cos(),
                c[1] + r * a.sin(),
                z0 + rng.random_range(-0.2..0.2),
            ]
            .map(|x: f64| f64::from(x as f32))
        });
        // Both windings, for the culled modes.
        fv.push(if i % 2 == 0 {
            face
        } else {
            [face[0], face[2], face[1]]
        });
    }
    let split = faces / 3;
    let meshes = vec![(0, split), (split, faces - split)];
    // Pairs of consecutive faces in the second mesh named as each other's other half.
    let mut neighbors = vec![-1i64; faces];
    for f in (split..faces - 1).step_by(5) {
        neighbors[f] = f as i64 + 1;
        neighbors[f + 1] = f as i64;
    }
    (fv, meshes, neighbors)
}

#[test]
fn the_kernels_match_the_twin_on_a_crowded_batch_in_every_mode() {
    let Some(ctx) = common::gpu() else { return };
    let mut raster = FragmentRasterizer::new(&ctx).unwrap();
    let (fv, meshes, neighbors) = crowded_scene(600, 3);
    let faces = face_floats(&fv);
    for (i, (perspective_correct, clip_barycentric_coords, cull_backfaces)) in [
        (false, false, false),
        (true, true, false),
        (false, true, true),
        (true, false, true),
    ]
    .into_iter()
    .enumerate()
    {
        let settings = FragmentSettings {
            width: 37,
            height: 29,
            blur_radius: if i % 2 == 0 { 0.0 } else { 4e-3 },
            faces_per_pixel: [1, 7, 24, 64][i],
            perspective_correct,
            clip_barycentric_coords,
            cull_backfaces,
        };
        let plan = FragmentPlan::new(&ctx, fv.len(), &meshes, &settings).unwrap();
        let out = raster
            .rasterize(&ctx, &plan, &faces, Some(&neighbors))
            .unwrap();
        let twin = fragments::rasterize(&fv, &meshes, Some(&neighbors), &settings);
        // f32 against f64: a slot may differ only where two depths are within f32 rounding,
        // counted; every slot whose face agrees must agree in value.
        let mut differ = 0usize;
        let mut filled = 0usize;
        for s in 0..twin.pix_to_face.len() {
            filled += usize::from(twin.pix_to_face[s] >= 0);
            if out.pix_to_face[s] != twin.pix_to_face[s] {
                differ += 1;
                continue;
            }
            if twin.pix_to_face[s] < 0 {
                continue;
            }
            let z = f64::from(out.zbuf[s]);
            assert!((z - twin.zbuf[s]).abs() <= 1e-5 * twin.zbuf[s].abs().max(1.0));
            assert!((f64::from(out.dists[s]) - twin.dists[s]).abs() <= 1e-5);
            for c in 0..3 {
                let b = f64::from(out.bary_coords[3 * s + c]);
                assert!(
                    (b - twin.bary_coords[s][c]).abs() <= 2e-4,
                    "mode {i} slot {s}: bary {b} {}",
                    twin.bary_coords[s][c]
                );
            }
        }
        assert!(filled > 1000, "mode {i}: only {filled} slots filled");
        assert!(
            differ * 2000 <= filled,
            "mode {i}: {differ} of {filled} slots hold another face than the twin's"
        );
        // The same bits on a second run.
        let again = raster
            .rasterize(&ctx, &plan, &faces, Some(&neighbors))
            .unwrap();
        assert_eq!(again, out, "mode {i}: a second run differs");

        // The backward against the twin's, on the kernels' own selection.
        let n = out.pix_to_face.len();
        let weight = |s: usize, c: usize| ((s * 7 + c * 3) % 11) as f32 / 11.0 - 0.45;
        let gz: Vec<f32> = (0..n).map(|s| weight(s, 0)).collect();
        let gd: Vec<f32> = (0..n).map(|s| weight(s, 4)).collect();
        let gb: Vec<f32> = (0..3 * n).map(|s| weight(s / 3, 1 + s % 3)).collect();
        let mut grad = vec![0.0f32; faces.len()];
        raster
            .rasterize_grad_into(
                &ctx,
                &plan,
                &faces,
                &out.pix_to_face,
                &gz,
                &gb,
                &gd,
                &mut grad,
            )
            .unwrap();
        let wide = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
        let gb3: Vec<[f64; 3]> = wide(&gb)
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let want = fragments::rasterize_grad(
            &fv,
            &out.pix_to_face,
            &wide(&gz),
            &gb3,
            &wide(&gd),
            &settings,
        );
        let scale = want
            .iter()
            .flatten()
            .flatten()
            .fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0);
        for f in 0..fv.len() {
            for c in 0..3 {
                for a in 0..3 {
                    let (g, w) = (f64::from(grad[9 * f + 3 * c + a]), want[f][c][a]);
                    assert!(
                        (g - w).abs() <= 1e-4 * w.abs() + 1e-5 * scale,
                        "mode {i} face {f} corner {c} axis {a}: {g} against the twin's {w}"
                    );
                }
            }
        }
        let mut again = vec![0.0f32; faces.len()];
        raster
            .rasterize_grad_into(
                &ctx,
                &plan,
                &faces,
                &out.pix_to_face,
                &gz,
                &gb,
                &gd,
                &mut again,
            )
            .unwrap();
        assert!(
            grad.iter()
                .zip(&again)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "mode {i}: the backward differs between runs"
        );
    }
}

#[test]
fn a_tile_crowded_past_the_drivers_loop_cap_folds_into_passes_with_the_same_result() {
    let Some(ctx) = common::gpu() else { return };
    let mut raster = FragmentRasterizer::new(&ctx).unwrap();
    // 1 500 faces over the whole image: every tile's run holds all of them, farthest first, so
    // that each face moves every entry of a full list (the worst case the passes are sized
    // for: 150 000 loop iterations in one pass).
    use rand::RngExt;
    let mut rng = common::rng(11);
    let mut fv: Vec<[[f64; 3]; 3]> = (0..1500)
        .map(|_| {
            let turn: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let z0: f64 = rng.random_range(1.0..3.0);
            [0.0, 1.0, 2.0].map(|k: f64| {
                let a = turn + k * std::f64::consts::TAU / 3.0;
                [
                    5.0 * a.cos(),
                    5.0 * a.sin(),
                    z0 + rng.random_range(-0.1..0.1),
                ]
                .map(|x: f64| f64::from(x as f32))
            })
        })
        .collect();
    fv.sort_by(|a, b| {
        let z = |f: &[[f64; 3]; 3]| f[0][2] + f[1][2] + f[2][2];
        z(b).total_cmp(&z(a))
    });
    let meshes = [(0, fv.len())];
    let settings = FragmentSettings {
        width: 16,
        height: 12,
        blur_radius: 0.0,
        faces_per_pixel: 100,
        perspective_correct: true,
        clip_barycentric_coords: false,
        cull_backfaces: false,
    };
    let plan = FragmentPlan::new(&ctx, fv.len(), &meshes, &settings).unwrap();
    let passes = FragmentRasterizer::forward_passes(&plan, fv.len() as u64);
    if ctx.info().shader_loop_limit().is_some() {
        assert!(
            passes >= 4,
            "{passes} passes: the test does not cross the cap"
        );
    }
    let faces = face_floats(&fv);
    let out = raster.rasterize(&ctx, &plan, &faces, None).unwrap();
    let twin = fragments::rasterize(&fv, &meshes, None, &settings);
    let differ = (0..twin.pix_to_face.len())
        .filter(|&s| out.pix_to_face[s] != twin.pix_to_face[s])
        .count();
    let filled = twin.pix_to_face.iter().filter(|&&f| f >= 0).count();
    assert_eq!(
        filled,
        twin.pix_to_face.len(),
        "every slot of every pixel is filled"
    );
    assert!(
        differ * 2000 <= filled,
        "{differ} of {filled} slots differ from the twin"
    );
}

/// FNV-1a over bytes: a test's fingerprint of outputs, not a cryptographic hash (no hashing
/// crate is a dependency; 64 bits tell apart any two runs that differ).
fn fingerprint(parts: &[&[u8]]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for part in parts {
        for &b in *part {
            h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// The fragments and gradients of a crowded batch, as bytes, are the same under every subgroup
/// width and workgroup shape CI runs the kernel tests with (llvmpipe's 4, 8 and 16 lanes, GPU
/// workgroup shapes): the forward's lists are ordered by (z, face) whatever order faces arrive
/// in, and each gradient is summed by one invocation in slot order.
#[test]
fn the_fragments_and_gradients_are_the_same_bytes_on_every_lane_width() {
    let Some(ctx) = common::gpu() else { return };
    let mut raster = FragmentRasterizer::new(&ctx).unwrap();
    let (fv, meshes, neighbors) = crowded_scene(600, 3);
    let faces = face_floats(&fv);
    let settings = FragmentSettings {
        width: 37,
        height: 29,
        blur_radius: 4e-3,
        faces_per_pixel: 7,
        perspective_correct: true,
        clip_barycentric_coords: true,
        cull_backfaces: false,
    };
    let plan = FragmentPlan::new(&ctx, fv.len(), &meshes, &settings).unwrap();
    let out = raster
        .rasterize(&ctx, &plan, &faces, Some(&neighbors))
        .unwrap();
    let n = out.pix_to_face.len();
    let gz: Vec<f32> = (0..n).map(|s| (s % 13) as f32 / 13.0 - 0.4).collect();
    let gb: Vec<f32> = (0..3 * n).map(|s| (s % 7) as f32 / 7.0 - 0.5).collect();
    let mut grad = vec![0.0f32; faces.len()];
    raster
        .rasterize_grad_into(
            &ctx,
            &plan,
            &faces,
            &out.pix_to_face,
            &gz,
            &gb,
            &gz,
            &mut grad,
        )
        .unwrap();
    let bytes = |v: &[f32]| bytemuck::cast_slice::<f32, u8>(v).to_vec();
    let got = fingerprint(&[
        bytemuck::cast_slice(&out.pix_to_face),
        &bytes(&out.zbuf),
        &bytes(&out.dists),
        &bytes(&out.bary_coords),
        &bytes(&grad),
    ]);
    assert_eq!(got, 0x3e63_ef68_70e5_79c5, "fingerprint {got:#018x}");
}
