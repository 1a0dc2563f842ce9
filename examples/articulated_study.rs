//! The basin study of `fit-articulated`: from starts whose every joint angle is off
//! by an offset in a range, the fraction of fits of the built-in figure ([`Rig::figure`]) that
//! end with every joint within `--success` degrees of the target.
//!
//! Each trial draws a target pose (every joint uniform in ±`--target-range` degrees about its
//! rest angle), renders it with the GPU (SoftRas's default lighting, sharp σ/γ), and starts
//! every joint off by a uniform offset in (lo, hi] degrees with a random sign. The target is
//! rendered at the fit's sharp σ/γ, or at `--target-sigma-gamma S/G` (1e-5/1e-4, SoftRas's
//! defaults, stand for a photograph: a fit at a softer σ then compares unlike images). The figure is
//! seen from SoftRas's default camera (all its hinges turn in the image plane).
//!
//! Modes (`--modes a,b`): `schedule` (`fit-articulated --target`'s defaults: the σ/γ schedule
//! against the one sharp target), `sharp` (every iteration sharp, `--no-schedule`) and
//! `rendered` (`fit-articulated --target-angles`' defaults: the target rendered again at every
//! stage's σ/γ from the known target angles, the schedule from σ = γ = 1e-2; possible only
//! when the target is the figure itself). `--sigma-start`/`--gamma-start` set both modes'
//! start.
//!
//! Run: `cargo run --release --example articulated_study -- --trials 20 --ranges 10-20,20-30`
//! (`--help` lists the knobs; `--png DIR` writes each mode's first trial: target, start,
//! result). Results: RESULTS.md, "Non-rigid pose".

use std::path::PathBuf;
use std::time::Instant;

use rand::{RngExt, SeedableRng};
use softvk::camera::Camera;
use softvk::fit::articulated::{ArticulatedFitOptions, fit_articulated};
use softvk::fit::pose::PoseTarget;
use softvk::fit::rig::Rig;
use softvk::fit::session::Session;
use softvk::gpu::{Context, ContextOptions};
use softvk::lighting::Lighting;
use softvk::raster::gpu::{Method, Renderer};

struct Args {
    trials: u32,
    seed: u64,
    ranges: Vec<(f64, f64)>,
    target_range: f64,
    success: f64,
    modes: Vec<String>,
    png: Option<PathBuf>,
    verbose: bool,
    target_blur: Option<(f64, f64)>,
    rendered_schedule: Option<softvk::fit::pose::Schedule>,
    opts: ArticulatedFitOptions,
}

const HELP: &str = "articulated_study [--trials N] [--seed S] [--ranges LO-HI,...]
  [--target-range DEG] [--success DEG] [--modes schedule,sharp] [--size N] [--iters N]
  [--lr LR] [--lr-final F] [--sigma S] [--gamma G] [--sigma-start S] [--gamma-start G]
  [--stages N] [--target-sigma-gamma S/G] [--blur-start PX (0: none)] [--blur-stages N] [--png DIR] [--verbose]";

