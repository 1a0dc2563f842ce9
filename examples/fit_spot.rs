//! Fits the default sphere to spot's silhouettes (24 views, elevation 30°, every 15° of azimuth,
//! 64², viewing angle 15°) and reports IoU on those views and on 24 unseen ones.
//!
//! Run: `cargo run --release --example fit_spot -- [iterations]`.

use softvk::camera::{Camera, Projection};
use softvk::fit::mesh_fit::{MeshFitOptions, default_template, fit_mesh};
use softvk::gpu::{Context, ContextOptions};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::reference::{Alpha, Dist, RasterSettings};

fn cameras(elevation: f64, offset: f64) -> Vec<Camera> {
    (0..24)
        .map(|i| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(2.732, elevation, offset + 15.0 * f64::from(i))
        })
        .collect()
}

fn silhouettes(ctx: &Context, mesh: &Mesh, cams: &[Camera], size: u32) -> Vec<f32> {
    let hard = RasterSettings {
        width: size,
        height: size,
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..RasterSettings::default()
    };
    Renderer::new(ctx)
        .unwrap()
        .render_views(
            ctx,
            mesh,
            cams,
            &Lighting::unlit(),
            &hard,
            Method::default(),
        )
        .unwrap()
        .images
        .iter()
        .map(|p| p[3])
        .collect()
}

fn ious(a: &[f32], b: &[f32], px: usize) -> Vec<f64> {
    a.chunks(px)
        .zip(b.chunks(px))
        .map(|(x, y)| {
            let i = x
                .iter()
                .zip(y)
                .filter(|(p, q)| **p > 0.5 && **q > 0.5)
                .count();
            let u = x
                .iter()
                .zip(y)
                .filter(|(p, q)| **p > 0.5 || **q > 0.5)
                .count();
            i as f64 / u.max(1) as f64
        })
        .collect()
}

fn main() {
    let iterations: u32 = std::env::args()
        .nth(1)
        .map_or(500, |s| s.parse().expect("iterations"));
    let ctx = Context::new(&ContextOptions::from_env()).expect("a Vulkan device");
    let spot = Mesh::load_obj(&softvk::assets::dir().join("spot_triangulated.obj"), 1).unwrap();
    let train = cameras(30.0, 0.0);
    let test = cameras(-10.0, 7.5);
    let size = 64;
    let targets = silhouettes(&ctx, &spot, &train, size);
    let opts = MeshFitOptions {
        iterations,
        ..MeshFitOptions::default()
    };
    let fit = fit_mesh(&ctx, &default_template(), &train, &targets, &opts, |l, ious, _| {
        let mean = ious.iter().sum::<f32>() / ious.len() as f32;
        eprintln!(
            "it {:5} loss {:.4} (1-IoU {:.4}, lap {:.4}, flat {:.2}) soft IoU {mean:.4}  {:.1} s",
            l.iteration, l.total, l.silhouette, l.laplacian, l.flatten, l.seconds
        );
        true
    })
    .unwrap();
    let px = (size * size) as usize;
    let seen = ious(&silhouettes(&ctx, &fit.mesh, &train, size), &targets, px);
    let unseen_t = silhouettes(&ctx, &spot, &test, size);
    let unseen = ious(&silhouettes(&ctx, &fit.mesh, &test, size), &unseen_t, px);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    println!(
        "{iterations} iterations in {:.1} s ({:.1} ms/iteration): mean IoU {:.4} on the 24 \
         training views, {:.4} on 24 unseen views",
        fit.seconds,
        1e3 * fit.seconds / f64::from(iterations),
        mean(&seen),
        mean(&unseen)
    );
}
