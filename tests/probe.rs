//! Sphere probing (SPEC §5) on the GPU against its CPU twins: sampling, the tiled forward
//! against the brute-force loop, the backward against the twin and the twin against finite
//! differences, boundary-aware assignment, the geometric regularizer, determinism and limits.

mod common;

use rand::RngExt;
use softvk::camera::{Camera, Projection};
use softvk::fit::GradOut;
use softvk::gpu::gate::{GateStatus, IterationGate};
use softvk::gpu::{Buffer, Context, MemoryKind};
use softvk::probe::prober::{NO_HIT, ProbeRun, RayOut, cpu as probe_cpu};
use softvk::probe::sampler::{Ray, cpu as sampler_cpu};
use softvk::probe::targets::sphere_silhouettes;
use softvk::probe::{
    Aggregate, GeoRegularizer, GpuTargets, ProbeSettings, Prober, Sampler, Targets, geo,
};
use softvk::{Error, LimitKind};

const RADIUS: f64 = 0.5;

fn cameras() -> Vec<Camera> {
    vec![
        Camera::from_angles(2.732, 0.0, 0.0),
        Camera::from_angles(2.732, 30.0, 100.0),
        Camera::from_angles(3.0, -40.0, 220.0),
    ]
}

/// Small settings: 3 views of 40×32, 192 rays per view, 768 anchors with a large τ so that rays
/// hit several anchors.
fn settings(aggregate: Aggregate) -> ProbeSettings {
    ProbeSettings {
        rays_per_view: 192,
        anchors: 768,
        tau: 0.08,
        anchor_sigma: 0.05,
        hull_resolution: 20,
        tile_size: 8,
        aggregate,
        temperature: 0.1,
        geo_candidates: 40,
        geo_epsilon: 0.25,
        seed: 42,
        ..ProbeSettings::default()
    }
}

fn targets() -> Targets {
    sphere_silhouettes(&cameras(), 40, 32, RADIUS).unwrap()
}

/// φ of a sphere of radius 0.5, soft: sigmoid(12 (0.5 − |p|)), plus a ripple so that φ values
/// are distinct (no ties for max).
fn sphere_phi(points: &[[f32; 4]]) -> Vec<f32> {
    points
        .iter()
        .map(|p| {
            let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            let r = (x * x + y * y + z * z).sqrt();
            let f = 12.0 * (RADIUS - r) + 0.4 * (9.0 * x).sin() * (7.0 * y + 3.0 * z).cos();
            (1.0 / (1.0 + (-f).exp())) as f32
        })
        .collect()
}

struct Iteration {
    rays: Vec<Ray>,
    anchors: Vec<[f32; 4]>,
    candidates: Vec<[f32; 4]>,
}

fn sample(ctx: &Context, sampler: &Sampler, gpu: &GpuTargets, iteration: u32) -> Iteration {
    ctx.submit_and_wait(|rec| sampler.record(rec, gpu, iteration))
        .unwrap();
    let s = sampler.settings();
    Iteration {
        rays: ctx
            .read_buffer(sampler.rays(), 0, sampler.ray_count() as usize)
            .unwrap(),
        anchors: ctx
            .read_buffer(sampler.anchors(), 0, s.anchors as usize)
            .unwrap(),
        candidates: ctx
            .read_buffer(sampler.candidates(), 0, s.geo_candidates as usize)
            .unwrap(),
    }
}

fn bits<T: bytemuck::Pod>(v: &[T]) -> Vec<u32> {
    bytemuck::cast_slice::<T, u32>(v).to_vec()
}

