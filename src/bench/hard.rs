//! nvdiffrast's primitives as a workload (`softvk bench --scene nv-…`): each primitive forward
//! and backward through [`HardRasterizer`]'s host-slice entry points (what the Python package
//! calls: the host copies are part of the cost), and a whole iteration rasterize →
//! interpolate → antialias → L2 → backward, on spot seen by a perspective camera; then
//! `texture` (linear-mipmap-linear, the mip levels built in each call as nvdiffrast builds them
//! without a prebuilt stack) forward and backward, and the textured iteration rasterize →
//! interpolate (uv with its pixel derivatives) → texture → antialias → L2 → backward, through
//! [`TextureSampler`]'s host-slice entry points. The texture is 1024² RGB with wrap; each
//! vertex's uv is its screen position scaled 1.2 (λ ≈ 2.3 at 512²).
//!
//! - `nv-spot-256`: spot (5 856 faces, centred, longest side 2) at 256², the scene of
//!   BENCHMARKS.md's PyTorch3D comparison (distance 2, elevation 10°, azimuth 30°, 60° field
//!   of view);
//! - `nv-512`, `nv-1024`: spot subdivided twice (93 696 faces) at 512² and 1024².
//!
//! Every time is a median over the repeats after one untimed run. The rasterizer's depth pass
//! bins 64 (pixel, triangle) pairs per (triangle, tile) entry and visits those of the subgroups
//! whose pixels the triangle's box meets ([`visited_pairs`], BENCHMARKS.md's definition);
//! `ns_per_visited_pair` is its GPU time over the visited pairs (GPU ns; on lavapipe, which
//! runs on every core, CPU-ns are that times the cores).

use std::path::Path;

use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::mesh::Mesh;
use crate::raster::hard::antialias::TopologyHash;
use crate::raster::hard::gpu::texture::{
    Levels, Lookup, Lookups, TexLayout, TexMode, TextureSampler,
};
use crate::raster::hard::gpu::{AntialiasArgs, HardRasterizer};
use crate::raster::hard::reference::AttrLayout;
use crate::raster::hard::texture::{Boundary, Filter, Mode};
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
    /// The depth pass's binned (pixel, triangle) pairs: 64 per (triangle, tile) entry, each of
    /// which it tests (rasterize only).
    pub binned_pairs: Option<u64>,
    /// The visited pairs, the per-pair figure's fixed denominator: per block of a subgroup's
    /// lanes, its pixels × the triangles whose snapped box meets it (`hard::visited_pairs`;
    /// rasterize only).
    pub visited_pairs: Option<u64>,
    /// The depth pass's GPU time per visited pair, ns (rasterize only).
    pub ns_per_visited_pair: Option<f64>,
    /// Device name.
    pub device: String,
    /// Timed calls the medians are over.
    pub repeats: u32,
}

