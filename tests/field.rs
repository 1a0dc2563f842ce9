//! The implicit fields against their f64 twins on lavapipe with validation on: eval, backward
//! (GPU vs twin, twin vs central finite differences), bit-identical repeats, an Adam fit of a grid
//! to a sphere; marching cubes (GPU vs twin, closed, volume); voxelization, field occupancy,
//! visual hull and IoU; the shaded preview's silhouette.
//!
//! **Tolerances.** φ of the grid: 1e-5 abs (f32 trilinear of f32 logits). φ of the MLP: 1e-4 abs
//! (the encoding's sin(2^k π u) of an f32 u carries an error of 2^k π · 6e-8). Gradients: 1e-3 of
//! the largest component (sums of up to 70 000 f32 terms). The twin's gradient against central
//! differences (step 1e-6): 1e-5 relative on every component above 1e-3 of the largest.

mod common;

use softvk::camera::Camera;
use softvk::field::mcubes::{self, MarchingCubes};
use softvk::field::preview::{PreviewOptions, pixel_ray, render_preview};
use softvk::field::voxel::{self, Occupancy};
use softvk::field::{Cube, Field, FieldKind, Shape, cpu};
use softvk::fit::{Adam, AdamOptions};
use softvk::gpu::{Context, MemoryKind};
use softvk::mesh::Mesh;
use softvk::{Error, LimitKind};

use rand::RngExt;

fn cube() -> Cube {
    Cube::new([0.1, -0.2, 0.05], 0.8).unwrap()
}

fn small_mlp() -> FieldKind {
    FieldKind::Mlp {
        hidden_layers: 2,
        width: 16,
        frequencies: 4,
    }
}

fn shapes() -> Vec<FieldKind> {
    let sharpness = 12.0;
    [
        Shape::Sphere {
            center: [0.15, -0.1, 0.0],
            radius: 0.45,
        },
        Shape::Box {
            center: [0.0, -0.25, 0.1],
            half_extents: [0.3, 0.4, 0.2],
        },
        Shape::Torus {
            center: [0.05, -0.2, 0.1],
            major: 0.4,
            minor: 0.15,
        },
    ]
    .into_iter()
    .map(|shape| FieldKind::Analytic { shape, sharpness })
    .collect()
}

/// Random points in the cube grown by 20 % (some outside: the grid clamps them).
fn random_points(rng: &mut rand_pcg::Pcg64, n: usize, cube: &Cube) -> Vec<[f32; 4]> {
    (0..n)
        .map(|_| {
            let p: [f64; 3] = std::array::from_fn(|k| {
                cube.center[k] + 1.2 * cube.half * rng.random_range(-1.0..1.0)
            });
            [p[0] as f32, p[1] as f32, p[2] as f32, 1.0]
        })
        .collect()
}

fn xyz(p: &[f32; 4]) -> [f64; 3] {
    [p[0], p[1], p[2]].map(f64::from)
}

fn widen(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x)).collect()
}

/// A field whose parameters are away from the initial φ ≈ 0.5, so that eval and backward are
/// tested on a field with structure: the grid gets random logits in ±4, the MLP its seeded init
/// with the output layer ×100.
fn field_with_structure(ctx: &Context, kind: FieldKind, seed: u64) -> (Field, Vec<f32>) {
    let field = Field::new(ctx, kind, cube(), seed).unwrap();
    let mut params = field.read_params(ctx).unwrap();
    assert_eq!(params, kind.initial_params(seed));
    let mut rng = common::rng(seed);
    match kind {
        FieldKind::Grid { .. } => {
            for p in &mut params {
                *p = rng.random_range(-4.0..4.0);
            }
        }
        FieldKind::Mlp { .. } => {
            let layout = kind.mlp_layout().unwrap();
            let (offset, _, _) = layout.layer(layout.hidden_layers as usize);
            for p in &mut params[offset..] {
                *p *= 100.0;
            }
        }
        FieldKind::Analytic { .. } => {}
    }
    field.set_params(ctx, &params).unwrap();
    (field, params)
}

