//! nvdiffrast's primitives as a workload (`softvk bench --scene nv-…`): each primitive forward
//! and backward through [`HardRasterizer`]'s host-slice entry points (what the Python package
//! calls: the host copies are part of the cost), and a whole iteration rasterize →
//! interpolate → antialias → L2 → backward, on spot seen by a perspective camera.
//!
//! - `nv-spot-256`: spot (5 856 faces, centred, longest side 2) at 256², the scene of
//!   BENCHMARKS.md's PyTorch3D comparison (distance 2, elevation 10°, azimuth 30°, 60° field
//!   of view);
//! - `nv-512`, `nv-1024`: spot subdivided twice (93 696 faces) at 512² and 1024².
//!
//! Every time is a median over the repeats after one untimed run. The rasterizer's depth pass
//! visits 64 (pixel, triangle) pairs per binned (triangle, tile) entry; `ns_per_visited_pair`
//! is its GPU time over them (multiply by the driver's threads for CPU-ns on lavapipe).

use std::path::Path;

use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::mesh::Mesh;
use crate::raster::hard::antialias::TopologyHash;
use crate::raster::hard::gpu::{AntialiasArgs, HardRasterizer};
use crate::raster::hard::reference::AttrLayout;
use crate::raster::hard::{Shape, Topology};

/// The scenes, run only when named.
pub const HARD_SCENES: [&str; 3] = ["nv-spot-256", "nv-512", "nv-1024"];

/// One timed primitive (or the iteration) of one scene.
#[derive(Clone, Debug, PartialEq)]
pub struct HardRecord {
    /// Scene name.
    pub scene: String,
    /// `rasterize`, `rasterize backward`, `interpolate`, …, `iteration`.
    pub pass: &'static str,
    /// Median host time of the call (submissions, waits and host copies), ms.
    pub wall_ms: f64,
    /// Median GPU time of each pass the call recorded, ms.
    pub passes: Vec<(String, f64)>,
    /// Triangles.
    pub faces: u32,
    /// Image side (square).
    pub size: u32,
    /// The depth pass's visited (pixel, triangle) pairs (rasterize only).
    pub visited_pairs: Option<u64>,
    /// The depth pass's GPU time per visited pair, ns (rasterize only).
    pub ns_per_visited_pair: Option<f64>,
    /// Device name.
    pub device: String,
    /// Timed calls the medians are over.
    pub repeats: u32,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Spot, centred and scaled to a longest side of 2, subdivided `times`, in clip space from
/// distance 2, elevation 10°, azimuth 30° (OpenGL perspective, 60° vertical field of view,
/// near 0.1, far 10).
fn scene(assets: &Path, times: u32) -> Result<(Vec<f32>, Vec<[u32; 3]>)> {
    let mut mesh = Mesh::load_obj(&assets.join("spot_triangulated.obj"), 1)
        .map_err(|e| Error::Input(format!("nv bench: {e}")))?;
    mesh.normalize()
        .map_err(|e| Error::Input(format!("nv bench: {e}")))?;
    for _ in 0..times {
        mesh = mesh
            .subdivided()
            .map_err(|e| Error::Input(format!("nv bench: {e}")))?;
    }
    let (el, az) = (10f64.to_radians(), 30f64.to_radians());
    let eye = [
        2.0 * el.cos() * az.sin(),
        2.0 * el.sin(),
        2.0 * el.cos() * az.cos(),
    ];
    let len = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let norm = |v: [f64; 3]| {
        let l = len(v);
        [v[0] / l, v[1] / l, v[2] / l]
    };
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let f = norm([-eye[0], -eye[1], -eye[2]]);
    let s = norm(cross(f, [0.0, 1.0, 0.0]));
    let u = cross(s, f);
    let (near, far) = (0.1, 10.0);
    let g = 1.0 / 30f64.to_radians().tan();
    let pos = mesh
        .positions
        .iter()
        .flat_map(|p| {
            let p = [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])];
            let d = [p[0] - eye[0], p[1] - eye[1], p[2] - eye[2]];
            let (x, y, z) = (dot(s, d), dot(u, d), -dot(f, d));
            let zc = (far + near) / (near - far) * z + 2.0 * far * near / (near - far);
            [(g * x) as f32, (g * y) as f32, zc as f32, (-z) as f32]
        })
        .collect();
    Ok((pos, mesh.faces))
}