fn parse() -> Args {
    let mut a = Args {
        trials: 20,
        seed: 7,
        ranges: vec![(10.0, 20.0), (20.0, 30.0), (30.0, 45.0), (45.0, 60.0)],
        target_range: 20.0,
        success: 2.0,
        modes: vec!["schedule".into(), "sharp".into()],
        png: None,
        verbose: false,
        target_blur: None,
        rendered_schedule: None,
        opts: ArticulatedFitOptions::default(),
    };
    let mut schedule = a.opts.schedule.unwrap_or_default();
    let mut blur = a.opts.blur.unwrap_or_default();
    let mut given_start = false;
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| panic!("{flag} needs a value"));
        let num = |s: &str| -> f64 { s.parse().unwrap_or_else(|_| panic!("bad number {s}")) };
        match flag.as_str() {
            "--trials" => a.trials = num(&value()) as u32,
            "--seed" => a.seed = num(&value()) as u64,
            "--ranges" => {
                a.ranges = value()
                    .split(',')
                    .map(|r| {
                        let (lo, hi) = r.split_once('-').expect("a range LO-HI");
                        (num(lo), num(hi))
                    })
                    .collect()
            }
            "--target-range" => a.target_range = num(&value()),
            "--success" => a.success = num(&value()),
            "--modes" => a.modes = value().split(',').map(str::to_owned).collect(),
            "--size" => {
                let n = num(&value()) as u32;
                a.opts.settings.width = n;
                a.opts.settings.height = n;
            }
            "--iters" => a.opts.iterations = num(&value()) as u32,
            "--lr" => a.opts.lr = num(&value()),
            "--lr-final" => a.opts.lr_final = num(&value()),
            "--sigma" => a.opts.settings.sigma = num(&value()),
            "--gamma" => a.opts.settings.gamma = num(&value()),
            "--sigma-start" => {
                schedule.sigma_start = num(&value());
                given_start = true;
            }
            "--gamma-start" => {
                schedule.gamma_start = num(&value());
                given_start = true;
            }
            "--stages" => schedule.stages = num(&value()) as u32,
            "--png" => a.png = Some(PathBuf::from(value())),
            "--verbose" => a.verbose = true,
            "--target-sigma-gamma" => {
                let v = value();
                let (sg, gg) = v.split_once('/').expect("--target-sigma-gamma S/G");
                a.target_blur = Some((num(sg), num(gg)));
            }
            "--blur-start" => blur.start = num(&value()),
            "--blur-stages" => blur.stages = num(&value()) as u32,
            "--help" | "-h" => {
                println!("{HELP}");
                std::process::exit(0);
            }
            f => panic!("unknown flag {f}\n{HELP}"),
        }
    }
    for m in &a.modes {
        assert!(
            ["schedule", "sharp", "rendered"].contains(&m.as_str()),
            "unknown mode {m}"
        );
    }
    a.opts.schedule = Some(schedule);
    // `rendered` starts from its own defaults unless the start is given.
    if !given_start {
        a.rendered_schedule = ArticulatedFitOptions::for_rendered_target().schedule;
    } else {
        a.rendered_schedule = Some(schedule);
    }
    a.opts.blur = (blur.start > 0.0).then_some(blur);
    a
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    match s.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => s[n / 2],
        n => 0.5 * (s[n / 2 - 1] + s[n / 2]),
    }
}

fn write_png(path: &std::path::Path, frames: &[&[[f32; 4]]], w: u32, h: u32) {
    let mut img = image::RgbaImage::new(w * frames.len() as u32, h);
    for (k, f) in frames.iter().enumerate() {
        for (i, p) in f.iter().enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            // Over white, so that the figure's silhouette reads.
            let a = p[3].clamp(0.0, 1.0);
            let c = |v: f32| ((v * a + 1.0 - a).clamp(0.0, 1.0) * 255.0).round() as u8;
            img.put_pixel(
                k as u32 * w + x,
                y,
                image::Rgba([c(p[0]), c(p[1]), c(p[2]), 255]),
            );
        }
    }
    img.save(path).expect("write the PNG");
}

