//! nvdiffrast's `antialias` on the GPU (`softvk::raster::hard::gpu`) against its f64 twin
//! (`softvk::raster::hard::antialias`), over `rast` from the GPU rasterizer: random triangle
//! soups (instanced and range mode, C = 1 and 3) and the closed, welded spot mesh from several
//! views. The forward per component within 1e-5 plus f32's floor, the colour and position
//! gradients within a relative bound plus a floor, everywhere but at the pixel pairs whose
//! decisions f32 rounding may take otherwise (found by perturbing the twin's inputs; counted and
//! bounded); the same bits twice; `pos_gradient_boost` as one f32 product.
//!
//! Measured (lavapipe; the same bits with `LP_NATIVE_VECTOR_WIDTH` 128 and 512 and
//! `SOFTVK_WORKGROUPS=gpu`): forward |GPU − twin| ≤ 6.7e-6 and colour gradient ≤ 4.2e-6, at most
//! 0.94 and 0.51 f32 ulps of (the image's half size + the pair's scale); position gradient
//! relative error ≤ 3.0e-4 on components above 10⁻³ of the largest (spot's small edges: 1/Δy),
//! |error| ≤ 1.8e-6 of the largest; 1 of 2849 blended pairs of the random scenes and none of
//! spot's 327 ambiguous.

mod common;

use common::hard::{clip, random_scene, wide};

use std::collections::{HashMap, HashSet};

use glam::Vec3;
use rand::RngExt;
use softvk::mesh::Mesh;
use softvk::raster::hard::antialias::{
    self, AntialiasInput, EdgePair, ImageShape, PosLayout, TopologyHash,
};
use softvk::raster::hard::gpu::{AntialiasArgs, HardRasterizer};
use softvk::raster::hard::{Shape, Topology};

/// One antialias call's arrays (f32, as the GPU takes them).
struct Case {
    name: String,
    shape: Shape,
    pos: Vec<f32>,
    tri: Vec<[u32; 3]>,
    rast: Vec<f32>,
    color: Vec<f32>,
    dy: Vec<f32>,
    channels: u32,
}

impl Case {
    /// Rasterizes `pos` with the GPU rasterizer and draws colours and an upstream gradient.
    #[allow(clippy::too_many_arguments)]
    fn new(
        name: &str,
        hard: &mut HardRasterizer,
        ctx: &softvk::gpu::Context,
        shape: Shape,
        pos: Vec<f32>,
        tri: Vec<[u32; 3]>,
        channels: u32,
        seed: u64,
    ) -> Case {
        let rast = hard.rasterize(ctx, &shape, &pos, &tri, None).unwrap().rast;
        let mut rng = common::rng(seed);
        let n = shape.pixels() * channels as usize;
        let color = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let dy = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
        Case {
            name: name.to_string(),
            shape,
            pos,
            tri,
            rast,
            color,
            dy,
            channels,
        }
    }

    fn instanced(&self) -> bool {
        matches!(self.shape.topology, Topology::Instanced { .. })
    }

    fn args(&self) -> AntialiasArgs<'_> {
        AntialiasArgs {
            color: &self.color,
            rast: &self.rast,
            pos: &self.pos,
            instanced: self.instanced(),
            vertex_count: self.shape.vertex_count,
            tri: &self.tri,
            batch: self.shape.batch(),
            height: self.shape.height,
            width: self.shape.width,
            channels: self.channels,
        }
    }

    fn image(&self) -> ImageShape {
        ImageShape {
            batch: self.shape.batch() as usize,
            height: self.shape.height as usize,
            width: self.shape.width as usize,
            channels: self.channels as usize,
        }
    }

    /// The twin's input over f64 copies (`color`, `rast`, `pos`).
    fn input<'a>(&'a self, wide: &'a Wide) -> AntialiasInput<'a> {
        let vertices = self.shape.vertex_count as usize;
        AntialiasInput {
            color: &wide.color,
            rast: &wide.rast,
            pos: &wide.pos,
            pos_layout: if self.instanced() {
                PosLayout::Instanced { vertices }
            } else {
                PosLayout::Range { vertices }
            },
            tri: &self.tri,
            shape: self.image(),
        }
    }

    /// The first vertex of minibatch item `b`'s set.
    fn vertex_base(&self, b: usize) -> usize {
        self.shape.vertex_base(b as u32)
    }
}

struct Wide {
    color: Vec<f64>,
    rast: Vec<f64>,
    pos: Vec<f64>,
}