fn assert_phi_close(what: &str, gpu: &[f32], twin: &[f64], tol: f64) {
    let (worst, at) = gpu
        .iter()
        .zip(twin)
        .map(|(&g, &t)| (f64::from(g) - t).abs())
        .enumerate()
        .fold(
            (0.0, 0),
            |(w, wi), (i, e)| if e > w { (e, i) } else { (w, wi) },
        );
    eprintln!("{what}: worst |φ_gpu − φ_twin| = {worst:.2e}");
    assert!(
        worst <= tol,
        "{what}: point {at}: GPU {} vs twin {}",
        gpu[at],
        twin[at]
    );
    // The field must not be flat, or the comparison checks little.
    let spread = twin.iter().fold(0.0f64, |m, &t| m.max((t - 0.5).abs()));
    assert!(spread > 0.2, "{what}: φ stays within {spread} of 0.5");
}

/// Worst |gpu − twin| / max |twin|; fails above `rel`.
fn assert_grad_close(what: &str, gpu: &[f32], twin: &[f64], rel: f64) {
    assert_eq!(gpu.len(), twin.len(), "{what}: lengths");
    let scale = twin.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0, "{what}: a zero gradient checks nothing");
    let (worst, at) = gpu
        .iter()
        .zip(twin)
        .map(|(&g, &t)| (f64::from(g) - t).abs())
        .enumerate()
        .fold(
            (0.0, 0),
            |(w, wi), (i, e)| if e > w { (e, i) } else { (w, wi) },
        );
    eprintln!(
        "{what}: worst error {:.2e} of the largest component",
        worst / scale
    );
    assert!(
        worst <= rel * scale,
        "{what}: parameter {at}: GPU {} vs twin {} (scale {scale:e})",
        gpu[at],
        twin[at]
    );
}

#[test]
fn grid_eval_matches_the_twin_inside_and_outside_the_cube() {
    let Some(ctx) = common::gpu() else { return };
    eval_matches_the_twin(&ctx, FieldKind::Grid { res: 5 }, 1, 2, 4000, 1e-5);
}

/// φ of a `kind` field with structure (seed `seed`) at `n` random points (seed `points_seed`)
/// against the twin, within `tol`.
fn eval_matches_the_twin(
    ctx: &Context,
    kind: FieldKind,
    seed: u64,
    points_seed: u64,
    n: usize,
    tol: f64,
) {
    let (field, params) = field_with_structure(ctx, kind, seed);
    let points = random_points(&mut common::rng(points_seed), n, &cube());
    let phi = field.eval(ctx, &points).unwrap();
    let twin: Vec<f64> = points
        .iter()
        .map(|p| cpu::eval(&kind, &cube(), &widen(&params), xyz(p)))
        .collect();
    assert_phi_close(&format!("{kind:?}"), &phi, &twin, tol);
}

#[test]
fn mlp_eval_matches_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    // Unrolled evaluation (`mlp::UNROLL_WEIGHTS`) with an even and an odd layer count (the
    // activations ping-pong between two halves), and the looped one (64 units).
    let unrolled_odd = FieldKind::Mlp {
        hidden_layers: 3,
        width: 32,
        frequencies: 3,
    };
    let looped = FieldKind::Mlp {
        hidden_layers: 3,
        width: 64,
        frequencies: 2,
    };
    for (k, kind) in [small_mlp(), unrolled_odd, looped].into_iter().enumerate() {
        eval_matches_the_twin(&ctx, kind, 3 + k as u64, 4, 2000, 1e-4);
    }
}

#[test]
fn mlp_initial_field_is_near_one_half() {
    let kind = FieldKind::Mlp {
        hidden_layers: 4,
        width: 64,
        frequencies: 6,
    };
    let params = widen(&kind.initial_params(7));
    let points = random_points(&mut common::rng(8), 500, &cube());
    let worst = points
        .iter()
        .map(|p| (cpu::eval(&kind, &cube(), &params, xyz(p)) - 0.5).abs())
        .fold(0.0f64, f64::max);
    eprintln!("initial MLP: max |φ − 0.5| = {worst:.3e}");
    assert!(worst < 0.05 && worst > 0.0);
    assert_ne!(
        kind.initial_params(7),
        kind.initial_params(8),
        "the seed matters"
    );
}

#[test]
fn analytic_eval_matches_the_twin_and_is_one_half_on_the_surface() {
    let Some(ctx) = common::gpu() else { return };
    for kind in shapes() {
        let field = Field::new(&ctx, kind, cube(), 0).unwrap();
        let params = widen(&field.read_params(&ctx).unwrap());
        let points = random_points(&mut common::rng(5), 2000, &cube());
        let phi = field.eval(&ctx, &points).unwrap();
        let twin: Vec<f64> = points
            .iter()
            .map(|p| cpu::eval(&kind, &cube(), &params, xyz(p)))
            .collect();
        assert_phi_close(&format!("{kind:?}"), &phi, &twin, 2e-6);
    }
    // On the surface: a sphere's φ is 0.5 at distance r from the centre.
    let [sphere, ..] = shapes()[..] else {
        unreachable!()
    };
    let FieldKind::Analytic {
        shape: Shape::Sphere { center, radius },
        ..
    } = sphere
    else {
        unreachable!()
    };
    let p = [center[0] + radius, center[1], center[2]];
    let params = Shape::Sphere { center, radius }.params();
    assert!((cpu::eval(&sphere, &cube(), &params, p) - 0.5).abs() < 1e-12);
}

