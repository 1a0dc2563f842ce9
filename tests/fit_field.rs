//! The field fit of sphere probing (SPEC §5): one GPU iteration against an iteration assembled
//! from the CPU twins, determinism, a tiny end-to-end fit, and `softvk fit-field` (its outputs
//! and its one-line errors).

mod common;

use common::{TempDir, softvk};

use std::path::{Path, PathBuf};

use softvk::Error;
use softvk::camera::Camera;
use softvk::field::{Cube, FieldKind, cpu as field_cpu, voxel};
use softvk::fit::AdamOptions;
use softvk::fit::adam::cpu as adam_cpu;
use softvk::fit::field_fit::{
    FieldFit, FieldFitOptions, FieldFitter, auto_cube, check_cameras_outside, fit_field,
};
use softvk::fit::session::Session;
use softvk::probe::prober::cpu as probe_cpu;
use softvk::probe::sampler::{Ray, cpu as sampler_cpu};
use softvk::probe::targets::sphere_silhouettes;
use softvk::probe::{Aggregate, ProbeSettings, Targets, geo};
use softvk_testing::Lcg;

/// 2 views of 24² of a sphere of radius 0.5.
fn tiny_targets() -> Targets {
    let cams = [
        Camera::from_angles(2.732, 20.0, 30.0),
        Camera::from_angles(2.732, -10.0, 130.0),
    ];
    sphere_silhouettes(&cams, 24, 24, 0.5).unwrap()
}

/// Tiny settings: 96 rays per view, 300 anchors (not a multiple of the alignment, so the points
/// buffer has padding), 12 surface candidates, a large τ and a wide window so that rays hit
/// several anchors and the regularizer sees many terms.
fn tiny_options(aggregate: Aggregate, lambda: f64) -> FieldFitOptions {
    FieldFitOptions {
        field: FieldKind::Grid { res: 8 },
        probe: ProbeSettings {
            rays_per_view: 96,
            anchors: 300,
            tau: 0.1,
            anchor_sigma: 0.08,
            hull_resolution: 16,
            tile_size: 8,
            aggregate,
            temperature: 0.1,
            geo_candidates: 12,
            geo_uniform_fraction: 0.5,
            geo_delta: 0.1,
            geo_normal_delta: 0.05,
            geo_epsilon: 0.35,
            geo_lambda: lambda,
            seed: 7,
            ..ProbeSettings::default()
        },
        adam: AdamOptions {
            lr: 0.05,
            betas: (0.9, 0.99),
            eps: 1e-8,
        },
        iterations: 3,
        log_every: 1,
        init_logit: 0.0,
    }
}

fn xyz(p: &[f32; 4]) -> [f64; 3] {
    [p[0], p[1], p[2]].map(f64::from)
}

/// Worst |gpu − twin| over the largest |twin|.
fn rel_error(gpu: &[f32], twin: &[f64]) -> f64 {
    assert_eq!(gpu.len(), twin.len());
    let scale = twin.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0, "a zero gradient checks nothing");
    let worst = gpu
        .iter()
        .zip(twin)
        .fold(0.0f64, |m, (&g, &t)| m.max((f64::from(g) - t).abs()));
    worst / scale
}