#[test]
fn gpu_sampling_equals_the_twin_and_repeats_for_a_seed() {
    let Some(ctx) = common::gpu() else { return };
    let t = targets();
    let gpu = GpuTargets::new(&ctx, &t).unwrap();
    let s = settings(Aggregate::Max);
    let sampler = Sampler::new(&ctx, &t, &gpu, &s).unwrap();
    assert!(sampler.boundary_points().len() > 100);

    // The GPU scan's CDF is the twin's prefix sum of the same integer weights, with the total
    // after it.
    let (weights, quantum) = sampler_cpu::contour_weights(&t, s.contour_sigma).unwrap();
    assert_eq!(quantum, sampler.quantum());
    let n = weights.len() + 1;
    let cdf: Vec<u32> = ctx.read_buffer(sampler.cdf(), 0, n).unwrap();
    assert_eq!(cdf, sampler_cpu::exclusive_prefix(&weights));
    assert_eq!(cdf[n - 1], weights.iter().sum::<u32>());

    let mut first = None;
    for iteration in [0, 7] {
        let got = sample(&ctx, &sampler, &gpu, iteration);
        let want = sampler_cpu::sample(&t, &s, sampler.boundary_points(), iteration).unwrap();
        assert_eq!(
            bits(&got.rays),
            bits(&want.rays),
            "rays, iteration {iteration}"
        );
        for (what, g, w, uniform) in [
            (
                "anchors",
                &got.anchors,
                &want.anchors,
                sampler.anchor_push(iteration).uniform_count,
            ),
            (
                "candidates",
                &got.candidates,
                &want.candidates,
                sampler.candidate_push(iteration).uniform_count,
            ),
        ] {
            assert_eq!(g.len(), w.len());
            for (i, (a, b)) in g.iter().zip(w).enumerate() {
                if (i as u32) < uniform {
                    assert_eq!(bits(a), bits(b), "{what} {i} (uniform): {a:?} vs {b:?}");
                } else {
                    let d = (0..4).map(|k| (a[k] - b[k]).abs()).fold(0.0, f32::max);
                    assert!(d <= 1e-6, "{what} {i}: {a:?} vs {b:?}");
                }
            }
        }
        match &first {
            None => first = Some(got),
            Some(f) => {
                assert_ne!(bits(&f.rays), bits(&got.rays), "iterations differ");
                assert_ne!(bits(&f.anchors), bits(&got.anchors), "iterations differ");
            }
        }
    }
    // Iteration 0 again: the same bits.
    let again = sample(&ctx, &sampler, &gpu, 0);
    let f = first.unwrap();
    assert_eq!(bits(&again.rays), bits(&f.rays));
    assert_eq!(bits(&again.anchors), bits(&f.anchors));
    assert_eq!(bits(&again.candidates), bits(&f.candidates));

    // Contour sampling put most non-uniform rays where the label changes nearby, and the
    // near-hull anchors near the sphere.
    let near = f
        .anchors
        .iter()
        .skip(sampler.anchor_push(0).uniform_count as usize)
        .filter(|a| {
            let r = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            (r - RADIUS as f32).abs() < 0.3
        })
        .count();
    assert!(near * 10 > 9 * (768 - 192), "{near}");
}

struct Probe {
    ctx: common::Gpu,
    targets: Targets,
    gpu: GpuTargets,
    it: Iteration,
    anchors: Buffer,
    rays: Buffer,
    phi_host: Vec<f32>,
    phi: Buffer,
}

fn probe_setup() -> Option<Probe> {
    let ctx = common::gpu()?;
    let targets = targets();
    let gpu = GpuTargets::new(&ctx, &targets).unwrap();
    let sampler = Sampler::new(&ctx, &targets, &gpu, &settings(Aggregate::Max)).unwrap();
    let it = sample(&ctx, &sampler, &gpu, 3);
    let anchors = ctx.upload_buffer("test anchors", &it.anchors).unwrap();
    let rays = ctx.upload_buffer("test rays", &it.rays).unwrap();
    let phi_host = sphere_phi(&it.anchors);
    let phi = ctx.upload_buffer("test phi", &phi_host).unwrap();
    drop(sampler);
    Some(Probe {
        ctx,
        targets,
        gpu,
        it,
        anchors,
        rays,
        phi_host,
        phi,
    })
}

fn run(p: &Probe, s: &ProbeSettings, brute: bool) -> ProbeRun {
    let mut prober = Prober::new(&p.ctx, &p.gpu, s).unwrap();
    prober
        .run(&p.ctx, &p.gpu, &p.anchors, &p.phi, &p.rays, brute)
        .unwrap()
}

fn max_abs(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, |m, x| m.max(x.abs()))
}