fn main() {
    let args = parse();
    let ctx = Context::new(&ContextOptions::from_env()).expect("a Vulkan device");
    let rig = Rig::figure();
    let n = rig.joint_count();
    let camera = Camera::default();
    let lighting = Lighting::default();
    let renderer = Renderer::new(&ctx).unwrap();
    let s = args.opts.settings;
    let render_at = |angles: &[f64], sigma: f64, gamma: f64| -> Vec<[f32; 4]> {
        let s = softvk::raster::settings::RasterSettings { sigma, gamma, ..s };
        renderer
            .render_views(
                &ctx,
                &rig.posed_mesh(angles),
                &[camera],
                &lighting,
                &s,
                Method::Tiled { tile: 8 },
            )
            .unwrap()
            .images
    };
    let (target_sigma, target_gamma) = args.target_blur.unwrap_or((s.sigma, s.gamma));
    let render = |angles: &[f64]| render_at(angles, s.sigma, s.gamma);
    let render_target = |angles: &[f64]| render_at(angles, target_sigma, target_gamma);
    if let Some(dir) = &args.png {
        std::fs::create_dir_all(dir).unwrap();
    }
    println!(
        "figure: {} joints, {} faces, {}x{}, {} iterations, lr {}, blur {:?}, σ/γ {:?} (rendered: {:?}), success ≤ {}°, targets ±{}°, seed {}",
        n,
        rig.mesh.face_count(),
        s.width,
        s.height,
        args.opts.iterations,
        args.opts.lr,
        args.opts.blur,
        args.opts.schedule,
        args.rendered_schedule,
        args.success,
        args.target_range,
        args.seed
    );
    println!("| offset per joint | mode | success | median worst joint error | median s/fit |");
    println!("| --- | --- | ---: | ---: | ---: |");
    for &(lo, hi) in &args.ranges {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(args.seed);
        let trials: Vec<(Vec<f64>, Vec<f64>)> = (0..args.trials)
            .map(|_| {
                let target: Vec<f64> = (0..n)
                    .map(|_| {
                        rng.random_range(-args.target_range..=args.target_range)
                            .to_radians()
                    })
                    .collect();
                let init = target
                    .iter()
                    .map(|t| {
                        let off = rng.random_range(lo..=hi);
                        let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                        t + (sign * off).to_radians()
                    })
                    .collect();
                (target, init)
            })
            .collect();
        for mode in &args.modes {
            let opts = ArticulatedFitOptions {
                schedule: match mode.as_str() {
                    "sharp" => None,
                    "rendered" => args.rendered_schedule,
                    _ => args.opts.schedule,
                },
                ..args.opts.clone()
            };
            let (mut ok, mut worst, mut secs) = (0, Vec::new(), Vec::new());
            for (k, (target_angles, init)) in trials.iter().enumerate() {
                let target = render_target(target_angles);
                let t0 = Instant::now();
                let mut per_stage = |sigma, gamma| Ok(render_at(target_angles, sigma, gamma));
                let r = fit_articulated(
                    &ctx,
                    &rig,
                    &camera,
                    &lighting,
                    if mode == "rendered" {
                        PoseTarget::PerStage(&mut per_stage)
                    } else {
                        PoseTarget::Fixed(&target)
                    },
                    init,
                    &opts,
                    Session::new(),
                )
                .unwrap();
                secs.push(t0.elapsed().as_secs_f64());
                let err = r
                    .angles
                    .iter()
                    .zip(target_angles)
                    .map(|(a, b)| (a - b).abs().to_degrees())
                    .fold(0.0, f64::max);
                worst.push(err);
                ok += u32::from(err <= args.success);
                if args.verbose {
                    let per: Vec<String> = r
                        .angles
                        .iter()
                        .zip(target_angles)
                        .zip(&rig.joints)
                        .map(|((a, b), j)| format!("{} {:+.1}", j.name, (a - b).to_degrees()))
                        .collect();
                    eprintln!(
                        "{lo}-{hi} {mode} trial {k}: worst {err:.2}°, loss {:.2e}: {}",
                        r.loss,
                        per.join(", ")
                    );
                }
                if k == 0
                    && let Some(dir) = &args.png
                {
                    write_png(
                        &dir.join(format!("{mode}-{lo}-{hi}.png")),
                        &[&target, &render(init), &r.image],
                        s.width,
                        s.height,
                    );
                }
            }
            println!(
                "| ({lo}°, {hi}°] | {mode} | {ok}/{} | {:.2}° | {:.2} |",
                args.trials,
                median(&worst),
                median(&secs)
            );
        }
    }
    ctx.check_validation().unwrap();
}