fn check_backward(ctx: &Context, kind: FieldKind, n: usize, seed: u64) {
    let (field, params) = field_with_structure(ctx, kind, seed);
    let mut rng = common::rng(seed + 100);
    let points = random_points(&mut rng, n, &cube());
    let d_phi: Vec<f32> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let grad = field.backward(ctx, &points, &d_phi).unwrap();
    let pts: Vec<[f64; 3]> = points.iter().map(xyz).collect();
    let twin = cpu::backward(&kind, &cube(), &widen(&params), &pts, &widen(&d_phi));
    assert_grad_close(
        &format!("{kind:?} backward of {n} points"),
        &grad,
        &twin,
        1e-3,
    );
    // Bit-identical on a second run.
    let again = field.backward(ctx, &points, &d_phi).unwrap();
    assert!(
        grad.iter()
            .zip(&again)
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "{kind:?}: a repeated backward differs"
    );
}

#[test]
fn grid_backward_matches_the_twin_over_several_batches_and_is_repeatable() {
    let Some(ctx) = common::gpu() else { return };
    // 70 000 points: two batches of the sort; res 4 puts ~2 600 points in each of 27 cells, so a
    // cell spans many chunks. A finer grid with fewer points leaves most cells empty.
    check_backward(&ctx, FieldKind::Grid { res: 4 }, 70_000, 11);
    check_backward(&ctx, FieldKind::Grid { res: 17 }, 3_000, 12);
    check_backward(&ctx, FieldKind::Grid { res: 2 }, 1_000, 14);
}

#[test]
fn mlp_backward_matches_the_twin_over_several_batches_and_is_repeatable() {
    let Some(ctx) = common::gpu() else { return };
    // 20 000 points: more than one backward batch (16 384 points for this network).
    check_backward(&ctx, small_mlp(), 20_000, 13);
    // Shapes that leave partial tiles everywhere in the backward's kernels (units in tiles of 8,
    // points of 4, inputs + bias columns of 8, chunks of 256), unrolled (width 13) and looped
    // (width 37).
    let mlp = |hidden_layers, width, frequencies| FieldKind::Mlp {
        hidden_layers,
        width,
        frequencies,
    };
    check_backward(&ctx, mlp(3, 13, 1), 1_023, 15);
    check_backward(&ctx, mlp(2, 37, 3), 2_001, 16);
}

#[test]
fn analytic_backward_matches_the_twin_and_is_repeatable() {
    let Some(ctx) = common::gpu() else { return };
    for (k, kind) in shapes().into_iter().enumerate() {
        check_backward(&ctx, kind, 5_000, 20 + k as u64);
    }
}

/// The twin's backward of `L = Σ d_phi_i φ(p_i)` against central differences of the twin's eval.
fn check_twin_fd(kind: FieldKind, params: &[f64], n: usize, seed: u64) {
    let mut rng = common::rng(seed);
    let pts: Vec<[f64; 3]> = random_points(&mut rng, n, &cube())
        .iter()
        .map(xyz)
        .collect();
    let d_phi: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let loss = |q: &[f64]| -> f64 {
        pts.iter()
            .zip(&d_phi)
            .map(|(&p, &g)| g * cpu::eval(&kind, &cube(), q, p))
            .sum()
    };
    let analytic = cpu::backward(&kind, &cube(), params, &pts, &d_phi);
    let scale = analytic.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    assert!(scale > 0.0);
    let h = 1e-6;
    let mut q = params.to_vec();
    let mut checked = 0;
    for i in 0..params.len() {
        if analytic[i].abs() <= 1e-3 * scale {
            continue;
        }
        q[i] = params[i] + h;
        let up = loss(&q);
        q[i] = params[i] - h;
        let down = loss(&q);
        q[i] = params[i];
        let fd = (up - down) / (2.0 * h);
        assert!(
            (fd - analytic[i]).abs() <= 1e-5 * analytic[i].abs(),
            "{kind:?}: parameter {i}: fd {fd} vs analytic {}",
            analytic[i]
        );
        checked += 1;
    }
    eprintln!("{kind:?}: {checked} of {} components checked", params.len());
    assert!(checked > 0);
}