/// Where a pair is: (minibatch item, column, row, next-row).
type PairAt = (usize, usize, usize, bool);

/// What a pair decides beyond its α: triangle, edge, whose triangle, the target, whether α
/// saturates (no position gradient) and whether it is +0.
type Decision = (usize, usize, bool, bool, bool, bool);

fn decisions(pairs: &[EdgePair]) -> HashMap<PairAt, Decision> {
    pairs
        .iter()
        .map(|p| {
            (
                (p.batch, p.x, p.y, p.vertical),
                (
                    p.triangle,
                    p.edge,
                    p.from_second,
                    p.alpha > 0.0,
                    p.alpha.abs() >= 0.5,
                    p.alpha.to_bits() == 0,
                ),
            )
        })
        .collect()
}

/// The pairs whose decisions f32 rounding may take otherwise: those that change (appear,
/// vanish or decide otherwise) when the twin runs on positions moved by a relative 2·10⁻⁶
/// (about 16 f32 ulps; x, y and w of every vertex independently, 12 draws).
fn ambiguous_pairs(case: &Case, wide: &Wide, hash: &TopologyHash) -> HashSet<PairAt> {
    let base = decisions(&antialias::find_edge_pairs(&case.input(wide), Some(hash)).unwrap());
    let mut rng = common::rng(99);
    let mut out = HashSet::new();
    for _ in 0..12 {
        let pos: Vec<f64> = wide
            .pos
            .iter()
            .enumerate()
            .map(|(k, &p)| {
                if k % 4 == 2 {
                    p
                } else {
                    p * (1.0 + 2e-6 * rng.random_range(-1.0..1.0))
                }
            })
            .collect();
        let moved = Wide {
            color: wide.color.clone(),
            rast: wide.rast.clone(),
            pos,
        };
        let other =
            decisions(&antialias::find_edge_pairs(&case.input(&moved), Some(hash)).unwrap());
        for (at, d) in &base {
            if other.get(at) != Some(d) {
                out.insert(*at);
            }
        }
        for at in other.keys() {
            if !base.contains_key(at) {
                out.insert(*at);
            }
        }
    }
    out
}

/// The pixel-frame magnitude of a pair's geometry: the largest |coordinate| of its edge's ends
/// relative to the triangle pixel's centre, and |x_c·Δy| + |a_x Δy| + |a_y Δx| over |Δy| (what
/// the crossing's f32 rounding is relative to).
fn pair_scale(case: &Case, wide: &Wide, p: &EdgePair) -> f64 {
    let (w, h) = (f64::from(case.shape.width), f64::from(case.shape.height));
    let (cx, cy) = match (p.from_second, p.vertical) {
        (false, _) => (p.x, p.y),
        (true, false) => (p.x + 1, p.y),
        (true, true) => (p.x, p.y + 1),
    };
    let base = case.vertex_base(p.batch);
    let frame = |v: u32| {
        let o = 4 * (base + v as usize);
        let q = &wide.pos[o..o + 4];
        let (x, y) = (
            q[0] / q[3] * w / 2.0 - (cx as f64 + 0.5 - w / 2.0),
            q[1] / q[3] * h / 2.0 - (cy as f64 + 0.5 - h / 2.0),
        );
        if p.vertical { (y, x) } else { (x, y) }
    };
    let t = case.tri[p.triangle];
    let (a, e) = (frame(t[(p.edge + 1) % 3]), frame(t[(p.edge + 2) % 3]));
    let (dx, dy) = (e.0 - a.0, e.1 - a.1);
    let m = a.0.abs().max(a.1.abs()).max(e.0.abs()).max(e.1.abs());
    m.max(((a.0 * dy).abs() + (a.1 * dx).abs()) / dy.abs())
}

/// What one case measured.
#[derive(Default, Debug)]
struct Report {
    pairs: usize,
    ambiguous: usize,
    /// Components left out of the comparison (touched by an ambiguous pair).
    skipped_out: usize,
    skipped_color: usize,
    skipped_pos: usize,
    /// Worst error over its bound.
    out: f64,
    color: f64,
    pos: f64,
    /// Raw measures: the largest |GPU − twin| of the forward and of the colour gradient, the
    /// same over f32's ulp of (the image's half size + the pixel's pair scale), the largest relative error of a
    /// position-gradient component above 10⁻³ of the largest, and the largest |error| over
    /// the largest component.
    out_abs: f64,
    color_abs: f64,
    out_ulps: f64,
    color_ulps: f64,
    pos_rel: f64,
    pos_abs: f64,
}