#[test]
fn probing_forward_and_backward_match_the_twin_for_every_aggregate() {
    let Some(p) = probe_setup() else { return };
    let phi64: Vec<f64> = p.phi_host.iter().map(|&x| f64::from(x)).collect();
    // Every aggregate with one radius, and max and LSE (the two backward paths) with a larger
    // radius for the rays outside the silhouettes.
    let cases = [Aggregate::Max, Aggregate::LogSumExp, Aggregate::Union]
        .map(settings)
        .into_iter()
        .chain(
            [Aggregate::Max, Aggregate::LogSumExp].map(|a| ProbeSettings {
                tau_outside: Some(0.12),
                ..settings(a)
            }),
        );
    for s in cases {
        let aggregate = s.aggregate;
        let got = run(&p, &s, false);
        let want = probe_cpu::forward(&p.targets, &s, &p.it.anchors, &phi64, &p.it.rays);
        // The binning: as many (anchor, tile) entries as the twin's boxes give (a box a
        // fraction of a pixel off changes the count); the boxes hold the larger radius.
        let grid = softvk::primitives::binning::TileGrid::new(40, 32, s.tile_size).unwrap();
        let box_tau = s.tau.max(s.tau_outside.unwrap_or(s.tau));
        let twin_entries: u64 = probe_cpu::items(&p.targets, box_tau, &p.it.anchors)
            .iter()
            .filter(|item| item.flags & softvk::probe::prober::FLAG_VALID != 0)
            .filter_map(|item| softvk::primitives::binning::cpu::tile_rect(item.screen_box, &grid))
            .map(|r| u64::from((r[2] - r[0] + 1) * (r[3] - r[1] + 1)))
            .sum();
        assert_eq!(got.entries, twin_entries, "{aggregate:?}: entries");
        let hit_rays = want.hits.iter().filter(|h| !h.is_empty()).count();
        let multi = want.hits.iter().filter(|h| h.len() > 2).count();
        let n = p.it.rays.len();
        assert!(
            hit_rays * 3 > n && multi * 5 > n,
            "{hit_rays} {multi} of {n}"
        );
        for (i, (o, h)) in got.outs.iter().zip(&want.hits).enumerate() {
            assert_eq!(o.aux == NO_HIT, h.is_empty(), "{aggregate:?} ray {i}");
            if aggregate != Aggregate::Union && !h.is_empty() {
                let (_, g) = probe_cpu::aggregate(
                    &ProbeSettings {
                        aggregate: Aggregate::Max,
                        ..s
                    },
                    h,
                    &phi64,
                );
                let arg = h[g.iter().position(|&x| x == 1.0).unwrap()];
                assert_eq!(o.aux, arg, "{aggregate:?} ray {i}: the maximizing anchor");
            }
            let d = (f64::from(o.psi) - want.psi[i]).abs();
            assert!(
                d <= 2e-6 * (1.0 + want.psi[i].abs()),
                "{aggregate:?} ray {i}: {o:?} vs {}",
                want.psi[i]
            );
        }
        let dl = (f64::from(got.loss) - want.loss).abs();
        assert!(
            dl <= 1e-5 * want.loss,
            "{aggregate:?}: {} vs {}",
            got.loss,
            want.loss
        );

        let d_want = probe_cpu::backward(&s, &want, &phi64, &p.it.rays);
        let scale = max_abs(d_want.iter().copied());
        assert!(scale > 0.0);
        let err = max_abs(
            got.d_phi
                .iter()
                .zip(&d_want)
                .map(|(&g, &w)| f64::from(g) - w),
        );
        assert!(
            err <= 1e-3 * scale,
            "{aggregate:?}: d_phi off by {err:e} (scale {scale:e})"
        );
        let nonzero = d_want.iter().filter(|&&x| x != 0.0).count();
        assert!(
            nonzero > 20,
            "{aggregate:?}: {nonzero} anchors get a gradient"
        );
    }
}

/// A radius of its own for the outside rays changes what those rays hit and leaves the inside
/// rays exactly as they were.
#[test]
fn the_outside_radius_changes_only_the_outside_rays() {
    let Some(p) = probe_setup() else { return };
    let s = settings(Aggregate::Max);
    let one = run(&p, &s, false);
    let two = run(
        &p,
        &ProbeSettings {
            tau_outside: Some(0.12),
            ..s
        },
        false,
    );
    let (mut inside, mut changed) = (0, 0);
    for (i, r) in p.it.rays.iter().enumerate() {
        if r.label >= 0.5 {
            inside += 1;
            assert_eq!(
                bits(&[one.outs[i]]),
                bits(&[two.outs[i]]),
                "inside ray {i} changed"
            );
        } else if bits(&[one.outs[i]]) != bits(&[two.outs[i]]) {
            changed += 1;
        }
    }
    assert!(
        inside > 20 && changed > 20,
        "{inside} inside rays, {changed} outside rays changed"
    );
}

#[test]
fn tiled_probing_equals_the_brute_force_loop_for_every_tile_size() {
    let Some(p) = probe_setup() else { return };
    let cases = [Aggregate::Max, Aggregate::LogSumExp, Aggregate::Union]
        .map(settings)
        .into_iter()
        .chain([ProbeSettings {
            tau_outside: Some(0.12),
            ..settings(Aggregate::LogSumExp)
        }]);
    for s in cases {
        let aggregate = s.aggregate;
        let brute = run(&p, &s, true);
        for tile_size in [4, 8, 16, 40] {
            let tiled = run(&p, &ProbeSettings { tile_size, ..s }, false);
            assert_eq!(
                bits::<RayOut>(&tiled.outs),
                bits::<RayOut>(&brute.outs),
                "{aggregate:?}, tile {tile_size}"
            );
            assert_eq!(tiled.loss.to_bits(), brute.loss.to_bits());
            // The gradient's partial sums follow the tiles: bit-identical on the same tiles
            // (the brute-force forward was backed by 8-pixel tiles), within rounding otherwise.
            if tile_size == s.tile_size {
                assert_eq!(bits(&tiled.d_phi), bits(&brute.d_phi));
            } else {
                let scale = max_abs(brute.d_phi.iter().map(|&x| f64::from(x)));
                let err = max_abs(
                    tiled
                        .d_phi
                        .iter()
                        .zip(&brute.d_phi)
                        .map(|(&a, &b)| f64::from(a - b)),
                );
                assert!(
                    err <= 1e-5 * scale,
                    "{aggregate:?}, tile {tile_size}: {err:e}"
                );
            }
        }
    }
}

