//! The pose study: from random initial rotations more than 60° from the target, the
//! fraction of `fit_pose` runs that end within 5° of it, with the σ/γ schedule and without it
//! (every iteration sharp), on the same iteration budget.
//!
//! Spot (`$SOFTVK_ASSETS/spot_triangulated.obj`, its texture sampled at `--texture-res`) is
//! rendered at a fixed target pose (SoftRas's default lighting and sharp σ/γ); each trial draws a
//! uniformly random rotation, rejected unless its geodesic angle to the target exceeds
//! `--min-angle`, starts at zero translation, and fits rotation and translation from it, once per
//! mode. The error is the geodesic angle between the fitted and the target rotation.
//!
//! Modes (`--modes a,b,...`):
//! - `sharp`: every iteration at the sharp σ/γ (`fit-pose --no-schedule`);
//! - `schedule`: the σ/γ schedule against the one sharp target (`fit-pose`'s default: what a
//!   user with a photograph can do);
//! - `rendered`: the same schedule, with the target re-rendered at every stage's σ/γ from the
//!   known target pose (possible only in a synthetic study: the loss landscape of the talk,
//!   where both images are equally soft).
//!
//! `schedule` and `rendered` take the schedule's start from `--sigma-start`/`--gamma-start`, or
//! from a suffix `@σ/γ` (`schedule@1e-3/1e-3`), so one run can compare several starts.
//!
//! `--starts K` fits each trial from K starts spread over the rotations, the trial's own first,
//! and keeps the lowest final loss (`fit-pose --starts K`); its seconds are all starts'.
//!
//! Run: `cargo run --release --example pose_study -- --trials 20` (`--help` lists the knobs).
//! Results: RESULTS.md, "Pose estimation".

use std::time::Instant;

use glam::{DQuat, DVec3};
use rand::{RngExt, SeedableRng};
use softvk::camera::Camera;
use softvk::fit::pose::{
    Pose, PoseFitOptions, PoseTarget, Refine, Schedule, fit_pose_multistart, rotation_distance,
    screened_starts,
};
use softvk::gpu::{Context, ContextOptions};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::RasterSettings;

struct Args {
    trials: u32,
    size: u32,
    iterations: u32,
    texture_res: u32,
    seed: u64,
    min_angle: f64,
    max_angle: f64,
    success: f64,
    starts: u32,
    candidates: u32,
    modes: Vec<String>,
    verbose: bool,
    opts: PoseFitOptions,
    schedule: Schedule,
}

const HELP: &str = "pose_study [--trials N] [--size N] [--iters N] [--texture-res R] [--seed S]
  [--min-angle DEG] [--max-angle DEG] [--success DEG] [--starts K] [--candidates N] [--modes sharp,schedule[@S/G],rendered[@S/G]]
  [--sigma-start S]
  [--gamma-start G] [--stages N] [--sigma S] [--gamma G] [--lr LR] [--lr-translation LR]
  [--lr-final F] [--tile N] [--refine N --window W --improvement X | --no-refine] [--verbose]";

fn parse() -> Args {
    let defaults = PoseFitOptions::default();
    let mut a = Args {
        trials: 20,
        size: defaults.settings.width,
        iterations: defaults.iterations,
        texture_res: 4,
        seed: 5,
        min_angle: 60.0,
        max_angle: 180.0,
        success: 5.0,
        starts: 1,
        candidates: 0,
        modes: vec!["schedule".into(), "sharp".into()],
        verbose: false,
        opts: defaults,
        schedule: Schedule::default(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| panic!("{flag} needs a value"));
        let num = |s: String| -> f64 { s.parse().unwrap_or_else(|_| panic!("bad number {s}")) };
        match flag.as_str() {
            "--trials" => a.trials = num(value()) as u32,
            "--size" => a.size = num(value()) as u32,
            "--iters" => a.iterations = num(value()) as u32,
            "--texture-res" => a.texture_res = num(value()) as u32,
            "--seed" => a.seed = num(value()) as u64,
            "--min-angle" => a.min_angle = num(value()),
            "--max-angle" => a.max_angle = num(value()),
            "--success" => a.success = num(value()),
            "--starts" => a.starts = (num(value()) as u32).max(1),
            "--candidates" => a.candidates = num(value()) as u32,
            "--modes" => {
                a.modes = value().split(',').map(str::to_owned).collect();
                for m in &a.modes {
                    let name = m.split('@').next().unwrap_or_default();
                    assert!(
                        ["sharp", "schedule", "rendered"].contains(&name),
                        "unknown mode {m}"
                    );
                }
            }
            "--sigma-start" => a.schedule.sigma_start = num(value()),
            "--gamma-start" => a.schedule.gamma_start = num(value()),
            "--stages" => a.schedule.stages = num(value()) as u32,
            "--sigma" => a.opts.settings.sigma = num(value()),
            "--gamma" => a.opts.settings.gamma = num(value()),
            "--lr" => a.opts.lr_rotation = num(value()),
            "--lr-translation" => a.opts.lr_translation = num(value()),
            "--lr-final" => a.opts.lr_final = num(value()),
            "--tile" => a.opts.tile = num(value()) as u32,
            "--refine" => {
                a.opts.refine.get_or_insert_with(Refine::default).iterations = num(value()) as u32
            }
            "--window" => {
                a.opts.refine.get_or_insert_with(Refine::default).window = num(value()) as u32
            }
            "--improvement" => {
                a.opts
                    .refine
                    .get_or_insert_with(Refine::default)
                    .min_improvement = num(value())
            }
            "--no-refine" => a.opts.refine = None,
            "--verbose" => a.verbose = true,
            "--help" | "-h" => {
                println!("{HELP}");
                std::process::exit(0);
            }
            f => panic!("unknown flag {f}\n{HELP}"),
        }
    }
    a.opts.iterations = a.iterations;
    a.opts.settings.width = a.size;
    a.opts.settings.height = a.size;
    a
}