#[test]
fn twin_backward_matches_central_differences() {
    let mut rng = common::rng(30);
    let grid = FieldKind::Grid { res: 4 };
    let gp: Vec<f64> = (0..grid.param_count())
        .map(|_| rng.random_range(-3.0..3.0))
        .collect();
    check_twin_fd(grid, &gp, 300, 31);
    let mlp = FieldKind::Mlp {
        hidden_layers: 2,
        width: 8,
        frequencies: 2,
    };
    let mut mp = widen(&mlp.initial_params(32));
    let (offset, _, _) = mlp.mlp_layout().unwrap().layer(2);
    for p in &mut mp[offset..] {
        *p *= 100.0;
    }
    check_twin_fd(mlp, &mp, 50, 33);
    for kind in shapes() {
        let FieldKind::Analytic { shape, .. } = kind else {
            unreachable!()
        };
        check_twin_fd(kind, &shape.params(), 300, 34);
    }
}

#[test]
fn eval_and_backward_repeat_bit_for_bit_and_empty_inputs_give_zeros() {
    let Some(ctx) = common::gpu() else { return };
    let (field, _) = field_with_structure(&ctx, small_mlp(), 40);
    let points = random_points(&mut common::rng(41), 1000, &cube());
    let a = field.eval(&ctx, &points).unwrap();
    let b = field.eval(&ctx, &points).unwrap();
    assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
    let grad = field.backward(&ctx, &[], &[]).unwrap();
    assert_eq!(grad.len(), field.param_count());
    assert!(grad.iter().all(|&g| g == 0.0));
}

#[test]
fn bad_inputs_are_errors() {
    let Some(ctx) = common::gpu() else { return };
    let field = Field::new(&ctx, FieldKind::Grid { res: 3 }, cube(), 0).unwrap();
    assert!(matches!(
        field.set_params(&ctx, &[0.0; 5]),
        Err(Error::Input(_))
    ));
    assert!(matches!(
        field.set_params(&ctx, &[f32::NAN; 27]),
        Err(Error::Input(_))
    ));
    let small = ctx.create_buffer("small", 16, MemoryKind::Device).unwrap();
    let r = ctx.submit_and_wait(|rec| field.record_eval(rec, small.whole(), 10, small.whole()));
    assert!(matches!(r, Err(Error::Input(_))), "{r:?}");
    assert!(matches!(
        Field::new(&ctx, FieldKind::Grid { res: 1 }, cube(), 0),
        Err(Error::Input(_))
    ));
    assert!(matches!(
        Field::new(
            &ctx,
            FieldKind::Grid { res: 4 },
            Cube {
                center: [0.0; 3],
                half: -1.0
            },
            0
        ),
        Err(Error::Input(_))
    ));
    if ctx.info().shader_loop_limit().is_some() {
        let big = FieldKind::Mlp {
            hidden_layers: 8,
            width: 256,
            frequencies: 8,
        };
        let r = Field::new(&ctx, big, cube(), 0);
        assert!(
            matches!(
                r,
                Err(Error::DeviceLimit {
                    kind: LimitKind::LoopIterations,
                    ..
                })
            ),
            "{:?}",
            r.err()
        );
    }
}

