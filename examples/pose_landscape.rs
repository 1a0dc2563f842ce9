//! The pose loss along rotation slices through the target pose, for several σ/γ, with the f64
//! twin (`fit::pose::cpu::loss`; CPU only): why the σ/γ schedule helps only when the target is
//! as soft as the render.
//!
//! Spot (texture-res 1) at the pose study's target pose and camera; for each of four axes
//! (x, y, z and an oblique one) the rotation is turned by −180°…180° in 10° steps (applied on
//! the left of the target rotation) and the image MSE printed (×10⁴), with its argmin. The
//! target is, by `--target`:
//! - `sharp` (default): rendered once at SoftRas's σ 1e-5, γ 1e-4, as a photograph would be
//!   (what `softvk fit-pose` compares with at every stage of its schedule);
//! - `same`: rendered at the row's own σ/γ (the talk's landscape: both images equally soft);
//! - `blur`: the sharp target blurred in image space by a Gaussian of `--blur-k · √σ` (NDC units)
//!   at each row's σ (an attempt to soften a given image to match).
//!
//! Run: `cargo run --release --example pose_landscape -- [--size 24] [--target sharp|same|blur]
//! [--blur-k 1.0]`. Results: RESULTS.md, "Pose estimation".

use glam::{DQuat, DVec3};
use softvk::camera::Camera;
use softvk::fit::pose::{self, Pose};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::reference::{MeshF64, render_f64};
use softvk::raster::settings::RasterSettings;

fn main() {
    let (mut size, mut target_kind, mut blur_k) = (24u32, String::from("sharp"), 1.0f64);
    let mut args = std::env::args().skip(1);
    while let Some(flag) = args.next() {
        let value = args
            .next()
            .unwrap_or_else(|| panic!("{flag} needs a value"));
        match flag.as_str() {
            "--size" => size = value.parse().expect("--size N"),
            "--target" => target_kind = value,
            "--blur-k" => blur_k = value.parse().expect("--blur-k K"),
            f => panic!("unknown flag {f}"),
        }
    }
    let path = softvk::assets::dir().join("spot_triangulated.obj");
    let mesh = MeshF64::from_mesh(&Mesh::load_obj(&path, 1).expect("spot"));
    let centre = pose::centroid(&mesh.positions);
    // The pose study's camera and target pose.
    let camera = Camera::from_angles(2.732, 20.0, -30.0);
    let lighting = Lighting::default();
    let target_pose = Pose {
        rotation: DVec3::new(0.35, -0.6, 0.25),
        translation: DVec3::new(0.05, -0.03, 0.04),
    };
    let sharp = RasterSettings {
        width: size,
        height: size,
        ..RasterSettings::default()
    };
    let render = |s: &RasterSettings, p: &Pose| {
        render_f64(&pose::cpu::posed(&mesh, centre, p), &camera, &lighting, s).expect("render")
    };
    let sharp_target = render(&sharp, &target_pose);
    println!(
        "spot {size}x{size}, target {target_kind}{}; MSE ×1e4 at −180°, −170°, …, 180°",
        if target_kind == "blur" {
            format!(" (k {blur_k})")
        } else {
            String::new()
        }
    );
    let rows = [
        (1e-5, 1e-4),
        (1e-3, 1e-3),
        (1e-2, 1e-4),
        (1e-2, 1e-1),
        (3e-2, 3e-1),
    ];
    let axes = [
        DVec3::X,
        DVec3::Y,
        DVec3::Z,
        DVec3::new(1.0, -1.0, 0.5).normalize(),
    ];
    for axis in axes {
        println!(
            "axis {:?}",
            axis.to_array().map(|c| (c * 1e3).round() / 1e3)
        );
        for &(sigma, gamma) in &rows {
            let s = RasterSettings {
                sigma,
                gamma,
                ..sharp
            };
            let target = match target_kind.as_str() {
                "sharp" => sharp_target.clone(),
                "same" => render(&s, &target_pose),
                "blur" => blur(
                    &sharp_target,
                    size,
                    blur_k * sigma.sqrt() * f64::from(size) / 2.0,
                ),
                t => panic!("unknown --target {t}"),
            };
            let mut line = format!("σ {sigma:.0e} γ {gamma:.0e}:");
            let mut best = (f64::INFINITY, 0);
            for k in -18..=18 {
                let turn = DQuat::from_axis_angle(axis, f64::from(k * 10).to_radians());
                let p = Pose {
                    rotation: (turn * DQuat::from_scaled_axis(target_pose.rotation))
                        .to_scaled_axis(),
                    ..target_pose
                };
                let l = pose::cpu::loss(&mesh, centre, &camera, &lighting, &s, &target, &p)
                    .expect("loss");
                if l < best.0 {
                    best = (l, k * 10);
                }
                line += &format!(" {:.0}", l * 1e4);
            }
            println!("{line}  | min at {}°", best.1);
        }
    }
}

/// A separable Gaussian blur of standard deviation `s_px` pixels; outside the image is
/// background (0), and every pixel is normalized by the whole kernel.
fn blur(img: &[[f64; 4]], n: u32, s_px: f64) -> Vec<[f64; 4]> {
    let n = i64::from(n);
    let r = (3.0 * s_px).ceil() as i64;
    let w: Vec<f64> = (-r..=r)
        .map(|i| (-((i * i) as f64) / (2.0 * s_px * s_px)).exp())
        .collect();
    let total: f64 = w.iter().sum();
    let pass = |src: &[[f64; 4]], horizontal: bool| -> Vec<[f64; 4]> {
        let mut out = vec![[0.0; 4]; src.len()];
        for y in 0..n {
            for x in 0..n {
                let mut acc = [0.0; 4];
                for (j, wj) in w.iter().enumerate() {
                    let d = j as i64 - r;
                    let (xx, yy) = if horizontal { (x + d, y) } else { (x, y + d) };
                    if xx < 0 || yy < 0 || xx >= n || yy >= n {
                        continue;
                    }
                    let p = src[(yy * n + xx) as usize];
                    for c in 0..4 {
                        acc[c] += wj * p[c];
                    }
                }
                out[(y * n + x) as usize] = acc.map(|a| a / total);
            }
        }
        out
    };
    pass(&pass(img, true), false)
}