/// Compares the GPU with the twin on `case`; panics past the bounds.
fn compare(hard: &mut HardRasterizer, ctx: &softvk::gpu::Context, case: &Case) -> Report {
    let what = &case.name;
    let copies = Wide {
        color: wide(&case.color),
        rast: wide(&case.rast),
        pos: wide(&case.pos),
    };
    let input = case.input(&copies);
    let hash = antialias::antialias_construct_topology_hash(&case.tri);
    let img = case.image();
    let c = img.channels;
    let pairs = antialias::find_edge_pairs(&input, Some(&hash)).unwrap();
    let ambiguous = ambiguous_pairs(case, &copies, &hash);
    let mut report = Report {
        pairs: pairs.len(),
        ambiguous: ambiguous.len(),
        ..Report::default()
    };

    // Pixels an ambiguous pair may change (both of its pixels), and the vertices whose
    // gradients it may change (those of both pixels' triangles).
    let mut bad_pixels = HashSet::new();
    let mut bad_vertices = HashSet::new();
    for &(b, x, y, vertical) in &ambiguous {
        let p0 = (b * img.height + y) * img.width + x;
        let p1 = p0 + if vertical { img.width } else { 1 };
        for p in [p0, p1] {
            bad_pixels.insert(p);
            let id = case.rast[4 * p + 3];
            if id >= 1.0 && (id as usize) <= case.tri.len() {
                for &v in &case.tri[id as usize - 1] {
                    bad_vertices.insert(case.vertex_base(b) + v as usize);
                }
            }
        }
    }
    // Per pixel the largest pair scale and |Δcolour| of the pairs that target it or include it.
    let mut scale = vec![0.0f64; img.pixel_count()];
    for p in &pairs {
        let s = pair_scale(case, &copies, p);
        for q in [p.first_pixel(img), p.second_pixel(img)] {
            scale[q] = scale[q].max(s);
        }
    }

    // Forward.
    let twin = antialias::antialias(&input, Some(&hash)).unwrap();
    let gpu = hard.antialias(ctx, &case.args(), &hash).unwrap();
    let again = hard.antialias(ctx, &case.args(), &hash).unwrap();
    assert_eq!(
        bytemuck::cast_slice::<f32, u8>(&gpu),
        bytemuck::cast_slice::<f32, u8>(&again),
        "{what}: the same bits twice"
    );
    let eps = f64::from(f32::EPSILON);
    // f32 places a vertex in the pixel frame within an ulp or so of the image's half size (the
    // projection's magnitude before the pixel centre is subtracted) and of the pair's scale.
    let half = f64::from(case.shape.width.max(case.shape.height)) / 2.0;
    let unit = |p: usize| eps * (half + scale[p]);
    for (k, (&g, &t)) in gpu.iter().zip(&twin).enumerate() {
        let p = k / c;
        if bad_pixels.contains(&p) {
            report.skipped_out += 1;
            continue;
        }
        // 1e-5, plus α's rounding: a few units times |Δcolour| ≤ 2.
        let tol = 1e-5 + FLOOR_UNITS * unit(p) * 2.0;
        let d = (f64::from(g) - t).abs();
        let e = d / tol;
        if e > 1.0 {
            eprintln!("{what}: out[{k}] gpu {g} twin {t} scale {}", scale[p]);
        }
        report.out_abs = report.out_abs.max(d);
        report.out_ulps = report.out_ulps.max(d / unit(p));
        report.out = report.out.max(e);
    }

    // Backward.
    let dy = wide(&case.dy);
    let boost = 1.0;
    let tg = antialias::antialias_backward(&input, Some(&hash), &dy, boost).unwrap();
    let (gc, gp) = hard
        .antialias_grad(ctx, &case.args(), &hash, &case.dy, boost)
        .unwrap();
    let (gc2, gp2) = hard
        .antialias_grad(ctx, &case.args(), &hash, &case.dy, boost)
        .unwrap();
    assert_eq!(
        bytemuck::cast_slice::<f32, u8>(&gc),
        bytemuck::cast_slice::<f32, u8>(&gc2),
        "{what}: grad_color, the same bits twice"
    );
    assert_eq!(
        bytemuck::cast_slice::<f32, u8>(&gp),
        bytemuck::cast_slice::<f32, u8>(&gp2),
        "{what}: grad_pos, the same bits twice"
    );
    for (k, (&g, &t)) in gc.iter().zip(&tg.color).enumerate() {
        let p = k / c;
        if bad_pixels.contains(&p) {
            report.skipped_color += 1;
            continue;
        }
        // dy plus up to four α·g (|α| ≤ 1/2, |g| ≤ 1), each α within its rounding.
        let tol = 1e-5 + FLOOR_UNITS * unit(p) * 2.0;
        let d = (f64::from(g) - t).abs();
        let e = d / tol;
        if e > 1.0 {
            eprintln!("{what}: grad_color[{k}] gpu {g} twin {t}");
        }
        report.color_abs = report.color_abs.max(d);
        report.color_ulps = report.color_ulps.max(d / unit(p));
        report.color = report.color.max(e);
    }
    let pos_scale = tg.pos.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    for (k, (&g, &t)) in gp.iter().zip(&tg.pos).enumerate() {
        if k % 4 == 2 {
            assert_eq!(g, 0.0, "{what}: z takes no gradient");
        }
        if bad_vertices.contains(&(k / 4)) {
            report.skipped_pos += 1;
            continue;
        }
        let tol = POS_REL * t.abs() + POS_FLOOR * pos_scale;
        let d = (f64::from(g) - t).abs();
        let e = d / tol.max(f64::MIN_POSITIVE);
        if t.abs() > 1e-3 * pos_scale {
            report.pos_rel = report.pos_rel.max(d / t.abs());
        }
        report.pos_abs = report.pos_abs.max(d / pos_scale);
        if e > 1.0 {
            eprintln!("{what}: grad_pos[{k}] gpu {g} twin {t} (scale {pos_scale})");
        }
        report.pos = report.pos.max(e);
    }
    assert!(
        gp.iter().filter(|&&g| g != 0.0).count() > 0,
        "{what}: some position moves a silhouette"
    );

    // pos_gradient_boost: one f32 product per float, the colour gradient untouched.
    let (bc, bp) = hard
        .antialias_grad(ctx, &case.args(), &hash, &case.dy, 2.5)
        .unwrap();
    assert_eq!(bc, gc, "{what}: the boost leaves grad_color alone");
    for (&b, &g) in bp.iter().zip(&gp) {
        assert_eq!(b.to_bits(), (g * 2.5f32).to_bits(), "{what}: boost");
    }

    eprintln!(
        "{what}: {report:?}; bits digest {:016x}",
        digest(&[&gpu, &gc, &gp, &bp])
    );
    assert!(
        report.out <= 1.0,
        "{what}: forward at {} of its bound",
        report.out
    );
    assert!(
        report.color <= 1.0,
        "{what}: grad_color at {} of its bound",
        report.color
    );
    assert!(
        report.pos <= 1.0,
        "{what}: grad_pos at {} of its bound",
        report.pos
    );
    assert!(
        report.ambiguous * 20 <= report.pairs.max(20),
        "{what}: {} of {} pairs ambiguous",
        report.ambiguous,
        report.pairs
    );
    report
}