#[test]
fn adam_steps_fit_a_grid_to_a_sphere() {
    let Some(ctx) = common::gpu() else { return };
    let cube = Cube::default();
    let kind = FieldKind::Grid { res: 12 };
    let field = Field::new(&ctx, kind, cube, 0).unwrap();
    let target = FieldKind::Analytic {
        shape: Shape::Sphere {
            center: [0.1, 0.0, -0.1],
            radius: 0.5,
        },
        sharpness: 10.0,
    };
    let FieldKind::Analytic { shape, .. } = target else {
        unreachable!()
    };
    let n = 4096;
    let points = random_points(&mut common::rng(50), n, &cube);
    let want: Vec<f32> = points
        .iter()
        .map(|p| cpu::eval(&target, &cube, &shape.params(), xyz(p)) as f32)
        .collect();
    let pts = ctx.upload_buffer("fit points", &points).unwrap();
    let phi = ctx
        .create_buffer("fit phi", 4 * n as u64, MemoryKind::Device)
        .unwrap();
    let d_phi = ctx
        .create_buffer("fit d_phi", 4 * n as u64, MemoryKind::Device)
        .unwrap();
    let grad = ctx
        .create_buffer(
            "fit grad",
            4 * field.param_count() as u64,
            MemoryKind::Device,
        )
        .unwrap();
    let adam = Adam::new(
        &ctx,
        field.param_count() as u64,
        AdamOptions {
            lr: 0.2,
            ..AdamOptions::default()
        },
    )
    .unwrap();
    let mut losses = Vec::new();
    for step in 1..=15u32 {
        ctx.submit_and_wait(|rec| field.record_eval(rec, pts.whole(), n as u32, phi.whole()))
            .unwrap();
        let got: Vec<f32> = ctx.read_buffer(&phi, 0, n).unwrap();
        let mse = got
            .iter()
            .zip(&want)
            .map(|(g, w)| f64::from(g - w).powi(2))
            .sum::<f64>()
            / n as f64;
        losses.push(mse);
        let d: Vec<f32> = got
            .iter()
            .zip(&want)
            .map(|(g, w)| 2.0 * (g - w) / n as f32)
            .collect();
        ctx.write_buffer(&d_phi, 0, &d).unwrap();
        ctx.submit_and_wait(|rec| {
            field.record_backward(rec, pts.whole(), n as u32, d_phi.whole(), grad.whole())?;
            adam.record_step(
                rec,
                field.params().range(0, 4 * field.param_count() as u64),
                grad.whole(),
                step,
            )
        })
        .unwrap();
    }
    eprintln!("grid → sphere MSE: {:?}", losses);
    assert!(
        losses[14] < 0.25 * losses[0],
        "MSE {} → {}",
        losses[0],
        losses[14]
    );
}

fn torus_and_sphere() -> Vec<FieldKind> {
    vec![
        FieldKind::Analytic {
            shape: Shape::Sphere {
                center: [0.05, -0.02, 0.03],
                radius: 0.6,
            },
            sharpness: 8.0,
        },
        FieldKind::Analytic {
            shape: Shape::Torus {
                center: [0.0, 0.05, -0.03],
                major: 0.55,
                minor: 0.22,
            },
            sharpness: 8.0,
        },
    ]
}

#[test]
fn marching_cubes_gpu_matches_its_twin_and_gives_closed_meshes_of_the_right_volume() {
    let Some(ctx) = common::gpu() else { return };
    let mc = MarchingCubes::new(&ctx).unwrap();
    let cube = Cube::default();
    let res = 40;
    for kind in torus_and_sphere() {
        let FieldKind::Analytic { shape, .. } = kind else {
            unreachable!()
        };
        let field = Field::new(&ctx, kind, cube, 0).unwrap();
        let lattice = mc.lattice_phi(&ctx, &field, res).unwrap();
        let twin_lattice = mcubes::cpu::lattice_phi(&kind, &cube, &shape.params(), res);
        assert_phi_close("lattice", &lattice, &twin_lattice, 2e-6);
        let gpu = mc.extract(&ctx, &field, res).unwrap();
        let twin = mcubes::cpu::extract(&widen(&lattice), res, &cube).unwrap();
        assert_eq!(gpu.faces, twin.faces, "{kind:?}: triangles");
        assert_eq!(gpu.edge_ids, twin.edge_ids, "{kind:?}: vertices");
        let worst = gpu
            .positions
            .iter()
            .zip(&twin.positions)
            .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "{kind:?}: positions differ by {worst}");
        assert!(
            gpu.is_closed(),
            "{kind:?}: the mesh has a border or a flipped face"
        );
        let (v, exact) = (gpu.volume(), shape.volume());
        eprintln!(
            "{kind:?}: {} faces, volume {v:.5} vs {exact:.5} ({:+.2} %)",
            gpu.faces.len(),
            100.0 * (v / exact - 1.0)
        );
        assert!((v / exact - 1.0).abs() < 0.02);
        // Every vertex lies on the surface up to the lattice's interpolation error.
        let h = 2.0 / f64::from(res - 1);
        for p in &gpu.positions {
            let sd = shape.sd(p.map(f64::from));
            assert!(sd.abs() < 0.05 * h, "vertex {p:?} is {sd} from the surface");
        }
        // The OBJ loads back as the same mesh.
        let path = std::env::temp_dir().join(format!("softvk-field-mc-{}.obj", std::process::id()));
        gpu.write_obj(&path).unwrap();
        let loaded = Mesh::load_obj(&path, 1).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(loaded, gpu.to_mesh().unwrap());
    }
}