#[test]
fn one_gpu_iteration_equals_the_iteration_of_the_cpu_twins() {
    let Some(ctx) = common::gpu() else { return };
    let targets = tiny_targets();
    for (aggregate, lambda) in [(Aggregate::Max, 0.5), (Aggregate::Union, 0.2)] {
        let opts = tiny_options(aggregate, lambda);
        let s = &opts.probe;
        let kind = opts.field;
        let cube = opts.cube();
        let mut fitter = FieldFit::fitter(&ctx, &targets, &opts).unwrap();
        // Random logits: a field with structure and without ties between anchors.
        let mut rng = Lcg(11);
        let p0: Vec<f32> = (0..kind.param_count())
            .map(|_| (4.0 * rng.unit() - 2.0) as f32)
            .collect();
        fitter.field().set_params(&ctx, &p0).unwrap();
        assert_eq!(fitter.run(1, 1, None).unwrap(), None);
        let (l_sil, l_geo) = fitter.read_losses(&ctx).unwrap();

        // The samples: the GPU's, checked against the sampler's twin.
        let sampler = fitter.sampler();
        let rays: Vec<Ray> = ctx
            .read_buffer(sampler.rays(), 0, sampler.ray_count() as usize)
            .unwrap();
        let anchors: Vec<[f32; 4]> = ctx
            .read_buffer(sampler.anchors(), 0, s.anchors as usize)
            .unwrap();
        let candidates: Vec<[f32; 4]> = ctx
            .read_buffer(sampler.candidates(), 0, s.geo_candidates as usize)
            .unwrap();
        let twin_samples = sampler_cpu::sample(&targets, s, sampler.boundary_points(), 1).unwrap();
        assert_eq!(rays, twin_samples.rays);
        for (a, b) in anchors.iter().zip(&twin_samples.anchors) {
            assert!((0..3).all(|k| (a[k] - b[k]).abs() <= 1e-6), "{a:?} {b:?}");
        }

        // The points buffer: anchors, zero padding, the regularizer's points.
        let total = (fitter.geo_start() + fitter.geo_count()) as usize;
        let points: Vec<[f32; 4]> = ctx.read_buffer(fitter.points(), 0, total).unwrap();
        let geo_points = geo::cpu::points(&candidates, s.geo_delta, s.geo_normal_delta);
        assert_eq!(fitter.geo_count() as usize, geo_points.len());
        assert_eq!(&points[..anchors.len()], &anchors[..]);
        let start = fitter.geo_start() as usize;
        assert!(start >= anchors.len());
        assert!(points[anchors.len()..start].iter().all(|p| *p == [0.0; 4]));
        assert_eq!(&points[start..], &geo_points[..]);

        // The twins' iteration, from the same parameters and samples.
        let p64: Vec<f64> = p0.iter().map(|&x| f64::from(x)).collect();
        let phi = |pts: &[[f32; 4]]| -> Vec<f64> {
            pts.iter()
                .map(|p| field_cpu::eval(&kind, &cube, &p64, xyz(p)))
                .collect()
        };
        let phi_a = phi(&anchors);
        let forward = probe_cpu::forward(&targets, s, &anchors, &phi_a, &rays);
        let d_a = probe_cpu::backward(s, &forward, &phi_a, &rays);
        let phi_g = phi(&geo_points);
        let (want_geo, d_g) = geo::cpu::loss(s, &phi_g);
        let hit_rays = forward.hits.iter().filter(|h| !h.is_empty()).count();
        assert!(
            hit_rays * 2 > rays.len(),
            "{hit_rays} of {} rays hit",
            rays.len()
        );
        assert!(d_g.iter().any(|&g| g != 0.0), "the regularizer contributes");
        assert!(want_geo > 0.0);
        let mut all_points: Vec<[f64; 3]> = anchors.iter().map(xyz).collect();
        all_points.extend(geo_points.iter().map(xyz));
        let mut d_all = d_a.clone();
        d_all.extend(d_g.iter().map(|g| lambda * g));
        let want = field_cpu::backward(&kind, &cube, &p64, &all_points, &d_all);

        let rel = |a: f32, b: f64| (f64::from(a) - b).abs() / b.abs().max(1e-30);
        assert!(
            rel(l_sil, forward.loss) < 1e-5,
            "L_sil {l_sil} vs {}",
            forward.loss
        );
        assert!(rel(l_geo, want_geo) < 1e-4, "L_geo {l_geo} vs {want_geo}");
        let grad: Vec<f32> = ctx
            .read_buffer(fitter.d_params(), 0, kind.param_count())
            .unwrap();
        let e = rel_error(&grad, &want);
        eprintln!("{aggregate:?}: d_params worst error {e:.2e} of the largest component");
        assert!(e <= 1e-3, "{aggregate:?}: d_params off by {e:e}");
        // Both terms reach the parameters: the geo part alone is a sizeable share.
        let geo_only = field_cpu::backward(
            &kind,
            &cube,
            &p64,
            &all_points[anchors.len()..],
            &d_all[anchors.len()..],
        );
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(norm(&geo_only) > 1e-3 * norm(&want));

        // The Adam step used that gradient: step 1 from zero moments.
        let mut p_want = p64.clone();
        let (mut m, mut v) = (vec![0.0; p64.len()], vec![0.0; p64.len()]);
        let g64: Vec<f64> = grad.iter().map(|&x| f64::from(x)).collect();
        adam_cpu::step(&mut p_want, &g64, &mut m, &mut v, 1, &opts.adam);
        let p1 = fitter.field().read_params(&ctx).unwrap();
        for (i, (&a, &b)) in p1.iter().zip(&p_want).enumerate() {
            assert!((f64::from(a) - b).abs() <= 1e-5, "param {i}: {a} vs {b}");
        }
    }
}