/// A timed call's name, wall times and per-run pass times.
type Timed = (&'static str, Vec<f64>, Vec<Vec<(String, f64)>>);

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

/// The visited (pixel, triangle) pairs of one minibatch item: over the 8×8 tiles a triangle's
/// box is binned to, each block of `lanes` pixels (4 × 2 for 8 lanes) whose sample box the
/// snapped triangle's box meets, times `lanes` (every block for a homogeneous triangle);
/// counted with the f64 twin's snapping. It is what the first depth kernel visited (a subgroup
/// a block, each testing the binned triangles its ballot kept) and is kept as the per-pair
/// figure's denominator, so that figures compare across kernels: the kernel of today tests
/// every binned pair (a lane a row of a tile, every binned triangle at all 64 pixels).
pub fn visited_pairs(shape: &Shape, pos: &[f32], tri: &[[u32; 3]], lanes: u32) -> Result<u64> {
    use crate::primitives::binning::{TileGrid, cpu::tile_rect};
    use crate::raster::hard::reference::{Coverage, coverage};
    let (w, h) = (shape.width, shape.height);
    let grid = TileGrid::new(w, h, 8)?;
    let s = f64::from(w.min(h));
    let scale = (1.0 / (8.0 * s)) as f32;
    let (bw, bh) = if lanes.is_power_of_two() && lanes <= 64 {
        let bw = 1u32 << (lanes.trailing_zeros().div_ceil(2));
        (bw, lanes / bw)
    } else {
        (8, 1)
    };
    let sample = |col: u32, row_top: u32| {
        (
            16 * i64::from(col) + 8 - 8 * i64::from(w),
            16 * (i64::from(h) - 1 - i64::from(row_top)) + 8 - 8 * i64::from(h),
        )
    };
    let mut visited = 0u64;
    for t in tri {
        let c = t.map(|v| {
            let o = 4 * v as usize;
            [pos[o], pos[o + 1], pos[o + 2], pos[o + 3]].map(f64::from)
        });
        let Some(cov) = coverage(c, w, h) else {
            continue;
        };
        let (boxf, snapped) = match cov {
            Coverage::Snapped(q) => {
                let lo = [0, 1].map(|k| q.p.iter().map(|p| p[k]).min().unwrap_or(0));
                let hi = [0, 1].map(|k| q.p.iter().map(|p| p[k]).max().unwrap_or(0));
                let b = [
                    lo[0] as f32 * scale,
                    lo[1] as f32 * scale,
                    hi[0] as f32 * scale,
                    hi[1] as f32 * scale,
                ];
                (b, Some((lo, hi)))
            }
            Coverage::Homogeneous => ([-1e30, -1e30, 1e30, 1e30], None),
        };
        let Some(r) = tile_rect(boxf, &grid) else {
            continue;
        };
        for ty in r[1]..=r[3] {
            for tx in r[0]..=r[2] {
                for by in 0..8 / bh {
                    for bx in 0..8 / bw {
                        let Some((lo, hi)) = snapped else {
                            visited += u64::from(lanes);
                            continue;
                        };
                        let (x0, y0) = sample(8 * tx + bx * bw, 8 * ty + by * bh + bh - 1);
                        let (x1, y1) = sample(8 * tx + bx * bw + bw - 1, 8 * ty + by * bh);
                        if !(x1 < lo[0] || y1 < lo[1] || x0 > hi[0] || y0 > hi[1]) {
                            visited += u64::from(lanes);
                        }
                    }
                }
            }
        }
    }
    Ok(visited)
}

/// What one iteration works on: the scene and its fixed target.
struct IterationScene<'a> {
    shape: &'a Shape,
    pos: &'a [f32],
    tri: &'a [[u32; 3]],
    colors: &'a [f32],
    layout: AttrLayout,
    topology: &'a TopologyHash,
    target: &'a [f32],
    /// Two floats a vertex: the textured iteration's uv.
    uv: &'a [f32],
    uv_layout: AttrLayout,
    tex_layout: TexLayout,
    /// The texture's base level.
    tex: &'a [f32],
}

/// The textured iteration's texture mode.
const TEX_MODE: TexMode = TexMode::Flat(Mode {
    filter: Filter::LinearMipmapLinear,
    boundary: Boundary::Wrap,
});

/// Everything one iteration computes.
struct Iteration {
    layer: crate::raster::hard::gpu::HardLayer,
    color: Vec<f32>,
    dy: Vec<f32>,
    g_color: Vec<f32>,
    g_interp: crate::raster::hard::gpu::InterpolateGrads32,
}