#[test]
fn marching_cubes_of_a_field_without_surface_is_empty() {
    let Some(ctx) = common::gpu() else { return };
    let mc = MarchingCubes::new(&ctx).unwrap();
    let field = Field::new(&ctx, FieldKind::Grid { res: 3 }, Cube::default(), 0).unwrap();
    field.set_params(&ctx, &[-1.0; 27]).unwrap();
    let s = mc.extract(&ctx, &field, 8).unwrap();
    assert!(s.is_empty());
    assert!(matches!(s.to_mesh(), Err(Error::Input(_))));
    assert!(matches!(mc.extract(&ctx, &field, 1), Err(Error::Input(_))));
}

fn scaled_icosphere(subdivisions: u32, center: [f32; 3], radius: f32) -> Mesh {
    let mut mesh = Mesh::icosphere(subdivisions);
    for p in &mut mesh.positions {
        for k in 0..3 {
            p[k] = center[k] + radius * p[k];
        }
    }
    mesh
}

#[test]
fn a_voxelized_sphere_matches_its_analytic_occupancy() {
    let cube = Cube::default();
    let (c, r) = ([0.1f32, -0.05, 0.02], 0.7f32);
    let mesh = scaled_icosphere(5, c, r);
    let v = voxel::voxelize_mesh(&mesh.positions, &mesh.faces, &cube, 64).unwrap();
    assert_eq!(v.odd_rays, 0);
    let exact = voxel::occupancy_from_fn(&cube, 64, |p| {
        (0..3)
            .map(|k| (p[k] - f64::from(c[k])).powi(2))
            .sum::<f64>()
            < f64::from(r * r)
    });
    let iou = voxel::iou(&v.occupancy, &exact).unwrap();
    eprintln!(
        "voxelized sphere: IoU {iou:.5}, {} voxels",
        v.occupancy.count()
    );
    assert!(iou > 0.99);
}

#[test]
fn spot_voxelizes_watertight_with_its_volume() {
    let path = softvk::assets::dir().join("spot_triangulated.obj");
    let mesh = Mesh::load_obj(&path, 1).unwrap();
    // Spot spans x ±0.47, y −0.74..0.95, z −0.67..1.05.
    let cube = Cube::new([0.0, 0.11, 0.19], 0.9).unwrap();
    assert!(
        mesh.positions
            .iter()
            .all(|p| (0..3).all(|k| (f64::from(p[k]) - cube.center[k]).abs() < cube.half)),
        "spot fits the cube"
    );
    let v = voxel::voxelize_mesh(&mesh.positions, &mesh.faces, &cube, 64).unwrap();
    let volume = mcubes::mesh_volume(&mesh.positions, &mesh.faces);
    eprintln!(
        "spot: {} voxels inside, voxel volume {:.5} vs mesh volume {volume:.5}, {} odd rays",
        v.occupancy.count(),
        v.occupancy.volume(),
        v.odd_rays
    );
    assert_eq!(v.odd_rays, 0);
    assert!((v.occupancy.volume() / volume - 1.0).abs() < 0.03);
}

#[test]
fn field_occupancy_on_the_gpu_matches_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    let cube = Cube::default();
    for kind in torus_and_sphere() {
        let FieldKind::Analytic { shape, .. } = kind else {
            unreachable!()
        };
        let field = Field::new(&ctx, kind, cube, 0).unwrap();
        let gpu = voxel::field_occupancy(&ctx, &field, &cube, 32).unwrap();
        let params = shape.params();
        let twin =
            voxel::occupancy_from_fn(&cube, 32, |p| cpu::eval(&kind, &cube, &params, p) > 0.5);
        let differ = gpu
            .inside
            .iter()
            .zip(&twin.inside)
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(differ, 0, "{kind:?}");
        assert!(gpu.count() > 100);
        // Near enough to the shape's exact volume at 32³.
        assert!((gpu.volume() / shape.volume() - 1.0).abs() < 0.1);
    }
}