#[test]
fn a_repeated_fit_gives_bit_identical_parameters() {
    let Some(ctx) = common::gpu() else { return };
    let targets = tiny_targets();
    for field in [
        FieldKind::Grid { res: 8 },
        FieldKind::Mlp {
            hidden_layers: 2,
            width: 16,
            frequencies: 2,
        },
    ] {
        let opts = FieldFitOptions {
            field,
            iterations: 4,
            log_every: 2,
            ..tiny_options(Aggregate::Max, 0.3)
        };
        let fit = || {
            let r = fit_field(&ctx, &targets, &opts, Session::new()).unwrap();
            (r.field.read_params(&ctx).unwrap(), r.log)
        };
        let (a, log_a) = fit();
        let (b, log_b) = fit();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b), "{field:?}");
        assert_eq!(log_a.len(), 2);
        for (x, y) in log_a.iter().zip(&log_b) {
            assert_eq!(x.silhouette.to_bits(), y.silhouette.to_bits());
            assert_eq!(x.geo.to_bits(), y.geo.to_bits());
        }
        // The fit moved the parameters.
        assert_ne!(bits(&a), bits(&field.initial_params(opts.probe.seed)));
    }
}

/// A fit's parameters (bits), its log (iteration and loss bits) and the submissions it made.
fn fit_bits(
    ctx: &common::Gpu,
    targets: &Targets,
    opts: &FieldFitOptions,
) -> (Vec<u32>, Vec<(u32, u32, u32)>, u64) {
    let before = ctx.counters().submissions;
    let r = fit_field(ctx, targets, opts, Session::new()).unwrap();
    let submissions = ctx.counters().submissions - before;
    let params = r.field.read_params(ctx).unwrap();
    let log = r
        .log
        .iter()
        .map(|l| (l.iteration, l.silhouette.to_bits(), l.geo.to_bits()))
        .collect();
    (
        params.iter().map(|x| x.to_bits()).collect(),
        log,
        submissions,
    )
}

#[test]
fn k_field_iterations_per_submission_give_the_bits_of_one_per_submission() {
    let Some(ctx) = common::gpu() else { return };
    let targets = tiny_targets();
    // Max (its backward by rays) and union (by the binned entries, whose count stays on the
    // GPU), with the regularizer.
    for aggregate in [Aggregate::Max, Aggregate::Union] {
        let opts = |iterations, log_every| FieldFitOptions {
            iterations,
            log_every,
            ..tiny_options(aggregate, 0.3)
        };
        let (params_1, log_1, submissions_1) = fit_bits(&ctx, &targets, &opts(6, 1));
        assert_eq!(log_1.len(), 6);
        let mut submissions = vec![(1u64, submissions_1)];
        for k in [4, 6] {
            let (params_k, log_k, submissions_k) = fit_bits(&ctx, &targets, &opts(6, k));
            submissions.push((u64::from(k), submissions_k));
            assert_eq!(params_k, params_1, "{aggregate:?}, k = {k}");
            // Logged after iterations k, 2k, ... and the last: k = 1's values there.
            let want: Vec<u32> = (1..=6).filter(|i| i % k == 0 || *i == 6).collect();
            assert_eq!(log_k.iter().map(|l| l.0).collect::<Vec<_>>(), want);
            for l in &log_k {
                assert_eq!(*l, log_1[l.0 as usize - 1], "{aggregate:?}, k = {k}");
            }
        }
        // Submissions grow with the chunks of k iterations, not with the iterations: a chunk
        // of 6 costs what a fit of 1 iteration costs, and 6, 2 and 1 chunks (k = 1, 4, 6) that
        // plus a fixed amount per further chunk.
        let (_, _, submissions_single) = fit_bits(&ctx, &targets, &opts(1, 1));
        assert_eq!(submissions[2].1, submissions_single, "{submissions:?}");
        let chunks = |k: u64| 6u64.div_ceil(k);
        let per_chunk = (submissions_1 - submissions_single) / (chunks(1) - 1);
        assert!(per_chunk > 0);
        for &(k, n) in &submissions {
            assert_eq!(
                n,
                submissions_single + (chunks(k) - 1) * per_chunk,
                "{aggregate:?}, k = {k}: {submissions:?}"
            );
        }
    }
}