/// Central differences of the twin's loss with respect to φ at the anchors (hits fixed).
#[test]
fn twin_gradients_match_central_differences_of_the_twin_loss() {
    let t = targets();
    for aggregate in [Aggregate::Max, Aggregate::LogSumExp, Aggregate::Union] {
        let s = ProbeSettings {
            anchors: 200,
            rays_per_view: 64,
            ..settings(aggregate)
        };
        let boundary = softvk::probe::hull::boundary_points(&t, &s);
        let it = sampler_cpu::sample(&t, &s, &boundary, 1).unwrap();
        let phi: Vec<f64> = sphere_phi(&it.anchors)
            .iter()
            .map(|&x| f64::from(x))
            .collect();
        let fwd = probe_cpu::forward(&t, &s, &it.anchors, &phi, &it.rays);
        let grad = probe_cpu::backward(&s, &fwd, &phi, &it.rays);
        let scale = max_abs(grad.iter().copied());
        assert!(scale > 0.0);
        let h = 1e-6;
        let mut x = phi.clone();
        for j in 0..phi.len() {
            x[j] = phi[j] + h;
            let up = probe_cpu::loss(&s, &fwd.hits, &x, &it.rays);
            x[j] = phi[j] - h;
            let down = probe_cpu::loss(&s, &fwd.hits, &x, &it.rays);
            x[j] = phi[j];
            let fd = (up - down) / (2.0 * h);
            assert!(
                (fd - grad[j]).abs() <= 1e-6 * scale,
                "{aggregate:?} anchor {j}: fd {fd:e} vs {:e}",
                grad[j]
            );
        }
    }
}

#[test]
fn boundary_aware_assignment_skips_anchors_across_the_silhouette() {
    let Some(ctx) = common::gpu() else { return };
    // One view of 32×32; the silhouette is the left half (columns 0..16).
    let camera = Camera::default();
    let (w, h) = (32u32, 32u32);
    let masks: Vec<f32> = (0..w * h)
        .map(|i| if i % w < 16 { 1.0 } else { 0.0 })
        .collect();
    let t = Targets::new(&[camera], w, h, masks).unwrap();
    let gpu = GpuTargets::new(&ctx, &t).unwrap();
    // The anchor projects to x_s = 3/32, into column 17 (outside); rays at columns 15.5
    // (inside, label 1) and 19.5 (outside, label 0) pass 4/32 screen units from it, about 0.2
    // world units at its depth, within τ = 0.3.
    let Projection::Perspective { viewing_angle_deg } = camera.projection else {
        unreachable!()
    };
    let x = 3.0 / 32.0 * viewing_angle_deg.to_radians().tan() * 2.732;
    let anchors = [[x as f32, 0.0, 0.0, 1.0]];
    let rays = [
        Ray {
            px: 15.5,
            py: 16.0,
            view: 0,
            label: 1.0,
        },
        Ray {
            px: 19.5,
            py: 16.0,
            view: 0,
            label: 0.0,
        },
    ];
    let phi = [0.8f32];
    let a = ctx.upload_buffer("anchor", &anchors).unwrap();
    let r = ctx.upload_buffer("rays", &rays).unwrap();
    let f = ctx.upload_buffer("phi", &phi).unwrap();
    let items = probe_cpu::items(&t, 0.3, &anchors);
    assert_eq!(
        items[0].flags,
        softvk::probe::prober::FLAG_VALID,
        "outside, valid"
    );
    for aware in [true, false] {
        let s = ProbeSettings {
            anchors: 1,
            rays_per_view: 2,
            tau: 0.3,
            tile_size: 8,
            boundary_aware: aware,
            ..ProbeSettings::default()
        };
        let mut prober = Prober::new(&ctx, &gpu, &s).unwrap();
        let got = prober.run(&ctx, &gpu, &a, &f, &r, false).unwrap();
        let twin = probe_cpu::forward(&t, &s, &anchors, &[0.8], &rays);
        let psi: Vec<f32> = got.outs.iter().map(|o| o.psi).collect();
        // Without the assignment both rays see the anchor; with it, the inside ray does not.
        let want = if aware { [0.0, 0.8] } else { [0.8, 0.8] };
        assert_eq!(psi, want.map(|x| x as f32), "boundary-aware {aware}");
        assert_eq!(twin.psi, want, "twin, boundary-aware {aware}");
        // dL/dφ = (2 / 2) Σ (ψ − S): the inside ray's error ψ − 1 only counts when it may use
        // the anchor.
        let d = probe_cpu::backward(&s, &twin, &[0.8], &rays)[0];
        assert!(
            (f64::from(got.d_phi[0]) - d).abs() <= 1e-6,
            "{} vs {d}",
            got.d_phi[0]
        );
        let expected = if aware {
            2.0 * 0.8 / 2.0
        } else {
            2.0 * (0.8 - 1.0) / 2.0 + 2.0 * 0.8 / 2.0
        };
        assert!((d - expected).abs() < 1e-6, "{d} vs {expected}");
    }
}

