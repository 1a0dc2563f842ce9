//! Checks a large scene against the CPU twin on a band of rows: `spot3-1024` (spot subdivided
//! three times, 374 784 faces, 1024²), whose brute-force kernel cannot run on llvmpipe (a pixel's
//! loop over every face passes the driver's loop cap), rendered tiled on the band's rows and by
//! `raster::reference` (f64) on the same rows; prints the largest difference per channel and
//! fails beyond the forward tests' tolerance (1e-4).
//!
//! ```text
//! cargo run --release --example large_band_check -- [ROWS] [TILE]   (default 8 rows, tile 8)
//! ```

use softvk::bench::Scene;
use softvk::gpu::{Context, ContextOptions};
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::reference;

fn main() -> softvk::Result<()> {
    let mut args = std::env::args().skip(1);
    let rows: u32 = args
        .next()
        .map_or(8, |a| a.parse().expect("ROWS: a number"));
    let tile: u32 = args
        .next()
        .map_or(8, |a| a.parse().expect("TILE: a number"));
    let scene = Scene::load("spot3-1024", &softvk::assets::dir())?.band(rows)?;
    println!(
        "{}: {} faces, {}x{} pixels, tile {tile}",
        scene.name,
        scene.mesh.face_count(),
        scene.settings.width,
        scene.settings.height
    );
    let ctx = Context::new(&ContextOptions::from_env())?;
    let start = std::time::Instant::now();
    let frames = Renderer::new(&ctx)?.render_views(
        &ctx,
        &scene.mesh,
        &scene.cameras,
        &scene.lighting,
        &scene.settings,
        Method::Tiled { tile },
    )?;
    ctx.check_validation()?;
    let gpu_s = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    let mut worst = [0.0f64; 4];
    for (v, camera) in scene.cameras.iter().enumerate() {
        let twin = reference::render(&scene.mesh, camera, &scene.lighting, &scene.settings)?;
        for (got, want) in frames.image(v).iter().zip(&twin) {
            for c in 0..4 {
                worst[c] = worst[c].max((f64::from(got[c]) - want[c]).abs());
            }
        }
    }
    let shown: Vec<String> = worst.iter().map(|d| format!("{d:.2e}")).collect();
    println!(
        "tiled {gpu_s:.2} s, twin {:.2} s; largest |tiled − twin| (R, G, B, A): {}",
        start.elapsed().as_secs_f64(),
        shown.join(", ")
    );
    if worst.iter().any(|&d| d.is_nan() || d > 1e-4) {
        return Err(softvk::Error::Check(format!(
            "tiled differs from the twin by {worst:?} (> 1e-4)"
        )));
    }
    println!("within 1e-4 of the twin");
    Ok(())
}