#[test]
fn a_field_fit_that_outgrows_its_entry_capacity_equals_one_that_never_did() {
    let Some(ctx) = common::gpu() else { return };
    let targets = tiny_targets();
    let opts = tiny_options(Aggregate::Union, 0.3);
    let params = |f: &FieldFitter| {
        let p = f.field().read_params(&ctx).unwrap();
        p.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    };
    let mut ample = FieldFit::fitter(&ctx, &targets, &opts).unwrap();
    assert_eq!(ample.run(1, 3, None).unwrap(), None);
    assert_eq!(ample.regrowths(), 0);
    let entries = ample.last_entries();
    assert!(entries > 1);

    let mut tight = FieldFit::fitter(&ctx, &targets, &opts).unwrap();
    tight.reserve(&ctx, 1).unwrap();
    assert_eq!(tight.capacity(), 1);
    // Iteration 1 does not fit: it and the later ones change nothing, and the capacity grows.
    let before = params(&tight);
    assert_eq!(tight.run(1, 3, None).unwrap(), Some(1));
    assert_eq!(params(&tight), before);
    assert_eq!(tight.regrowths(), 1);
    assert!(tight.capacity() > 1);
    let mut it = 1;
    while let Some(stopped) = tight.run(it, 3, None).unwrap() {
        it = stopped;
    }
    assert_eq!(params(&tight), params(&ample));
    assert_eq!(tight.last_entries(), entries);
}