#[test]
fn geo_regularizer_matches_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    let t = targets();
    let gpu = GpuTargets::new(&ctx, &t).unwrap();
    let s = settings(Aggregate::Max);
    let sampler = Sampler::new(&ctx, &t, &gpu, &s).unwrap();
    let geo = GeoRegularizer::new(&ctx, &s).unwrap();
    ctx.submit_and_wait(|rec| {
        sampler.record(rec, &gpu, 5)?;
        geo.record_points(rec, sampler.candidates().whole())
    })
    .unwrap();
    let cands: Vec<[f32; 4]> = ctx
        .read_buffer(sampler.candidates(), 0, s.geo_candidates as usize)
        .unwrap();
    let points: Vec<[f32; 4]> = ctx
        .read_buffer(geo.points(), 0, geo.point_count() as usize)
        .unwrap();
    let want_points = geo::cpu::points(&cands, s.geo_delta, s.geo_normal_delta);
    assert_eq!(bits(&points), bits(&want_points));

    let phi = sphere_phi(&points);
    let phi_buf = ctx.upload_buffer("geo phi", &phi).unwrap();
    let lambda = 0.3f32;
    // Accumulate onto a buffer of ones: d = 1 + λ dL/dφ.
    let d_buf = ctx
        .upload_buffer("geo d_phi", &vec![1f32; phi.len()])
        .unwrap();
    ctx.submit_and_wait(|rec| {
        geo.record_loss(
            rec,
            phi_buf.whole(),
            Some(GradOut::accumulate(d_buf.whole(), lambda)),
        )
    })
    .unwrap();
    let loss = geo.read_loss(&ctx).unwrap();
    let d: Vec<f32> = ctx.read_buffer(&d_buf, 0, phi.len()).unwrap();
    let phi64: Vec<f64> = phi.iter().map(|&x| f64::from(x)).collect();
    let (want_loss, want_d) = geo::cpu::loss(&s, &phi64);
    assert!(want_loss > 0.0, "a loss of 0 checks nothing");
    assert!(
        (f64::from(loss) - want_loss).abs() <= 1e-4 * want_loss,
        "{loss} vs {want_loss}"
    );
    let scale = max_abs(want_d.iter().copied()) * f64::from(lambda);
    assert!(scale > 0.0);
    let err = max_abs(
        d.iter()
            .zip(&want_d)
            .map(|(&g, &w)| f64::from(g) - 1.0 - f64::from(lambda) * w),
    );
    assert!(
        err <= 1e-3 * scale,
        "d_phi off by {err:e} (scale {scale:e})"
    );

    // The loss alone, without a gradient, is the same loss.
    ctx.submit_and_wait(|rec| geo.record_loss(rec, phi_buf.whole(), None))
        .unwrap();
    assert_eq!(geo.read_loss(&ctx).unwrap().to_bits(), loss.to_bits());
}

/// One whole iteration as the glue records it: two submissions.
fn whole_iteration(ctx: &Context, t: &Targets, s: &ProbeSettings) -> Vec<Vec<u32>> {
    let gpu = GpuTargets::new(ctx, t).unwrap();
    let sampler = Sampler::new(ctx, t, &gpu, s).unwrap();
    let mut prober = Prober::new(ctx, &gpu, s).unwrap();
    let geo = GeoRegularizer::new(ctx, s).unwrap();
    ctx.submit_and_wait(|rec| {
        sampler.record(rec, &gpu, 11)?;
        geo.record_points(rec, sampler.candidates().whole())?;
        prober.record_count(rec, &gpu, sampler.anchors().whole())
    })
    .unwrap();
    prober.finish_count(ctx).unwrap();
    // The "field": φ of the sphere, evaluated on the host.
    let anchors: Vec<[f32; 4]> = ctx
        .read_buffer(sampler.anchors(), 0, s.anchors as usize)
        .unwrap();
    let points: Vec<[f32; 4]> = ctx
        .read_buffer(geo.points(), 0, geo.point_count() as usize)
        .unwrap();
    let phi_a = ctx.upload_buffer("phi a", &sphere_phi(&anchors)).unwrap();
    let phi_g = ctx.upload_buffer("phi g", &sphere_phi(&points)).unwrap();
    let d_a = ctx
        .create_buffer("d a", 4 * u64::from(s.anchors), MemoryKind::Device)
        .unwrap();
    let d_g = ctx
        .create_buffer("d g", 4 * geo.point_count(), MemoryKind::Device)
        .unwrap();
    ctx.submit_and_wait(|rec| {
        let (a, r) = (sampler.anchors().whole(), sampler.rays().whole());
        prober.record_forward(rec, &gpu, a, phi_a.whole(), r)?;
        prober.record_backward(rec, &gpu, a, phi_a.whole(), r, GradOut::write(d_a.whole()))?;
        geo.record_loss(
            rec,
            phi_g.whole(),
            Some(GradOut::write(d_g.whole()).weighted(s.geo_lambda as f32)),
        )
    })
    .unwrap();
    let read = |b: &Buffer, n: usize| -> Vec<u32> { ctx.read_buffer(b, 0, n).unwrap() };
    vec![
        read(sampler.rays(), 4 * sampler.ray_count() as usize),
        read(prober.outputs(), 4 * sampler.ray_count() as usize),
        read(prober.loss_buffer(), 1),
        read(&d_a, s.anchors as usize),
        read(geo.loss_buffer(), 1),
        read(&d_g, geo.point_count() as usize),
    ]
}

