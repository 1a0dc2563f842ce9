//! Fits the default sphere to spot's silhouettes (24 views, elevation 30°, every 15° of azimuth,
//! 64², viewing angle 15°) and reports IoU on those views and on 24 unseen ones.
//!
//! Also writes the fitted mesh (`[out.obj]`, default `fit_spot.obj`) and measures its 3D IoU
//! against spot, both voxelized at 64³ over the cube centred (0, 0.11, 0.19) with half-size 0.9
//! (spot's bounding box with a margin), next to the visual hull's IoU from the same 24 views: the
//! best any silhouette-only method can do.
//!
//! Run: `cargo run --release --example fit_spot -- [iterations] [out.obj]`.

use softvk::camera::{Camera, Projection};
use softvk::field::Cube;
use softvk::field::voxel::{iou, visual_hull, voxelize_mesh};
use softvk::fit::mesh_fit::{MeshFit, MeshFitOptions, default_template, fit_mesh};
use softvk::fit::session::{Progress, Session};
use softvk::fit::silhouette::hard_ious;
use softvk::gpu::{Context, ContextOptions};
use softvk::io::{Silhouettes, write_obj};
use softvk::mesh::Mesh;
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::{Alpha, Dist, RasterSettings};

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
        .render_silhouettes(ctx, mesh, cams, &hard, Method::default())
        .unwrap()
}

fn ious(a: &[f32], b: &[f32], px: usize) -> Vec<f64> {
    hard_ious(a, b, px).into_iter().map(f64::from).collect()
}

fn main() {
    let iterations: u32 = std::env::args()
        .nth(1)
        .map_or(500, |s| s.parse().expect("iterations"));
    let out = std::env::args()
        .nth(2)
        .unwrap_or_else(|| "fit_spot.obj".into());
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
    let log = |p: &Progress<'_, '_, MeshFit<'_>>| {
        let (l, ious) = (p.row(), p.fitter.read_ious()?);
        let mean = ious.iter().sum::<f32>() / ious.len() as f32;
        eprintln!(
            "it {:5} loss {:.4} (1-IoU {:.4}, lap {:.4}, flat {:.2}) soft IoU {mean:.4}  {:.1} s",
            l.iteration, l.total, l.silhouette, l.laplacian, l.flatten, l.seconds
        );
        Ok(true)
    };
    let session = Session::new().hooks(log);
    let fit = fit_mesh(&ctx, &default_template(), &train, &targets, &opts, session).unwrap();
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

    write_obj(out.as_ref(), &fit.mesh.positions, &fit.mesh.faces).unwrap();

    // 3D IoU at 64³: the fitted mesh and the visual hull against spot.
    let cube = Cube::new([0.0, 0.11, 0.19], 0.9).unwrap();
    let res = 64;
    let truth = voxelize_mesh(&spot.positions, &spot.faces, &cube, res).unwrap();
    let fitted = voxelize_mesh(&fit.mesh.positions, &fit.mesh.faces, &cube, res).unwrap();
    let sil = Silhouettes {
        width: size,
        height: size,
        names: (0..train.len()).map(|i| format!("{i:03}.png")).collect(),
        masks: targets
            .iter()
            .map(|&a| if a > 0.5 { 1.0 } else { 0.0 })
            .collect(),
    };
    let hull = visual_hull(&sil, &train, &cube, res).unwrap();
    println!(
        "3D IoU at {res}³: fitted mesh {:.4} (odd rays {}), visual hull of the 24 views {:.4}; \
         mesh written to {out}",
        iou(&fitted.occupancy, &truth.occupancy).unwrap(),
        fitted.odd_rays,
        iou(&hull, &truth.occupancy).unwrap()
    );
}