#[test]
fn a_short_fit_of_a_sphere_raises_its_3d_iou() {
    let Some(ctx) = common::gpu() else { return };
    let cams: Vec<Camera> = (0..8)
        .map(|i| Camera::from_angles(2.732, [25.0, -20.0][i % 2], 45.0 * i as f64))
        .collect();
    let targets = sphere_silhouettes(&cams, 32, 32, 0.5).unwrap();
    let cube = Cube::default();
    let opts = FieldFitOptions {
        field: FieldKind::Grid { res: 16 },
        probe: ProbeSettings {
            rays_per_view: 256,
            anchors: 2048,
            tau: 0.06,
            anchor_sigma: 0.06,
            hull_resolution: 32,
            tile_size: 8,
            geo_candidates: 128,
            geo_lambda: 0.0,
            seed: 1,
            ..ProbeSettings::default()
        },
        adam: AdamOptions {
            lr: 0.1,
            betas: (0.9, 0.99),
            eps: 1e-8,
        },
        iterations: 30,
        log_every: 10,
        init_logit: 0.0,
    };
    let sphere = voxel::occupancy_from_fn(&cube, 24, |p| {
        (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() < 0.5
    });
    let before = {
        let f = FieldFit::fitter(&ctx, &targets, &opts).unwrap();
        voxel::iou(
            &voxel::field_occupancy(&ctx, f.field(), &cube, 24).unwrap(),
            &sphere,
        )
        .unwrap()
    };
    let r = fit_field(&ctx, &targets, &opts, Session::new()).unwrap();
    let after = voxel::iou(
        &voxel::field_occupancy(&ctx, &r.field, &cube, 24).unwrap(),
        &sphere,
    )
    .unwrap();
    let (first, last) = (r.log[0].silhouette, r.log.last().unwrap().silhouette);
    eprintln!("sphere: 3D IoU {before:.3} → {after:.3}, L_sil {first:.4} → {last:.4}");
    assert!(
        after > 0.7 && after > before + 0.5,
        "IoU {before} → {after}"
    );
    assert!(last < first, "L_sil {first} → {last}");
}

#[test]
fn cameras_inside_the_cube_and_bad_options_are_input_errors() {
    let targets = tiny_targets();
    let inside = Cube::new([0.0; 3], 3.0).unwrap();
    assert!(matches!(
        check_cameras_outside(&targets, &inside),
        Err(Error::Input(_))
    ));
    check_cameras_outside(&targets, &Cube::default()).unwrap();
    let cube = auto_cube(&targets, 0.1).unwrap();
    // The auto cube holds the sphere (radius 0.5) and keeps the cameras out.
    for a in 0..3 {
        assert!(cube.center[a] - cube.half < -0.5 && cube.center[a] + cube.half > 0.5);
    }
    check_cameras_outside(&targets, &cube).unwrap();
    let empty = Targets::new(&targets.cameras, 24, 24, vec![0.0; 2 * 24 * 24]).unwrap();
    assert!(matches!(auto_cube(&empty, 0.1), Err(Error::Input(_))));
    let Some(ctx) = common::gpu() else { return };
    let mut opts = tiny_options(Aggregate::Max, 0.1);
    opts.probe.cube_half = 3.0;
    assert!(matches!(
        FieldFit::fitter(&ctx, &targets, &opts),
        Err(Error::Input(_))
    ));
    let opts = FieldFitOptions {
        iterations: 0,
        ..tiny_options(Aggregate::Max, 0.1)
    };
    assert!(matches!(
        fit_field(&ctx, &targets, &opts, Session::new()),
        Err(Error::Input(_))
    ));
}

#[test]
fn dense_marching_matches_its_twin() {
    use softvk::field::Field;
    use softvk::probe::GpuTargets;
    use softvk::probe::dense::{DenseMarch, cpu as dense_cpu};
    let Some(ctx) = common::gpu() else { return };
    let targets = tiny_targets();
    let s = tiny_options(Aggregate::Max, 0.0).probe;
    let boundary = softvk::probe::hull::boundary_points(&targets, &s);
    let rays = sampler_cpu::sample(&targets, &s, &boundary, 2)
        .unwrap()
        .rays;
    let cube = Cube::default();
    let kind = FieldKind::Grid { res: 8 };
    let field = Field::new(&ctx, kind, cube, 0).unwrap();
    let mut rng = Lcg(5);
    let params: Vec<f32> = (0..kind.param_count())
        .map(|_| (4.0 * rng.unit() - 2.0) as f32)
        .collect();
    field.set_params(&ctx, &params).unwrap();
    let step = 2.0 / 7.0;
    let gpu = GpuTargets::new(&ctx, &targets).unwrap();
    let ray_buf = ctx.upload_buffer("rays", &rays).unwrap();
    let dense = DenseMarch::new(&ctx, &targets, &rays, &cube, step).unwrap();
    let n = dense.sample_count();
    ctx.submit_and_wait(|rec| {
        dense.record_points(rec, &gpu, ray_buf.whole())?;
        field.record_eval(rec, dense.points().whole(), n, dense.phi().whole())?;
        dense.record_max(rec, ray_buf.whole(), true)
    })
    .unwrap();
    let counts = dense_cpu::counts(&targets, &rays, &cube, step);
    let offsets = dense_cpu::offsets(&counts);
    assert_eq!(offsets[rays.len()], n);
    // Most rays cross the cube (the image reaches beyond it), none with more than
    // ceil(2√3 / step) samples.
    let crossing = counts.iter().filter(|&&c| c > 0).count();
    assert!(crossing * 4 > rays.len() * 3, "{counts:?}");
    assert!(counts.iter().all(|&c| c <= 13), "{counts:?}");
    let want_points = dense_cpu::points(&targets, &rays, &offsets, &cube);
    let points: Vec<[f32; 4]> = ctx.read_buffer(dense.points(), 0, n as usize).unwrap();
    for (g, w) in points.iter().zip(&want_points) {
        assert!(
            (0..3).all(|a| (f64::from(g[a]) - w[a]).abs() < 1e-5),
            "{g:?} vs {w:?}"
        );
        assert!(
            w.iter().all(|c| c.abs() <= 1.0 + 1e-5),
            "a sample outside the cube: {w:?}"
        );
    }
    // The max of the GPU's φ (the field's eval is tested elsewhere), ψ and dL/dφ.
    let phi: Vec<f32> = ctx.read_buffer(dense.phi(), 0, n as usize).unwrap();
    let phi64: Vec<f64> = phi.iter().map(|&x| f64::from(x)).collect();
    for (i, (&f, w)) in phi.iter().zip(&want_points).enumerate() {
        let t = field_cpu::eval(
            &kind,
            &cube,
            &params.iter().map(|&x| f64::from(x)).collect::<Vec<_>>(),
            *w,
        );
        assert!((f64::from(f) - t).abs() < 1e-4, "sample {i}: {f} vs {t}");
    }
    let (want_psi, want_d) = dense_cpu::max(&rays, &offsets, &phi64);
    let psi: Vec<f32> = ctx.read_buffer(dense.psi(), 0, rays.len()).unwrap();
    let d: Vec<f32> = ctx.read_buffer(dense.d_phi(), 0, n as usize).unwrap();
    for (g, w) in psi.iter().zip(&want_psi) {
        assert_eq!(f64::from(*g), *w);
    }
    assert!(rel_error(&d, &want_d) < 1e-6);
}

#[test]
fn the_auto_cube_holds_a_sphere_that_the_frames_cut() {
    use softvk::camera::Projection;
    use softvk::fit::field_fit::silhouettes_touch_the_border;
    // A 10° frame is ±0.48 wide at the origin: a sphere of radius 0.6 overflows every view.
    let cams: Vec<Camera> = (0..12)
        .map(|i| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 10.0,
            },
            ..Camera::from_angles(2.732, [30.0, -15.0][i % 2], 30.0 * i as f64)
        })
        .collect();
    let cut = sphere_silhouettes(&cams, 32, 32, 0.6).unwrap();
    assert!(silhouettes_touch_the_border(&cut));
    let cube = auto_cube(&cut, 0.0).unwrap();
    for a in 0..3 {
        let (lo, hi) = (cube.center[a] - cube.half, cube.center[a] + cube.half);
        assert!(lo <= -0.6 && hi >= 0.6, "axis {a}: [{lo}, {hi}]");
    }
    check_cameras_outside(&cut, &cube).unwrap();
    // A sphere within every frame: the ordinary hull, a cube just around it.
    let whole = sphere_silhouettes(&cams, 32, 32, 0.3).unwrap();
    assert!(!silhouettes_touch_the_border(&whole));
    let cube = auto_cube(&whole, 0.0).unwrap();
    assert!(cube.half > 0.3 && cube.half < 0.45, "{cube:?}");
}

