//! `softvk bench` through its library entry point, on lavapipe with validation on: one cheap
//! scene end to end (brute force, tiled, the bit-for-bit check, JSON), and the band that quick
//! runs use.

mod common;

use softvk::bench::{self, BenchOptions, Scene};
use softvk::raster::gpu::{Method, Renderer};

#[test]
fn one_cheap_scene_runs_end_to_end_and_checks_tiled_against_brute() {
    let Some(gpu) = common::gpu() else { return };
    // Eight rows of spot-256: the same per-pixel work as the full frame, at 1/32 of the cost.
    let opts = BenchOptions {
        scenes: vec!["spot-256".into()],
        repeat: 1,
        tiles: vec![8, 32],
        band: Some(8),
        ..BenchOptions::default()
    };
    let mut lines = Vec::new();
    let records = bench::run(&gpu, &opts, |line| lines.push(line.to_string())).unwrap();
    let log = lines.join("\n");
    assert_eq!(records.len(), 3, "{log}");
    assert_eq!(records[0].method, Method::Brute);
    assert_eq!(records[0].pairs, 256 * 8 * 5856);
    for (r, tile) in records[1..].iter().zip([8, 32]) {
        assert_eq!(r.method, Method::Tiled { tile });
        assert_eq!(r.identical_to_brute, Some(true));
        assert!(r.pairs > 0 && r.pairs < records[0].pairs);
        assert!(r.entries.is_some_and(|e| e > 0));
    }
    for r in &records {
        assert_eq!(r.scene, "spot-256[rows 124..132]");
        assert_eq!(r.rows, Some([124, 132]));
        assert_eq!(r.repeats, 1);
        assert!(r.wall_ms > 0.0 && r.gpu_ms.is_some_and(|ms| ms > 0.0));
        assert!(r.passes.iter().any(|(name, _)| name == "face setup"));
    }
    assert_eq!(
        log.matches("images and aux bit-identical to brute force")
            .count(),
        2,
        "{log}"
    );
    let json: serde_json::Value = serde_json::from_str(&bench::to_json(&records)).unwrap();
    assert_eq!(json.as_array().map(Vec::len), Some(3));
    assert_eq!(json[1]["tile"], 8);
    assert_eq!(json[0]["device"], gpu.info().name.as_str());
}

#[test]
fn a_band_renders_the_rows_of_the_full_frame() {
    let Some(gpu) = common::gpu() else { return };
    let r = Renderer::new(&gpu).unwrap();
    let full = Scene::load("spot-256", &softvk::assets::dir()).unwrap();
    let band = full.band(16).unwrap();
    assert_eq!(band.rows, Some([120, 136]));
    let render = |s: &Scene| {
        r.render_views(
            &gpu,
            &s.mesh,
            &s.cameras,
            &s.lighting,
            &s.settings,
            Method::Tiled { tile: 8 },
        )
        .unwrap()
    };
    let (a, b) = (render(&full), render(&band));
    // Screen space is scaled by 16: only f32 rounding differs.
    let rows = &a.images[120 * 256..136 * 256];
    let max = rows
        .iter()
        .flatten()
        .zip(b.images.iter().flatten())
        .map(|(p, q)| (p - q).abs())
        .fold(0.0f32, f32::max);
    assert!(max < 1e-3, "band differs from the full frame by {max}");
    assert!(rows.iter().any(|p| p[3] > 0.5), "the band crosses spot");
}

#[test]
fn bad_options_are_errors_with_a_clear_message() {
    let Some(gpu) = common::gpu() else { return };
    let opts = BenchOptions {
        scenes: vec!["spot-4096".into()],
        ..BenchOptions::default()
    };
    let err = bench::run(&gpu, &opts, |_| panic!("no progress expected")).unwrap_err();
    assert!(
        err.to_string().contains("unknown scene `spot-4096`"),
        "{err}"
    );
    let opts = BenchOptions {
        band: Some(7), // 256 - 7 is odd: no centred band
        scenes: vec!["spot-256".into()],
        ..BenchOptions::default()
    };
    assert!(bench::run(&gpu, &opts, |_| {}).is_err());
}