/// Runs the named scenes of [`HARD_SCENES`] (`repeat` timed calls each).
pub fn run_hard(
    ctx: &Context,
    scenes: &[&str],
    repeat: u32,
    assets: &Path,
    mut progress: impl FnMut(&str),
) -> Result<Vec<HardRecord>> {
    let mut hard = HardRasterizer::new(ctx)?;
    hard.time_passes(ctx)?;
    let mut records = Vec::new();
    for &name in scenes {
        let (times, size) = match name {
            "nv-spot-256" => (0, 256),
            "nv-512" => (2, 512),
            _ => (2, 1024),
        };
        let (pos, tri) = scene(assets, times)?;
        let vertices = pos.len() as u32 / 4;
        let shape = Shape {
            width: size,
            height: size,
            vertex_count: vertices,
            triangle_count: tri.len() as u32,
            topology: Topology::Instanced { batch: 1 },
        };
        let n = shape.pixels();
        // Vertex colours from the positions.
        let colors: Vec<f32> = pos
            .chunks(4)
            .flat_map(|p| [0.5 + 0.4 * p[0] / p[3], 0.5 + 0.4 * p[1] / p[3], 0.5])
            .collect();
        let layout = AttrLayout {
            vertex_count: vertices,
            attr_count: 3,
            per_item: false,
        };
        let topology = TopologyHash::new(&tri);
        let target = vec![0.25f32; 3 * n];
        let mut timed: Vec<(&'static str, Vec<f64>, Vec<Vec<(String, f64)>>)> = Vec::new();
        let mut time = |what: &'static str,
                        run: &mut dyn FnMut(&mut HardRasterizer) -> Result<()>,
                        hard: &mut HardRasterizer|
         -> Result<()> {
            run(hard)?; // warm-up: buffers grown, pipelines made
            hard.take_timings();
            let mut walls = Vec::new();
            let mut passes = Vec::new();
            for _ in 0..repeat {
                let start = std::time::Instant::now();
                run(hard)?;
                walls.push(start.elapsed().as_secs_f64() * 1e3);
                passes.push(
                    hard.take_timings()
                        .into_iter()
                        .filter(|p| p.depth == 0)
                        .map(|p| (p.name, p.ms))
                        .collect(),
                );
            }
            timed.push((what, walls, passes));
            Ok(())
        };
        let layer = hard.rasterize(ctx, &shape, &pos, &tri, None)?;
        let entries = hard.entries().unwrap_or(0);
        let (color, _) = hard.interpolate(
            ctx,
            &colors,
            layout,
            &layer.rast,
            &tri,
            [size, size],
            None,
            &[],
        )?;
        let args = AntialiasArgs {
            color: &color,
            rast: &layer.rast,
            pos: &pos,
            instanced: false,
            vertex_count: vertices,
            tri: &tri,
            batch: 1,
            height: size,
            width: size,
            channels: 3,
        };
        let out = hard.antialias(ctx, &args, &topology)?;
        let dy: Vec<f32> = out
            .iter()
            .zip(&target)
            .map(|(o, t)| 2.0 * (o - t) / n as f32)
            .collect();
        let (g_color, _) = hard.antialias_grad(ctx, &args, &topology, &dy, 1.0)?;
        let g_interp = hard.interpolate_grad(
            ctx,
            &colors,
            layout,
            &layer.rast,
            &tri,
            [size, size],
            None,
            &[],
            &g_color,
            None,
        )?;
        time(
            "rasterize",
            &mut |h| h.rasterize(ctx, &shape, &pos, &tri, None).map(drop),
            &mut hard,
        )?;
        let dy_rast = g_interp.rast.clone();
        time(
            "rasterize backward",
            &mut |h| {
                h.rasterize_grad(ctx, &shape, &pos, &tri, &layer.rast, &dy_rast, None)
                    .map(drop)
            },
            &mut hard,
        )?;
        time(
            "interpolate",
            &mut |h| {
                h.interpolate(
                    ctx,
                    &colors,
                    layout,
                    &layer.rast,
                    &tri,
                    [size, size],
                    None,
                    &[],
                )
                .map(drop)
            },
            &mut hard,
        )?;
        time(
            "interpolate backward",
            &mut |h| {
                h.interpolate_grad(
                    ctx,
                    &colors,
                    layout,
                    &layer.rast,
                    &tri,
                    [size, size],
                    None,
                    &[],
                    &g_color,
                    None,
                )
                .map(drop)
            },
            &mut hard,
        )?;
        time(
            "antialias",
            &mut |h| h.antialias(ctx, &args, &topology).map(drop),
            &mut hard,
        )?;
        time(
            "antialias backward",
            &mut |h| h.antialias_grad(ctx, &args, &topology, &dy, 1.0).map(drop),
            &mut hard,
        )?;
        time(
            "iteration",
            &mut |h| {
                let layer = h.rasterize(ctx, &shape, &pos, &tri, None)?;
                let (color, _) = h.interpolate(
                    ctx,
                    &colors,
                    layout,
                    &layer.rast,
                    &tri,
                    [size, size],
                    None,
                    &[],
                )?;
                let args = AntialiasArgs {
                    color: &color,
                    rast: &layer.rast,
                    ..args
                };
                let out = h.antialias(ctx, &args, &topology)?;
                let dy: Vec<f32> = out
                    .iter()
                    .zip(&target)
                    .map(|(o, t)| 2.0 * (o - t) / n as f32)
                    .collect();
                let (g_color, g_pos_aa) = h.antialias_grad(ctx, &args, &topology, &dy, 1.0)?;
                let g = h.interpolate_grad(
                    ctx,
                    &colors,
                    layout,
                    &layer.rast,
                    &tri,
                    [size, size],
                    None,
                    &[],
                    &g_color,
                    None,
                )?;
                let g_pos =
                    h.rasterize_grad(ctx, &shape, &pos, &tri, &layer.rast, &g.rast, None)?;
                std::hint::black_box((g_pos, g_pos_aa, g.attr));
                Ok(())
            },
            &mut hard,
        )?;
        for (what, walls, passes) in timed {
            let mut names: Vec<String> = Vec::new();
            for p in passes.iter().flatten() {
                if !names.contains(&p.0) {
                    names.push(p.0.clone());
                }
            }
            let passes: Vec<(String, f64)> = names
                .into_iter()
                .map(|name| {
                    let per_run: Vec<f64> = passes
                        .iter()
                        .map(|run| run.iter().filter(|p| p.0 == name).map(|p| p.1).sum())
                        .collect();
                    (name, median(per_run))
                })
                .collect();
            let (visited, ns) = if what == "rasterize" {
                let visited = entries * 64;
                let depth = passes.iter().find(|p| p.0 == "hard depth").map(|p| p.1);
                (
                    Some(visited),
                    depth.map(|ms| ms * 1e6 / visited.max(1) as f64),
                )
            } else {
                (None, None)
            };
            let record = HardRecord {
                scene: name.to_string(),
                pass: what,
                wall_ms: median(walls),
                passes,
                faces: tri.len() as u32,
                size,
                visited_pairs: visited,
                ns_per_visited_pair: ns,
                device: ctx.info().name.clone(),
                repeats: repeat,
            };
            progress(&format!(
                "{name} {what}: {:.2} ms wall{}",
                record.wall_ms,
                record
                    .ns_per_visited_pair
                    .map_or(String::new(), |ns| format!(", {ns:.2} ns per visited pair"))
            ));
            records.push(record);
        }
    }
    Ok(records)
}

/// The records as a JSON list, one a line.
#[cfg(feature = "json")]
pub fn hard_to_json(records: &[HardRecord]) -> String {
    use serde_json::{Map, Value, json};
    let lines: Vec<String> = records
        .iter()
        .map(|r| {
            let passes: Map<String, Value> = r
                .passes
                .iter()
                .map(|(n, ms)| (n.clone(), json!(ms)))
                .collect();
            json!({
                "scene": r.scene, "pass": r.pass, "wall_ms": r.wall_ms, "faces": r.faces,
                "size": r.size, "visited_pairs": r.visited_pairs,
                "ns_per_visited_pair": r.ns_per_visited_pair, "device": r.device,
                "repeats": r.repeats, "passes": passes,
            })
            .to_string()
        })
        .collect();
    format!("[\n{}\n]\n", lines.join(",\n"))
}