// ---- the command line ----

/// Sphere silhouettes (3 views of 24²) and their cameras file, written by the library.
fn write_sphere_inputs(dir: &TempDir) -> (PathBuf, PathBuf) {
    use softvk::io::{self, CameraRow};
    let rows: Vec<CameraRow> = (0..3)
        .map(|i| CameraRow {
            distance: 2.732,
            elevation: 20.0,
            azimuth: 120.0 * f64::from(i),
        })
        .collect();
    let cams: Vec<Camera> = rows.iter().map(CameraRow::camera).collect();
    let t = sphere_silhouettes(&cams, 24, 24, 0.5).unwrap();
    let sil = dir.path("sil");
    io::write_silhouettes(&sil, &io::silhouette_names(3), 24, 24, &t.masks).unwrap();
    let csv = dir.path("cameras.csv");
    io::write_cameras(&csv, &rows).unwrap();
    (sil, csv)
}

const TINY: [&str; 12] = [
    "--grid-res",
    "8",
    "--rays",
    "64",
    "--anchors",
    "256",
    "--geo-candidates",
    "16",
    "--hull-res",
    "16",
    "--mc-res",
    "16",
];

#[test]
fn fit_field_writes_the_mesh_the_preview_and_the_loss_plot() {
    if common::no_gpu() {
        eprintln!("SOFTVK_NO_GPU=1: skipping a GPU test");
        return;
    }
    let dir = TempDir::new("fit-field");
    let (sil, csv) = write_sphere_inputs(&dir);
    let out = dir.path("field.obj");
    let o = softvk()
        .args(["fit-field", "--iters", "4", "--log-every", "2", "--quiet"])
        .args(["--viewing-angle", "30", "--preview-size", "32"])
        .args(TINY)
        .arg("--silhouettes")
        .arg(&sil)
        .arg("--cameras")
        .arg(&csv)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = dir.path("field-report");
    for f in ["preview.png", "compare.png", "loss.png", "loss.csv"] {
        assert!(report.join(f).is_file(), "{f} missing");
    }
    // The visual hull's surface beside the fitted one: two labelled 32² panels, both showing a
    // lit shape (the hull of a sphere's silhouettes is a blob; the fitted surface is not empty).
    let sheet = image::open(report.join("compare.png")).unwrap().to_rgb8();
    assert_eq!(sheet.width(), 2 * 32 + 3);
    for (i, name) in ["visual hull", "fitted"].iter().enumerate() {
        let (x0, y0) = (1 + 33 * i as u32, sheet.height() - 33);
        let lit = (0..32 * 32)
            .filter(|k| {
                sheet
                    .get_pixel(x0 + k % 32, y0 + k / 32)
                    .0
                    .iter()
                    .any(|&c| c > 40)
            })
            .count();
        assert!(lit > 20, "{name}: {lit} lit pixels");
    }
    let csv_text = std::fs::read_to_string(report.join("loss.csv")).unwrap();
    assert_eq!(csv_text.lines().count(), 1 + 2, "{csv_text}");
    // Marching cubes of a 4-iteration field may or may not cross 0.5; when it does, it wrote a
    // mesh; when not, the run says so and fails. Here the field starts at φ ≈ 0.5 and is pushed
    // both ways, so there is a surface.
    let mesh = softvk::mesh::Mesh::load_obj(&out, 1).unwrap();
    assert!(mesh.face_count() > 0);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("cube"), "{stdout}");
}