/// Silhouettes of `mesh` rendered by the project's reference rasterizer (hard coverage).
fn silhouettes(mesh: &Mesh, cameras: &[Camera], size: u32) -> softvk::io::Silhouettes {
    use softvk::lighting::Lighting;
    use softvk::raster::reference::render;
    use softvk::raster::settings::{Alpha, Dist, RasterSettings};
    let settings = RasterSettings {
        width: size,
        height: size,
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..RasterSettings::default()
    };
    let mut masks = Vec::new();
    for cam in cameras {
        let img = render(mesh, cam, &Lighting::default(), &settings).unwrap();
        masks.extend(img.iter().map(|p| p[3] as f32));
    }
    softvk::io::Silhouettes {
        width: size,
        height: size,
        names: (0..cameras.len()).map(|v| format!("{v:03}.png")).collect(),
        masks,
    }
}

#[test]
fn the_visual_hull_of_a_sphere_contains_it_and_is_close_to_it() {
    let cube = Cube::default();
    let (c, r) = ([0.25f32, 0.15, -0.1], 0.45f32);
    let mesh = scaled_icosphere(3, c, r);
    let cameras: Vec<Camera> = (0..16)
        .map(|v| Camera::from_angles(2.732, [-35.0, 0.0, 35.0, 60.0][v % 4], 22.5 * v as f64))
        .collect();
    let sil = silhouettes(&mesh, &cameras, 48);
    let hull = voxel::visual_hull(&sil, &cameras, &cube, 48).unwrap();
    let object = voxel::voxelize_mesh(&mesh.positions, &mesh.faces, &cube, 48)
        .unwrap()
        .occupancy;
    // Every voxel of the object whose centre is more than a pixel's footprint (≈ 0.04 at this
    // distance and size) inside the surface is in the hull.
    let inner = voxel::occupancy_from_fn(&cube, 48, |p| {
        (0..3)
            .map(|k| (p[k] - f64::from(c[k])).powi(2))
            .sum::<f64>()
            .sqrt()
            < f64::from(r) - 0.06
    });
    let missed = inner
        .inside
        .iter()
        .zip(&hull.inside)
        .filter(|&(&i, &h)| i && !h)
        .count();
    let iou = voxel::iou(&hull, &object).unwrap();
    eprintln!(
        "visual hull: {} voxels, object {}, missed inner {missed}, IoU {iou:.4}",
        hull.count(),
        object.count()
    );
    assert_eq!(missed, 0);
    assert!(iou > 0.85, "IoU {iou}");
    // Mismatched counts are an error.
    assert!(matches!(
        voxel::visual_hull(&sil, &cameras[..3], &cube, 8),
        Err(Error::Input(_))
    ));
    assert!(matches!(
        voxel::iou(&hull, &Occupancy::empty(cube, 8)),
        Err(Error::Input(_))
    ));
}