/// The forward's and the colour gradient's floor, in f32 ulps of (the image's half size + the
/// pair's scale) per unit of |Δcolour|.
const FLOOR_UNITS: f64 = 4.0;

/// FNV-1a of the arrays' bits: what runs under other driver settings
/// (`LP_NATIVE_VECTOR_WIDTH`, `SOFTVK_WORKGROUPS`) print to be compared.
fn digest(arrays: &[&[f32]]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for a in arrays {
        for v in *a {
            h = (h ^ u64::from(v.to_bits())).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    h
}

/// The position gradient's relative bound and floor (times the largest |component|).
const POS_REL: f64 = 1e-4;
const POS_FLOOR: f64 = 1e-5;

#[test]
fn random_scenes_match_the_twin_in_instanced_and_range_mode() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let mut total = Report::default();
    for (seed, width, height, channels) in
        [(1u64, 37u32, 29u32, 3u32), (2, 32, 32, 1), (3, 20, 45, 3)]
    {
        let (pos, tri) = random_scene(seed, 60, 90);
        let mut pos2 = pos.clone();
        pos2.extend(
            pos.chunks(4)
                .flat_map(|v| [v[0] * 0.7, v[1] * 0.8, v[2], v[3]]),
        );
        let instanced = Shape {
            width,
            height,
            vertex_count: 60,
            triangle_count: tri.len() as u32,
            topology: Topology::Instanced { batch: 2 },
        };
        let ranged = Shape {
            topology: Topology::Ranged(vec![[0, 50], [30, 60]]),
            ..instanced.clone()
        };
        for (mode, shape, pos) in [
            ("instanced", instanced, pos2),
            ("ranged", ranged, pos.clone()),
        ] {
            let case = Case::new(
                &format!("{mode} {width}x{height} C={channels}"),
                &mut hard,
                &ctx,
                shape,
                pos,
                tri.clone(),
                channels,
                seed + 100,
            );
            let r = compare(&mut hard, &ctx, &case);
            total.pairs += r.pairs;
            total.ambiguous += r.ambiguous;
        }
    }
    eprintln!(
        "random scenes: {} pairs blended, {} ambiguous",
        total.pairs, total.ambiguous
    );
    assert!(total.pairs > 500);
}

#[test]
fn a_closed_mesh_matches_the_twin_from_several_views() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let assets = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets");
    let mesh = Mesh::load_obj(&assets.join("spot_triangulated.obj"), 1).unwrap();
    let tri = mesh.faces.clone();
    let (w, h) = (128u32, 96u32);
    let mut rng = common::rng(17);
    let mut total = Report::default();
    for view in 0..3 {
        // Two views a minibatch, instanced (each its own vertices).
        let mut pos = Vec::new();
        for _ in 0..2 {
            let dir = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
            .normalize_or(Vec3::Z);
            pos.extend(clip(&mesh, dir * 3.2, w as f32 / h as f32));
        }
        let shape = Shape {
            width: w,
            height: h,
            vertex_count: mesh.positions.len() as u32,
            triangle_count: tri.len() as u32,
            topology: Topology::Instanced { batch: 2 },
        };
        let channels = if view == 1 { 1 } else { 3 };
        let case = Case::new(
            &format!("spot views {view} C={channels}"),
            &mut hard,
            &ctx,
            shape,
            pos,
            tri.clone(),
            channels,
            200 + view,
        );
        let r = compare(&mut hard, &ctx, &case);
        total.pairs += r.pairs;
        total.ambiguous += r.ambiguous;
    }
    // One view in range mode: the positions shared by both minibatch items, each drawing all
    // triangles (the same image twice).
    let pos = clip(
        &mesh,
        Vec3::new(0.3, 0.5, 1.0).normalize() * 3.2,
        w as f32 / h as f32,
    );
    let shape = Shape {
        width: w,
        height: h,
        vertex_count: mesh.positions.len() as u32,
        triangle_count: tri.len() as u32,
        topology: Topology::Ranged(vec![[0, tri.len() as u32]; 2]),
    };
    let case = Case::new("spot ranged C=3", &mut hard, &ctx, shape, pos, tri, 3, 300);
    let r = compare(&mut hard, &ctx, &case);
    total.pairs += r.pairs;
    total.ambiguous += r.ambiguous;
    eprintln!(
        "spot: {} pairs blended, {} ambiguous",
        total.pairs, total.ambiguous
    );
    assert!(total.pairs > 300);
}