impl IterationScene<'_> {
    fn antialias_args<'b>(&'b self, rast: &'b [f32], color: &'b [f32]) -> AntialiasArgs<'b> {
        let s = self.shape;
        AntialiasArgs {
            color,
            rast,
            pos: self.pos,
            instanced: false,
            vertex_count: s.vertex_count,
            tri: self.tri,
            batch: 1,
            height: s.height,
            width: s.width,
            channels: 3,
        }
    }

    /// rasterize → interpolate → antialias → L2 against the target (on the host) → antialias,
    /// interpolate and rasterize backward.
    fn iterate(&self, ctx: &Context, h: &mut HardRasterizer) -> Result<Iteration> {
        let s = self.shape;
        let size = [s.height, s.width];
        let layer = h.rasterize(ctx, s, self.pos, self.tri, None)?;
        let (color, _) = h.interpolate(
            ctx,
            self.colors,
            self.layout,
            &layer.rast,
            self.tri,
            size,
            None,
            &[],
        )?;
        let args = self.antialias_args(&layer.rast, &color);
        let out = h.antialias(ctx, &args, self.topology)?;
        let n = out.len() as f32 / 3.0;
        let dy: Vec<f32> = out
            .iter()
            .zip(self.target)
            .map(|(o, t)| 2.0 * (o - t) / n)
            .collect();
        let (g_color, g_pos_antialias) = h.antialias_grad(ctx, &args, self.topology, &dy, 1.0)?;
        let g_interp = h.interpolate_grad(
            ctx,
            self.colors,
            self.layout,
            &layer.rast,
            self.tri,
            size,
            None,
            &[],
            &g_color,
            None,
        )?;
        let g_pos = h.rasterize_grad(
            ctx,
            s,
            self.pos,
            self.tri,
            &layer.rast,
            &g_interp.rast,
            None,
        )?;
        std::hint::black_box((g_pos, g_pos_antialias));
        Ok(Iteration {
            layer,
            color,
            dy,
            g_color,
            g_interp,
        })
    }

    /// `texture`'s lookups at a layer's interpolated uv and its pixel derivatives.
    fn lookup<'b>(&self, uv: &'b [f32], uv_da: &'b [f32]) -> Lookup<'b> {
        Lookup {
            grid: Lookups {
                batch: 1,
                height: self.shape.height,
                width: self.shape.width,
                uv_da: true,
                bias: false,
            },
            uv,
            uv_da: Some(uv_da),
            bias: None,
        }
    }

    /// rasterize → interpolate uv (with rast_db, its derivatives) → texture → antialias → L2
    /// → antialias, texture, interpolate and rasterize backward; the interpolated uv and
    /// `uv_da`, and the texture's output gradient, for the timed texture calls.
    fn iterate_textured(
        &self,
        ctx: &Context,
        h: &mut HardRasterizer,
        t: &mut TextureSampler,
    ) -> Result<Textured> {
        let s = self.shape;
        let size = [s.height, s.width];
        let layer = h.rasterize(ctx, s, self.pos, self.tri, None)?;
        let (uv, uv_da) = h.interpolate(
            ctx,
            self.uv,
            self.uv_layout,
            &layer.rast,
            self.tri,
            size,
            Some(&layer.rast_db),
            &[0, 1],
        )?;
        let lookup = self.lookup(&uv, &uv_da);
        let color = t.sample(
            ctx,
            &self.tex_layout,
            TEX_MODE,
            Levels::Build(self.tex),
            &lookup,
        )?;
        let args = self.antialias_args(&layer.rast, &color);
        let out = h.antialias(ctx, &args, self.topology)?;
        let n = out.len() as f32 / 3.0;
        let dy: Vec<f32> = out
            .iter()
            .zip(self.target)
            .map(|(o, t)| 2.0 * (o - t) / n)
            .collect();
        let (g_color, g_pos_antialias) = h.antialias_grad(ctx, &args, self.topology, &dy, 1.0)?;
        let g = t.sample_grad(
            ctx,
            &self.tex_layout,
            TEX_MODE,
            Levels::Build(self.tex),
            &lookup,
            &g_color,
        )?;
        let g_interp = h.interpolate_grad(
            ctx,
            self.uv,
            self.uv_layout,
            &layer.rast,
            self.tri,
            size,
            Some(&layer.rast_db),
            &[0, 1],
            &g.uv,
            Some(&g.uv_da),
        )?;
        let g_pos = h.rasterize_grad(
            ctx,
            s,
            self.pos,
            self.tri,
            &layer.rast,
            &g_interp.rast,
            Some(&g_interp.rast_db),
        )?;
        std::hint::black_box((g_pos, g_pos_antialias, g.stack));
        Ok(Textured { uv, uv_da, g_color })
    }
}