#[test]
fn repeated_iterations_are_bit_identical() {
    let Some(ctx) = common::gpu() else { return };
    let t = targets();
    for aggregate in [Aggregate::Max, Aggregate::Union] {
        let s = settings(aggregate);
        let first = whole_iteration(&ctx, &t, &s);
        let second = whole_iteration(&ctx, &t, &s);
        assert_eq!(first, second, "{aggregate:?}");
        assert!(first[3].iter().any(|&x| x != 0), "some anchor gradient");
        assert!(first[5].iter().any(|&x| x != 0), "some geo gradient");
    }
}

#[test]
fn loop_caps_and_bad_inputs_are_clear_errors() {
    let Some(ctx) = common::gpu() else { return };
    let t = targets();
    let gpu = GpuTargets::new(&ctx, &t).unwrap();
    if let Some(limit) = ctx.info().shader_loop_limit() {
        // More rays per view than a backward invocation may loop over.
        let s = ProbeSettings {
            rays_per_view: limit as u32 + 1,
            ..settings(Aggregate::Max)
        };
        let loop_cap = |e: &softvk::Result<_>| {
            matches!(
                e,
                Err(Error::DeviceLimit {
                    kind: LimitKind::LoopIterations,
                    ..
                })
            )
        };
        assert!(loop_cap(&Prober::new(&ctx, &gpu, &s).map(|_| ())));
        // (More anchors than a forward loop may visit are folded in passes:
        // `over_200k_anchors_in_one_tile_probe_as_the_twin`.)
    }
    // Buffers too small for the settings' counts.
    let s = settings(Aggregate::Max);
    let prober = Prober::new(&ctx, &gpu, &s).unwrap();
    let small = ctx.create_buffer("small", 64, MemoryKind::Device).unwrap();
    let e = ctx.submit_and_wait(|rec| prober.record_count(rec, &gpu, small.whole()));
    assert!(matches!(e, Err(Error::Input(_))), "{e:?}");
    // Settings out of range, and a camera probing cannot follow.
    let bad = ProbeSettings {
        tau: -1.0,
        ..settings(Aggregate::Max)
    };
    assert!(matches!(
        Prober::new(&ctx, &gpu, &bad),
        Err(Error::Input(_))
    ));
    let mut cams = cameras();
    cams[1].projection = Projection::Matrix {
        p: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 3.0],
        ],
        dist_coeffs: [0.01, 0.0, 0.0, 0.0, 0.0],
        orig_size: 2.0,
    };
    let e = Targets::new(&cams, 40, 32, vec![0.0; 3 * 40 * 32]);
    assert!(
        matches!(e, Err(Error::Input(ref m)) if m.contains("view 1")),
        "{e:?}"
    );
}