#[test]
fn inconsistent_inputs_are_rejected() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let tri = vec![[0u32, 1, 2]];
    let pos = vec![
        -0.5f32, -0.5, 0.0, 1.0, 0.5, -0.5, 0.0, 1.0, 0.0, 0.5, 0.0, 1.0,
    ];
    let (w, h) = (8u32, 8u32);
    let rast = vec![0.0f32; 4 * 64];
    let color = vec![0.0f32; 64];
    let hash = TopologyHash::new(&tri);
    let args = AntialiasArgs {
        color: &color,
        rast: &rast,
        pos: &pos,
        instanced: true,
        vertex_count: 3,
        tri: &tri,
        batch: 1,
        height: h,
        width: w,
        channels: 1,
    };
    assert_eq!(hard.antialias(&ctx, &args, &hash).unwrap(), color);
    assert!(
        hard.antialias(
            &ctx,
            &AntialiasArgs {
                color: &color[1..],
                ..args
            },
            &hash
        )
        .is_err()
    );
    assert!(
        hard.antialias(
            &ctx,
            &AntialiasArgs {
                rast: &rast[4..],
                ..args
            },
            &hash
        )
        .is_err()
    );
    assert!(
        hard.antialias(
            &ctx,
            &AntialiasArgs {
                vertex_count: 4,
                ..args
            },
            &hash
        )
        .is_err()
    );
    assert!(
        hard.antialias(
            &ctx,
            &AntialiasArgs {
                tri: &[[0, 1, 3]],
                ..args
            },
            &hash
        )
        .is_err()
    );
    let other = TopologyHash::new(&[[0, 1, 2], [0, 2, 1]]);
    assert!(hard.antialias(&ctx, &args, &other).is_err());
    assert!(
        hard.antialias_grad(&ctx, &args, &hash, &color[1..], 1.0)
            .is_err()
    );
}