/// What the textured iteration leaves for the timed texture calls.
struct Textured {
    uv: Vec<f32>,
    uv_da: Vec<f32>,
    g_color: Vec<f32>,
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
    let mut sampler = TextureSampler::new(ctx)?;
    sampler.time_passes(ctx)?;
    let tex_layout = TexLayout::with_mips(1, 1024, 1024, 3, None)?;
    let tex: Vec<f32> = (0..tex_layout.level_texels(0) as u32 * 3)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 8) as f32 / 16_777_216.0)
        .collect();
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
        let uv: Vec<f32> = pos
            .chunks(4)
            .flat_map(|p| [0.5 + 1.2 * p[0] / p[3], 0.5 + 1.2 * p[1] / p[3]])
            .collect();
        let uv_layout = AttrLayout {
            attr_count: 2,
            ..layout
        };
        let topology = TopologyHash::new(&tri);
        let target = vec![0.25f32; 3 * n];
        let mut timed: Vec<Timed> = Vec::new();
        type Run<'r> = dyn FnMut(&mut HardRasterizer, &mut TextureSampler) -> Result<()> + 'r;
        let mut time = |what: &'static str,
                        run: &mut Run<'_>,
                        hard: &mut HardRasterizer,
                        sampler: &mut TextureSampler|
         -> Result<()> {
            run(hard, sampler)?; // warm-up: buffers grown, pipelines made
            hard.take_timings();
            sampler.take_timings();
            let mut walls = Vec::new();
            let mut passes = Vec::new();
            for _ in 0..repeat {
                let start = std::time::Instant::now();
                run(hard, sampler)?;
                walls.push(start.elapsed().as_secs_f64() * 1e3);
                passes.push(
                    hard.take_timings()
                        .into_iter()
                        .chain(sampler.take_timings())
                        .filter(|p| p.depth == 0)
                        .map(|p| (p.name, p.ms))
                        .collect(),
                );
            }
            timed.push((what, walls, passes));
            Ok(())
        };
        // The lanes the depth pass runs with (a size that is not a power of two up to 64 runs
        // as rows of 8: `visited_pairs` counts it so).
        let lanes = ctx.info().subgroup_size.clamp(1, 64);
        let visited_count = visited_pairs(&shape, &pos, &tri, lanes)?;
        let scene = IterationScene {
            shape: &shape,
            pos: &pos,
            tri: &tri,
            colors: &colors,
            layout,
            topology: &topology,
            target: &target,
            uv: &uv,
            uv_layout,
            tex_layout,
            tex: &tex,
        };
        // One untimed iteration gives every timed call its inputs.
        let it = scene.iterate(ctx, &mut hard)?;
        // The binning of its rasterize (the other primitives bin nothing).
        let entries = hard.entries().unwrap_or(0);
        let args = scene.antialias_args(&it.layer.rast, &it.color);
        let (layer, dy, g_color, g_interp) = (&it.layer, &it.dy, &it.g_color, &it.g_interp);
        time(
            "rasterize",
            &mut |h, _| h.rasterize(ctx, &shape, &pos, &tri, None).map(drop),
            &mut hard,
            &mut sampler,
        )?;
        let dy_rast = g_interp.rast.clone();
        time(
            "rasterize backward",
            &mut |h, _| {
                h.rasterize_grad(ctx, &shape, &pos, &tri, &layer.rast, &dy_rast, None)
                    .map(drop)
            },
            &mut hard,
            &mut sampler,
        )?;
        time(
            "interpolate",
            &mut |h, _| {
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
            &mut sampler,
        )?;
        time(
            "interpolate backward",
            &mut |h, _| {
                h.interpolate_grad(
                    ctx,
                    &colors,
                    layout,
                    &layer.rast,
                    &tri,
                    [size, size],
                    None,
                    &[],
                    g_color,
                    None,
                )
                .map(drop)
            },
            &mut hard,
            &mut sampler,
        )?;
        time(
            "antialias",
            &mut |h, _| h.antialias(ctx, &args, &topology).map(drop),
            &mut hard,
            &mut sampler,
        )?;
        time(
            "antialias backward",
            &mut |h, _| h.antialias_grad(ctx, &args, &topology, dy, 1.0).map(drop),
            &mut hard,
            &mut sampler,
        )?;
        time(
            "iteration",
            &mut |h, _| {
                scene
                    .iterate(ctx, h)
                    .map(|it| drop(std::hint::black_box(it)))
            },
            &mut hard,
            &mut sampler,
        )?;
        let textured = scene.iterate_textured(ctx, &mut hard, &mut sampler)?;
        let lookup = scene.lookup(&textured.uv, &textured.uv_da);
        time(
            "texture",
            &mut |_, t| {
                t.sample(ctx, &tex_layout, TEX_MODE, Levels::Build(&tex), &lookup)
                    .map(drop)
            },
            &mut hard,
            &mut sampler,
        )?;
        time(
            "texture backward",
            &mut |_, t| {
                t.sample_grad(
                    ctx,
                    &tex_layout,
                    TEX_MODE,
                    Levels::Build(&tex),
                    &lookup,
                    &textured.g_color,
                )
                .map(drop)
            },
            &mut hard,
            &mut sampler,
        )?;
        time(
            "textured iteration",
            &mut |h, t| {
                scene
                    .iterate_textured(ctx, h, t)
                    .map(|it| drop(std::hint::black_box(it)))
            },
            &mut hard,
            &mut sampler,
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
            let (binned, visited, ns) = if what == "rasterize" {
                let depth = passes.iter().find(|p| p.0 == "hard depth").map(|p| p.1);
                (
                    Some(entries * 64),
                    Some(visited_count),
                    depth.map(|ms| ms * 1e6 / visited_count.max(1) as f64),
                )
            } else {
                (None, None, None)
            };
            let record = HardRecord {
                scene: name.to_string(),
                pass: what,
                wall_ms: median(walls),
                passes,
                faces: tri.len() as u32,
                size,
                binned_pairs: binned,
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
                "size": r.size, "binned_pairs": r.binned_pairs, "visited_pairs": r.visited_pairs,
                "ns_per_visited_pair": r.ns_per_visited_pair, "device": r.device,
                "repeats": r.repeats, "passes": passes,
            })
            .to_string()
        })
        .collect();
    format!("[\n{}\n]\n", lines.join(",\n"))
}