/// One tile holding more anchors than llvmpipe lets one shader invocation loop over (65 535
/// iterations): 204 800 anchors in a ball of radius 0.3 about the origin, which every view sees
/// in the first of its two 32-pixel tiles. The tile's list and the forward over it are folded in
/// passes, as is brute force's loop over every anchor; both give the same ψ bit for bit, and the
/// twin's ψ, loss and dL/dφ.
#[test]
fn over_200k_anchors_in_one_tile_probe_as_the_twin() {
    let Some(p) = probe_setup() else { return };
    const N: usize = 204_800;
    let mut rng = common::rng(71);
    let anchors: Vec<[f32; 4]> = (0..N)
        .map(|_| {
            loop {
                let v: [f32; 3] = std::array::from_fn(|_| rng.random_range(-0.3f32..0.3));
                if v.iter().map(|c| c * c).sum::<f32>() < 0.09 {
                    break [v[0], v[1], v[2], 0.0];
                }
            }
        })
        .collect();
    let phi_host = sphere_phi(&anchors);
    let phi64: Vec<f64> = phi_host.iter().map(|&x| f64::from(x)).collect();
    let s = ProbeSettings {
        anchors: N as u32,
        tau: 0.02,
        tile_size: 32,
        ..settings(Aggregate::LogSumExp)
    };
    let anchor_buf = p.ctx.upload_buffer("crowded anchors", &anchors).unwrap();
    let phi = p.ctx.upload_buffer("crowded phi", &phi_host).unwrap();
    let mut prober = Prober::new(&p.ctx, &p.gpu, &s).unwrap();
    let tiled = prober
        .run(&p.ctx, &p.gpu, &anchor_buf, &phi, &p.rays, false)
        .unwrap();
    assert!(tiled.entries >= 3 * N as u64 * 9 / 10, "{}", tiled.entries);
    let brute = prober
        .run(&p.ctx, &p.gpu, &anchor_buf, &phi, &p.rays, true)
        .unwrap();
    assert_eq!(bits(&tiled.outs), bits(&brute.outs));

    let want = probe_cpu::forward(&p.targets, &s, &anchors, &phi64, &p.it.rays);
    let hit_rays = want.hits.iter().filter(|h| h.len() > 100).count();
    assert!(hit_rays >= 3, "{hit_rays} rays hit over 100 anchors");
    for (i, o) in tiled.outs.iter().enumerate() {
        let d = (f64::from(o.psi) - want.psi[i]).abs();
        assert!(
            d <= 2e-6 * (1.0 + want.psi[i].abs()),
            "ray {i}: {o:?} vs {}",
            want.psi[i]
        );
    }
    assert!((f64::from(tiled.loss) - want.loss).abs() <= 1e-5 * want.loss);
    // dL/dφ of every anchor (59 391 of them nonzero), each held to its own size: `|got − want|
    // ≤ rel |want| + floor · largest`. Measured: the worst component is off by 2.1e-6 of itself
    // (an anchor whose dL/dφ is 5e-3 of the largest), a sixth of these bars; a bound by 1e-3 of
    // the largest alone would leave every component below that unchecked.
    let d_want = probe_cpu::backward(&s, &want, &phi64, &p.it.rays);
    let scale = max_abs(d_want.iter().copied());
    assert!(scale > 0.0);
    let (rel, floor) = (1e-5, 1e-8);
    let mut worst = (0.0f64, 0usize);
    let mut nonzero = 0;
    for (i, (&g, &w)) in tiled.d_phi.iter().zip(&d_want).enumerate() {
        nonzero += usize::from(w != 0.0);
        let share = (f64::from(g) - w).abs() / (rel * w.abs() + floor * scale);
        if share > worst.0 {
            worst = (share, i);
        }
    }
    assert!(nonzero > N / 10, "{nonzero} anchors with a gradient");
    let i = worst.1;
    assert!(
        worst.0 <= 1.0,
        "dL/dφ of anchor {i}: {} against the twin's {} (largest {scale:e})",
        tiled.d_phi[i],
        d_want[i]
    );
}

/// Guarded probing (the field fit's: the count stays on the GPU) over a capacity: one
/// submission, gated on the count.
fn run_guarded(
    p: &Probe,
    s: &ProbeSettings,
    capacity: u64,
) -> (Vec<RayOut>, f32, Vec<f32>, GateStatus) {
    let ctx = &p.ctx;
    let mut prober = Prober::new(ctx, &p.gpu, s).unwrap();
    prober.reserve_guarded(ctx, capacity).unwrap();
    assert_eq!(prober.entry_capacity(), capacity);
    let mut gate = IterationGate::new(ctx).unwrap();
    let n = p.it.anchors.len();
    // A sentinel that any gradient written would replace.
    let d_phi = ctx.upload_buffer("test d_phi", &vec![7.0f32; n]).unwrap();
    ctx.submit_and_wait(|rec| {
        gate.reset();
        prober.record_guarded(rec, &mut gate, 1, &p.gpu, p.anchors.whole(), |rec| {
            prober.record_forward(
                rec,
                &p.gpu,
                p.anchors.whole(),
                p.phi.whole(),
                p.rays.whole(),
            )?;
            prober.record_backward(
                rec,
                &p.gpu,
                p.anchors.whole(),
                p.phi.whole(),
                p.rays.whole(),
                GradOut::write(d_phi.whole()),
            )
        })
    })
    .unwrap();
    let outs = if gate.read(ctx).unwrap().stopped.is_none() {
        prober.read_outputs(ctx).unwrap()
    } else {
        Vec::new()
    };
    (
        outs,
        prober.read_loss(ctx).unwrap(),
        ctx.read_buffer(&d_phi, 0, n).unwrap(),
        gate.read(ctx).unwrap(),
    )
}