/// A uniformly random rotation (Shoemake's method) as an axis-angle vector.
fn random_rotation(rng: &mut rand_pcg::Pcg64) -> DVec3 {
    let (u1, u2, u3): (f64, f64, f64) = (
        rng.random_range(0.0..1.0),
        rng.random_range(0.0..1.0),
        rng.random_range(0.0..1.0),
    );
    let tau = std::f64::consts::TAU;
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    let q = DQuat::from_xyzw(
        a * (tau * u2).sin(),
        a * (tau * u2).cos(),
        b * (tau * u3).sin(),
        b * (tau * u3).cos(),
    );
    q.normalize().to_scaled_axis()
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

fn main() {
    let args = parse();
    let ctx = Context::new(&ContextOptions::from_env()).expect("a Vulkan device");
    let path = softvk::assets::dir().join("spot_triangulated.obj");
    let mesh = Mesh::load_obj(&path, args.texture_res).expect("spot");
    let camera = Camera::from_angles(2.732, 20.0, -30.0);
    let lighting = Lighting::default();
    let target_pose = Pose {
        rotation: DVec3::new(0.35, -0.6, 0.25),
        translation: DVec3::new(0.05, -0.03, 0.04),
    };
    let s = args.opts.settings;
    // The target: spot at the target pose, rendered with the GPU (sharp, or at a stage's σ/γ).
    let rest = softvk::lighting::positions_f64(&mesh);
    let centre = softvk::fit::pose::centroid(&rest);
    let mut posed = mesh.clone();
    for (p, q) in posed
        .positions
        .iter_mut()
        .zip(target_pose.apply(&rest, centre))
    {
        *p = [q.x as f32, q.y as f32, q.z as f32];
    }
    let renderer = Renderer::new(&ctx).unwrap();
    let render_target = |sigma: f64, gamma: f64| {
        let settings = RasterSettings { sigma, gamma, ..s };
        renderer
            .render_views(
                &ctx,
                &posed,
                &[camera],
                &lighting,
                &settings,
                Method::Tiled { tile: 8 },
            )
            .map(|f| f.images)
    };
    let target = render_target(s.sigma, s.gamma).unwrap();

    let mut rng: rand_pcg::Pcg64 = SeedableRng::seed_from_u64(args.seed);
    let inits: Vec<DVec3> = (0..args.trials)
        .map(|_| {
            loop {
                let w = random_rotation(&mut rng);
                let angle = rotation_distance(w, target_pose.rotation).to_degrees();
                if angle > args.min_angle && angle <= args.max_angle {
                    break w;
                }
            }
        })
        .collect();

    println!(
        "spot, {0}x{0}, texture-res {1}, {2} iterations, lr {3} / {4} (decaying to ×{5}), \
         sharp σ {6:e} γ {7:e}; schedule σ {8:e} γ {9:e} in {10} stages; {11} trials in \
         ({12}°, {13}°] (seed {14}), {16} start(s) per fit; device {15}",
        s.width,
        args.texture_res,
        args.iterations,
        args.opts.lr_rotation,
        args.opts.lr_translation,
        args.opts.lr_final,
        s.sigma,
        s.gamma,
        args.schedule.sigma_start,
        args.schedule.gamma_start,
        args.schedule.stages,
        args.trials,
        args.min_angle,
        args.max_angle,
        args.seed,
        ctx.info().name,
        args.starts
    );
    println!("refinement after the schedule: {:?}", args.opts.refine);
    println!("trial,mode,init_deg,final_deg,translation_err,loss,seconds,best_start,iterations");
    let total = Instant::now();
    let mut summary = Vec::new();
    let cpu_start = cpu_seconds();
    for mode in &args.modes {
        let (name, start) = mode.split_once('@').unwrap_or((mode, ""));
        let mut schedule = args.schedule;
        if let Some((sg, gm)) = start.split_once('/') {
            schedule.sigma_start = sg.parse().expect("σ of the mode");
            schedule.gamma_start = gm.parse().expect("γ of the mode");
        }
        let opts = PoseFitOptions {
            schedule: (name != "sharp").then_some(schedule),
            ..args.opts.clone()
        };
        let mode_cpu = cpu_seconds();
        let mut errors = Vec::new();
        let mut seconds = 0.0;
        let mut iterations = 0u64;
        for (trial, init) in inits.iter().enumerate() {
            let init_pose = Pose {
                rotation: *init,
                translation: DVec3::ZERO,
            };
            let init_deg = rotation_distance(*init, target_pose.rotation).to_degrees();
            let mut per_stage = |sigma, gamma| render_target(sigma, gamma);
            let fit_target = if name == "rendered" {
                PoseTarget::PerStage(&mut per_stage)
            } else {
                PoseTarget::Fixed(&target)
            };
            let multi = fit_pose_multistart(
                &ctx,
                &mesh,
                &camera,
                &lighting,
                fit_target,
                &screened_starts(
                    &ctx,
                    &mesh,
                    &camera,
                    &lighting,
                    &target,
                    &init_pose,
                    args.starts,
                    args.candidates,
                    30f64.to_radians(),
                    &opts,
                )
                .expect("screening"),
                &opts,
                |start, l| {
                    if args.verbose && (l.iteration % 10 == 0 || l.iteration == 1) {
                        eprintln!(
                            "  {mode} trial {trial} start {start} it {:4} σ {:.1e} γ {:.1e} \
                             loss {:.5} err {:6.2}° {:.1} s",
                            l.iteration,
                            l.sigma,
                            l.gamma,
                            l.loss,
                            rotation_distance(l.pose.rotation, target_pose.rotation).to_degrees(),
                            l.seconds
                        );
                    }
                    true
                },
            )
            .expect("fit");
            let result = multi.best;
            let seconds_all: f64 = multi.starts.iter().map(|s| s.seconds).sum();
            let err = rotation_distance(result.pose.rotation, target_pose.rotation).to_degrees();
            let terr = (result.pose.translation - target_pose.translation).length();
            let its: u64 = multi.starts.iter().map(|s| u64::from(s.iterations)).sum();
            println!(
                "{trial},{mode},{init_deg:.2},{err:.3},{terr:.4},{:.6},{seconds_all:.2},{},{its}",
                result.loss, multi.best_start
            );
            errors.push(err);
            seconds += seconds_all;
            iterations += its;
        }
        ctx.check_validation().expect("no validation messages");
        let hits = errors.iter().filter(|&&e| e < args.success).count();
        summary.push(format!(
            "{mode:>8}: {hits}/{} within {}° ({:.0}%), median error {:.2}°, worst {:.2}°, {} \
             iterations, {:.1} s wall, {:.1} ms per iteration, {:.0} s CPU (process, all threads)",
            errors.len(),
            args.success,
            100.0 * hits as f64 / errors.len().max(1) as f64,
            median(&errors),
            errors.iter().copied().fold(0.0, f64::max),
            iterations,
            seconds,
            1e3 * seconds / iterations.max(1) as f64,
            cpu_seconds() - mode_cpu
        ));
    }
    for line in summary {
        println!("{line}");
    }
    println!(
        "wall {:.1} s, CPU {:.0} s",
        total.elapsed().as_secs_f64(),
        cpu_seconds() - cpu_start
    );
}

/// User + system CPU seconds of this process (all threads), from /proc/self/stat; 0 where
/// unavailable. Reported beside wall time because the study machine is shared.
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
        return 0.0;
    };
    // Fields after the command name (which may hold spaces) start after the last ')'.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of proc_pid_stat(5): indices 11 and 12 here.
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    (ticks(11) + ticks(12)) / 100.0
}