/// The run failed with exactly one stderr line containing `needle`.
fn assert_one_error_line(what: &str, out: &std::process::Output, needle: &str) {
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
        "{what}: `{needle}` missing: {stderr}"
    );
    assert!(out.stdout.is_empty(), "{what}: printed on stdout");
}

#[test]
fn fit_field_errors_are_one_line_and_write_nothing() {
    use softvk::io::{self, CameraRow};
    let dir = TempDir::new("fit-field-errors");
    let (sil, csv) = write_sphere_inputs(&dir);
    let empty = dir.path("empty_sil");
    io::write_silhouettes(&empty, &io::silhouette_names(3), 8, 8, &[0.0; 3 * 64]).unwrap();
    let no_png = dir.path("no_png");
    std::fs::create_dir_all(&no_png).unwrap();
    let row = CameraRow {
        distance: 2.732,
        elevation: 20.0,
        azimuth: 0.0,
    };
    let two = dir.path("two.csv");
    io::write_cameras(&two, &[row, row]).unwrap();
    let near = dir.path("near.csv");
    let close = CameraRow {
        distance: 0.9,
        ..row
    };
    io::write_cameras(&near, &[close, row, row]).unwrap();
    let out = dir.path("m.obj");
    let no_dir = dir.path("none");
    let cases: Vec<(&str, &Path, &Path, Vec<&str>, &str)> = vec![
        ("missing silhouettes", &no_dir, &csv, vec![], "none"),
        ("no silhouettes", &no_png, &csv, vec![], "no_png"),
        ("empty silhouettes", &empty, &csv, vec![], "no pixel inside"),
        ("camera rows vs images", &sil, &two, vec![], "2 camera rows"),
        (
            "camera inside the cube",
            &sil,
            &near,
            vec!["--cube", "0,0,0,1"],
            "inside the field's cube",
        ),
        ("bad cube", &sil, &csv, vec!["--cube", "0,0,1"], "--cube"),
        (
            "size mismatch",
            &sil,
            &csv,
            vec!["--size", "16"],
            "--size 16",
        ),
        ("bad probe setting", &sil, &csv, vec!["--tau", "0"], "tau"),
        (
            "mlp over the loop cap or out of range",
            &sil,
            &csv,
            vec!["--field", "mlp", "--mlp-width", "999"],
            "width",
        ),
    ];
    for (what, s, c, args, needle) in cases {
        let o = softvk()
            .arg("fit-field")
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