#[test]
fn guarded_probing_gives_the_exact_runs_bits_or_stops_untouched() {
    let Some(p) = probe_setup() else { return };
    for aggregate in [Aggregate::Max, Aggregate::LogSumExp, Aggregate::Union] {
        let s = settings(aggregate);
        let exact = run(&p, &s, false);
        let entries = exact.entries;
        assert!(entries > 1);
        // A capacity that the count fills exactly, and one with room to spare (the kernels
        // then read the count on the GPU): the exact run's outputs, loss and gradient.
        for capacity in [entries, 3 * entries] {
            let (outs, loss, d_phi, status) = run_guarded(&p, &s, capacity);
            assert_eq!(status.stopped, None, "{aggregate:?}, capacity {capacity}");
            assert_eq!(status.last_total, entries);
            assert_eq!(
                bits(&outs),
                bits(&exact.outs),
                "{aggregate:?}, capacity {capacity}"
            );
            assert_eq!(loss.to_bits(), exact.loss.to_bits());
            assert_eq!(
                bits(&d_phi),
                bits(&exact.d_phi),
                "{aggregate:?}, capacity {capacity}"
            );
        }
        // One entry short: the gate stops the iteration, which writes nothing.
        let (_, _, d_phi, status) = run_guarded(&p, &s, entries - 1);
        assert_eq!(status.stopped, Some((1, entries)), "{aggregate:?}");
        assert!(d_phi.iter().all(|&x| x == 7.0), "{aggregate:?}");
    }
}

/// The binning's screen box of an anchor (the sphere's extent on each screen axis within its
/// τ-cube's corner box, `probe_items.comp` and its twin) is conservative: every continuous pixel
/// position whose ray passes within τ of the anchor (the forward's own f32 hit test) lies in a
/// tile of the box's rectangle. Perspective views near and far and an orthographic one, anchors
/// all over the cube, two τ; rays at 4 × 4 positions per pixel, edges included. A box too tight
/// by a fraction of a pixel loses rays here (and the tiled forward would then differ from brute
/// force).
#[test]
fn anchor_boxes_hold_every_ray_that_can_hit_the_anchor() {
    use rand::RngExt;
    use softvk::primitives::binning::{TileGrid, cpu::tile_rect};
    let cameras = vec![
        Camera::from_angles(2.732, 30.0, 100.0),
        Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 40.0,
            },
            ..Camera::from_angles(1.9, -20.0, 35.0)
        },
        Camera {
            projection: Projection::Orthographic { scale: 0.8 },
            ..Camera::from_angles(3.0, 10.0, 250.0)
        },
    ];
    let (w, h) = (40u32, 32u32);
    let t = sphere_silhouettes(&cameras, w, h, RADIUS).unwrap();
    let grid = TileGrid::new(w, h, 8).unwrap();
    let inv_s = (1.0 / f64::from(w.min(h))) as f32;
    let mut rng = common::rng(17);
    let anchors: Vec<[f32; 4]> = (0..300)
        .map(|_| {
            let mut c = || rng.random_range(-1.0..1.0f32);
            [c(), c(), c(), 1.0]
        })
        .collect();
    let sub = [0.0f32, 0.3, 0.6, 0.999];
    for tau in [0.08f32, 0.3] {
        let items = probe_cpu::items(&t, f64::from(tau), &anchors);
        let mut hits = 0usize;
        for (k, view) in t.views.iter().enumerate() {
            let tiles_per_view = grid.tiles_x * grid.tiles_y;
            for (j, a) in anchors.iter().enumerate() {
                let item = &items[k * anchors.len() + j];
                if item.flags & softvk::probe::prober::FLAG_VALID == 0 {
                    continue;
                }
                let rect = tile_rect(item.screen_box, &grid);
                for row in 0..h {
                    for col in 0..w {
                        for dy in sub {
                            for dx in sub {
                                let ray = Ray {
                                    px: col as f32 + dx,
                                    py: row as f32 + dy,
                                    view: k as u32,
                                    label: 0.0,
                                };
                                let (o, d) = probe_cpu::ray_line(view, &ray, w, h, inv_s);
                                let bound = probe_cpu::hit_bound(d, tau * tau);
                                if !probe_cpu::ray_hits(o, d, bound, [a[0], a[1], a[2]]) {
                                    continue;
                                }
                                hits += 1;
                                let tile =
                                    probe_cpu::ray_tile(&ray, &grid) - k as u32 * tiles_per_view;
                                let (tx, ty) = (tile % grid.tiles_x, tile / grid.tiles_x);
                                let inside = rect.is_some_and(|r| {
                                    (r[0]..=r[2]).contains(&tx) && (r[1]..=r[3]).contains(&ty)
                                });
                                assert!(
                                    inside,
                                    "view {k}, anchor {a:?}, tau {tau}: the ray at ({}, {}) hits \
                                     it in tile ({tx}, {ty}) outside the box's tiles {rect:?} (box \
                                     {:?})",
                                    ray.px, ray.py, item.screen_box
                                );
                            }
                        }
                    }
                }
            }
        }
        assert!(
            hits > 10_000,
            "tau {tau}: only {hits} hits; the test proves little"
        );
    }
}