#[test]
fn the_mesh_fitting_benchmark_shares_its_iteration_and_counts_its_pairs() {
    let Some(gpu) = common::gpu() else { return };
    let opts = BenchOptions {
        scenes: vec!["fit-120".into()],
        repeat: 1,
        ..BenchOptions::default()
    };
    let mut lines = Vec::new();
    let records = bench::run_fit(&gpu, &opts, |line| lines.push(line.to_string())).unwrap();
    let log = lines.join("\n");
    let passes: Vec<_> = records.iter().map(|r| r.pass).collect();
    assert_eq!(
        passes,
        ["fit-iteration", "fit-loop-k1", "fit-loop-k10"],
        "{log}"
    );
    for r in &records {
        assert_eq!(r.scene, "fit-120");
        assert_eq!((r.views, r.width, r.height), (120, 64, 64));
        let counts = r.counts.expect("the fit's pairs are counted");
        assert!(r.pairs > 0 && r.pairs == counts.binned, "{log}");
        assert!(r.entries.is_some_and(|e| e > 0), "{log}");
    }
    // The iteration's shares first, then its passes; the loops' one pass is the host's.
    let names: Vec<_> = records[0].passes.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names[..3], ["render", "backward", "rest"], "{log}");
    assert!(
        names.contains(&"raster tiled") && names.contains(&"grad tiled"),
        "{log}"
    );
    let share: f64 = records[0].passes[..3].iter().map(|(_, ms)| ms).sum();
    let gpu_ms = records[0].gpu_ms.unwrap();
    assert!(
        (share - gpu_ms).abs() <= 1e-6 * gpu_ms.max(1.0),
        "{share} vs {gpu_ms}: {log}"
    );
    for r in &records[1..] {
        let names: Vec<_> = r.passes.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(names, ["host overhead"], "{log}");
    }
}

#[test]
fn the_pose_fitting_benchmark_times_its_iterations_and_its_loop() {
    let Some(gpu) = common::gpu() else { return };
    let opts = BenchOptions {
        scenes: vec!["fit-pose".into()],
        repeat: 2,
        ..BenchOptions::default()
    };
    let mut lines = Vec::new();
    let records = bench::run_fit(&gpu, &opts, |line| lines.push(line.to_string())).unwrap();
    let log = lines.join("\n");
    let passes: Vec<_> = records.iter().map(|r| r.pass).collect();
    assert_eq!(passes, ["fit-iteration", "fit-loop-k10"], "{log}");
    for r in &records {
        assert_eq!(r.scene, "fit-pose");
        assert_eq!((r.width, r.height, r.faces), (48, 48, 5856));
        assert!(r.entries.is_some_and(|e| e > 0), "{log}");
        assert!(
            r.wall_ms > 0.0 && r.gpu_ms.is_some_and(|ms| ms > 0.0),
            "{log}"
        );
    }
    // Every pass of an iteration is timed, the GPU chain's own among them.
    for pass in [
        "pose",
        "lighting",
        "raster tiled",
        "grad tiled",
        "lighting backward",
        "adam",
    ] {
        assert!(
            records[0].passes.iter().any(|(name, _)| name == pass),
            "{pass}: {log}"
        );
    }
}

#[test]
fn the_conditioned_field_training_benchmark_times_every_slot_of_its_batch() {
    let Some(gpu) = common::gpu() else { return };
    let opts = BenchOptions {
        scenes: vec!["train-recon-field".into()],
        repeat: 1,
        ..BenchOptions::default()
    };
    let mut lines = Vec::new();
    let records = bench::run_fit(&gpu, &opts, |line| lines.push(line.to_string())).unwrap();
    let log = lines.join("\n");
    assert_eq!(records.len(), 1, "{log}");
    let r = &records[0];
    assert_eq!(
        (r.scene.as_str(), r.pass),
        ("train-recon-field", "fit-iteration")
    );
    // The default batch: 16 objects of 24 views at 64².
    assert_eq!((r.views, r.width, r.height), (16 * 24, 64, 64));
    assert!(r.entries.is_some_and(|e| e > 0), "{log}");
    let count = |pass: &str| r.passes.iter().filter(|(name, _)| name == pass).count();
    for pass in [
        "sample",
        "probe forward",
        "probe backward",
        "field backward",
    ] {
        assert_eq!(count(pass), 16, "{pass}: {log}");
    }
    for pass in ["recon encoder", "recon encoder backward", "adam"] {
        assert_eq!(count(pass), 1, "{pass}: {log}");
    }
}