#[test]
fn a_crossing_in_the_slack_saturates_as_in_the_twin() {
    // The twin's own case: a triangle right of a vertical edge at pixel x = 1.53 in a 4 × 1
    // image, pixel 1 (centre 1.5) marked covered anyway, as a snapping rasterizer may: the
    // crossing lies in the slack behind pixel 1's centre, r clamps to 0, α = −1/2, pixel 1
    // becomes the mean of the two and no gradient reaches the positions.
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let at = |px: f32| 2.0 * px / 4.0 - 1.0;
    let edge_at = |px: f32| {
        vec![
            10.0f32,
            -10.0,
            0.0,
            1.0,
            at(px),
            10.0,
            0.0,
            1.0,
            at(px),
            -10.0,
            0.0,
            1.0,
        ]
    };
    let tri = vec![[0u32, 1, 2]];
    let rast: Vec<f32> = [0.0f32, 1.0, 1.0, 1.0]
        .iter()
        .flat_map(|&id| [0.0, 0.0, 0.0, id])
        .collect();
    let color = vec![0.0f32, 1.0, 5.0, 6.0];
    let hash = TopologyHash::new(&tri);
    let slack = edge_at(1.53);
    let base = AntialiasArgs {
        color: &color,
        rast: &rast,
        pos: &slack,
        instanced: false,
        vertex_count: 3,
        tri: &tri,
        batch: 1,
        height: 1,
        width: 4,
        channels: 1,
    };
    let args = |pos| AntialiasArgs { pos, ..base };
    let dy = [0.0f32, 1.0, 0.0, 0.0];
    assert_eq!(
        hard.antialias(&ctx, &args(&slack), &hash).unwrap(),
        [0.0, 0.5, 5.0, 6.0]
    );
    let (gc, gp) = hard
        .antialias_grad(&ctx, &args(&slack), &hash, &dy, 1.0)
        .unwrap();
    assert_eq!(gc, [0.5, 0.5, 0.0, 0.0]);
    assert!(gp.iter().all(|&g| g == 0.0));
    // Past the slack (0.1 px outside) nothing is blended.
    let past = edge_at(1.6);
    assert_eq!(hard.antialias(&ctx, &args(&past), &hash).unwrap(), color);
    // Inside the triangle (the edge at 1.3 px): r = 0.2, α = −0.3, a gradient to the edge's
    // x and w and none to z or to the far vertex.
    let inside = edge_at(1.3);
    let out = hard.antialias(&ctx, &args(&inside), &hash).unwrap();
    assert!((out[1] - 0.7).abs() < 1e-6, "{out:?}");
    let (_, gp) = hard
        .antialias_grad(&ctx, &args(&inside), &hash, &dy, 1.0)
        .unwrap();
    assert!(gp[..4].iter().all(|&g| g == 0.0));
    // d out₁ / d x_edge: moving the edge right by one NDC unit (2 px) brings the crossing 2 px
    // nearer pixel 1's centre, lowering α·Δc by 2 (less 10⁻⁴ for nvdiffrast's guard on the
    // edge's 10 px extent).
    assert!((gp[4] + gp[8] + 2.0).abs() < 1e-3, "{gp:?}");
    assert_eq!((gp[6], gp[10]), (0.0, 0.0));
}

#[test]
fn no_triangles_leave_the_image_alone() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let tri: Vec<[u32; 3]> = Vec::new();
    let pos = vec![0.0f32, 0.0, 0.0, 1.0];
    let rast = vec![0.0f32; 4 * 30];
    let color: Vec<f32> = (0..60).map(|i| i as f32).collect();
    let hash = TopologyHash::new(&tri);
    let args = AntialiasArgs {
        color: &color,
        rast: &rast,
        pos: &pos,
        instanced: true,
        vertex_count: 1,
        tri: &tri,
        batch: 1,
        height: 5,
        width: 6,
        channels: 2,
    };
    assert_eq!(hard.antialias(&ctx, &args, &hash).unwrap(), color);
    let (gc, gp) = hard
        .antialias_grad(&ctx, &args, &hash, &color, 3.0)
        .unwrap();
    assert_eq!(gc, color);
    assert_eq!(gp, [0.0; 4]);
}