#[test]
fn the_preview_of_a_sphere_is_its_analytic_disc() {
    let Some(ctx) = common::gpu() else { return };
    let cube = Cube::default();
    let (center, radius) = ([0.2, -0.1, 0.05], 0.5);
    let kind = FieldKind::Analytic {
        shape: Shape::Sphere { center, radius },
        sharpness: 20.0,
    };
    let field = Field::new(&ctx, kind, cube, 0).unwrap();
    let camera = Camera::from_angles(2.732, 20.0, 30.0);
    let options = PreviewOptions {
        width: 40,
        height: 32,
        ..PreviewOptions::default()
    };
    let image = render_preview(&ctx, &field, &camera, &options).unwrap();
    let c = glam::DVec3::from(center);
    let (mut hits, mut brightest) = (0, (0u8, 1.0f64));
    for row in 0..options.height {
        for col in 0..options.width {
            let ray = pixel_ray(&camera, col, row, options.width, options.height).unwrap();
            let t = (c - ray.origin).dot(ray.dir);
            let dist = (ray.origin + ray.dir * t - c).length();
            let px = image.get_pixel(col, row);
            let hit = px[3] == 255;
            if (dist - radius).abs() > 1e-3 {
                assert_eq!(
                    hit,
                    dist < radius,
                    "pixel ({col}, {row}): ray at {dist} from the centre"
                );
            }
            if hit {
                hits += 1;
                if px[0] > brightest.0 {
                    brightest = (px[0], dist / radius);
                }
            } else {
                assert_eq!(px.0, [0, 0, 0, 0]);
            }
        }
    }
    eprintln!(
        "preview: {hits} pixels hit; brightest {} at {:.2} r from the centre",
        brightest.0, brightest.1
    );
    assert!(hits > 60);
    // Headlight: the brightest pixel looks at the sphere head-on (0.85 · (0.25 + 0.75) · 255).
    assert!(brightest.0 >= 214 && brightest.1 < 0.2, "{brightest:?}");
    // And it writes as a PNG of that size.
    let path =
        std::env::temp_dir().join(format!("softvk-field-preview-{}.png", std::process::id()));
    softvk::fit::report::write_png(&path, &image).unwrap();
    let back = image::open(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!((back.width(), back.height()), (40, 32));
}

#[test]
fn marching_cubes_of_a_random_field_is_closed_despite_ambiguous_faces() {
    let Some(ctx) = common::gpu() else { return };
    let mc = MarchingCubes::new(&ctx).unwrap();
    let cube = Cube::default();
    let res = 12;
    let field = Field::new(&ctx, FieldKind::Grid { res }, cube, 0).unwrap();
    let mut rng = common::rng(60);
    let r = res as usize;
    // Random logits, the border outside: on the lattice of the grid's own nodes every sign
    // pattern occurs, ambiguous faces and cells included.
    let params: Vec<f32> = (0..r * r * r)
        .map(|v| {
            let q = [v % r, (v / r) % r, v / (r * r)];
            if q.iter().any(|&c| c == 0 || c == r - 1) {
                -3.0
            } else {
                rng.random_range(-1.0..1.0)
            }
        })
        .collect();
    field.set_params(&ctx, &params).unwrap();
    let table = mcubes::table();
    let mut ambiguous_cases = 0;
    for lattice in [res, 2 * res - 1] {
        let phi = mc.lattice_phi(&ctx, &field, lattice).unwrap();
        let gpu = mc.extract(&ctx, &field, lattice).unwrap();
        let twin = mcubes::cpu::extract(&widen(&phi), lattice, &cube).unwrap();
        assert_eq!(gpu.faces, twin.faces);
        assert!(gpu.is_closed(), "lattice {lattice}: not closed");
        assert!(gpu.volume() > 0.0);
        if lattice == res {
            // Count cells whose case has more than one loop (an ambiguous face or cell).
            let l = lattice as usize;
            for z in 0..l - 1 {
                for y in 0..l - 1 {
                    for x in 0..l - 1 {
                        let case = (0..8).fold(0usize, |c, k| {
                            let v = [x + (k & 1), y + (k >> 1 & 1), z + (k >> 2 & 1)];
                            c | (usize::from(phi[v[0] + l * (v[1] + l * v[2])] > 0.5) << k)
                        });
                        let crossings = (0..12)
                            .filter(|&e| {
                                let (a, b) = mcubes::edge_corners(e);
                                (case >> a & 1) != (case >> b & 1)
                            })
                            .count();
                        // One loop of m crossings makes m − 2 triangles; more loops, fewer.
                        if crossings > 0 && table.counts[case] as usize != crossings - 2 {
                            ambiguous_cases += 1;
                        }
                    }
                }
            }
        }
        eprintln!(
            "random field at {lattice}³: {} faces, closed",
            gpu.faces.len()
        );
    }
    eprintln!("{ambiguous_cases} cells with several loops");
    assert!(ambiguous_cases > 10);
}

#[test]
fn an_mlp_just_under_the_loop_cap_still_matches_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    // 6 × 216 with 4 frequencies: ~64 200 loop iterations per point in the forward pass (the
    // evaluation's, and the backward's with its stores) by the host's count, just under
    // llvmpipe's 65 535: a count that underestimated the kernels' loops would let llvmpipe cut
    // them short here, and φ or the gradient would be wrong.
    let kind = FieldKind::Mlp {
        hidden_layers: 6,
        width: 216,
        frequencies: 4,
    };
    let layout = kind.mlp_layout().unwrap();
    let n = layout.forward_iterations();
    assert!(n > 60_000 && n <= 65_535, "{n}");
    let (field, params) = field_with_structure(&ctx, kind, 70);
    let mut rng = common::rng(71);
    let points = random_points(&mut rng, 300, &cube());
    let phi = field.eval(&ctx, &points).unwrap();
    let twin: Vec<f64> = points
        .iter()
        .map(|p| cpu::eval(&kind, &cube(), &widen(&params), xyz(p)))
        .collect();
    assert_phi_close("6 × 216 MLP", &phi, &twin, 1e-4);
    let d_phi: Vec<f32> = (0..points.len())
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let grad = field.backward(&ctx, &points, &d_phi).unwrap();
    let pts: Vec<[f64; 3]> = points.iter().map(xyz).collect();
    let twin = cpu::backward(&kind, &cube(), &widen(&params), &pts, &widen(&d_phi));
    assert_grad_close("6 × 216 MLP backward", &grad, &twin, 1e-3);
}
