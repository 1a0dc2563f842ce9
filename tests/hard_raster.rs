//! nvdiffrast's rasterizer on the GPU (`softvk::raster::hard::gpu`) against its f64 twin
//! (`softvk::raster::hard::reference`): ids exactly wherever the twin does not flag a pixel as
//! one f32 may decide otherwise (counted and bounded), `u, v, z/w` within 1e-5 and `rast_db`
//! within 1e-5 relative; in instanced and range mode, square and not, with triangles through
//! the near and far planes, behind the eye and beyond the viewport; depth peeling layer by
//! layer; and the fill rule on closed meshes from 50 random views (every pixel centre inside
//! the silhouette drawn once by a front face and once by a back face, none twice).

mod common;

use common::hard::{clip, fnv1a, random_scene, wide};

use glam::Vec3;
use rand::RngExt;
use softvk::mesh::Mesh;
use softvk::raster::hard::gpu::{HardLayer, HardPlan, HardRasterizer};
use softvk::raster::hard::reference::{self, Coverage, DepthKey, Layer};
use softvk::raster::hard::{Shape, Topology};

/// How much f32 rounding the pixel's barycentrics carry: the sum of the magnitudes of the
/// products in the three edge functions over their sum (1 for a centre well inside a large
/// triangle; large for a centre far from a tiny one, where nvdiffrast's own f32 arithmetic is
/// as inexact).
fn condition(shape: &Shape, pos: &[f64], tri: &[[u32; 3]], i: usize, t: u32) -> f64 {
    let (w, h) = (shape.width as usize, shape.height as usize);
    let b = i / (w * h);
    let (x, y) = ((i % (w * h)) % w, (i % (w * h)) / w);
    let f = reference::pixel_ndc(x as u32, y as u32, shape.width, shape.height);
    let base = shape.vertex_base(b as u32);
    let r: Vec<[f64; 2]> = tri[t as usize]
        .iter()
        .map(|&v| {
            let o = 4 * (base + v as usize);
            [pos[o] - f[0] * pos[o + 3], pos[o + 1] - f[1] * pos[o + 3]]
        })
        .collect();
    let (mut mag, mut sum) = (0.0, 0.0);
    for (i, j) in [(1, 2), (2, 0), (0, 1)] {
        let (p, q) = (r[i][0] * r[j][1], r[i][1] * r[j][0]);
        mag += p.abs() + q.abs();
        sum += p - q;
    }
    mag / sum.abs()
}

/// Compares a GPU layer with the twin's: ids exactly except at pixels the twin flags as
/// ambiguous (returns how many of those differ); `u, v, z/w` within 1e-5 and `rast_db` within
/// 1e-5 relative, plus f32's own floor: 4e-7 (seven roundings) times the pixel's
/// [`condition`], and the pixel derivatives times two ulps of the image's half size (where
/// f32 puts the centre).
fn compare(
    gpu: &HardLayer,
    twin: &Layer,
    scene: (&Shape, &[f64], &[[u32; 3]]),
    what: &str,
) -> usize {
    let pixels = twin.keys.len();
    let mut differ = 0;
    let (mut worst_uvz, mut worst_db, mut worst_cond) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..pixels {
        let (g, t) = (&gpu.rast[4 * i..4 * i + 4], &twin.rast[4 * i..4 * i + 4]);
        if f64::from(g[3]) != t[3] {
            assert!(
                twin.ambiguous[i],
                "{what}: pixel {i}: GPU id {} twin {} (not an ambiguous pixel)",
                g[3], t[3]
            );
            differ += 1;
            continue;
        }
        let Some(k) = twin.keys[i] else {
            assert!(
                g.iter()
                    .chain(&gpu.rast_db[4 * i..4 * i + 4])
                    .all(|&v| v == 0.0)
            );
            continue;
        };
        let cond = condition(scene.0, scene.1, scene.2, i, k.triangle);
        worst_cond = worst_cond.max(cond);
        // f32 places the centre (and each p_k − f w_k) within a few ulps of NDC: that moves
        // u and v by their pixel derivatives times a few ulps of the image's half size.
        let db: f64 = twin.rast_db[4 * i..4 * i + 4].iter().map(|d| d.abs()).sum();
        let half = f64::from(scene.0.width.max(scene.0.height)) / 2.0;
        let tol = 1e-5 + 4e-7 * cond + 2.0 * f64::from(f32::EPSILON) * half * db;
        for c in 0..3 {
            let e = (f64::from(g[c]) - t[c]).abs() / tol;
            if e > 0.5 && std::env::var("HARD_DEBUG").is_ok() {
                eprintln!(
                    "{what}: pixel {i} channel {c}: gpu {} twin {} cond {cond}",
                    g[c], t[c]
                );
            }
            worst_uvz = worst_uvz.max(e);
        }
        for c in 0..4 {
            let (gd, td) = (f64::from(gpu.rast_db[4 * i + c]), twin.rast_db[4 * i + c]);
            worst_db = worst_db.max((gd - td).abs() / (1.0 + td.abs()) / tol);
        }
    }
    assert!(
        worst_uvz <= 1.0,
        "{what}: u, v, z/w at {worst_uvz} of their bound"
    );
    assert!(
        worst_db <= 1.0,
        "{what}: rast_db at {worst_db} of its bound"
    );
    eprintln!(
        "{what}: {differ} ambiguous pixels differ; u, v, z/w at {worst_uvz:.2}, rast_db at \
         {worst_db:.2} of their bounds (largest condition {worst_cond:.0})"
    );
    differ
}

fn drawn(layer: &Layer) -> usize {
    layer.keys.iter().filter(|k| k.is_some()).count()
}

#[test]
fn random_scenes_match_the_twin_in_instanced_and_range_mode() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    for (seed, width, height) in [(1u64, 37u32, 29u32), (2, 32, 32), (3, 20, 45)] {
        let (pos, tri) = random_scene(seed, 60, 90);
        // Instanced: two minibatch items over different vertices (the second scaled).
        let mut pos2 = pos.clone();
        pos2.extend(
            pos.chunks(4)
                .flat_map(|v| [v[0] * 0.7, v[1] * 0.8, v[2], v[3]]),
        );
        let shape = Shape {
            width,
            height,
            vertex_count: 60,
            triangle_count: tri.len() as u32,
            topology: Topology::Instanced { batch: 2 },
        };
        let gpu = hard.rasterize(&ctx, &shape, &pos2, &tri, None).unwrap();
        let twin = reference::rasterize(&shape, &wide(&pos2), &tri, None);
        assert!(
            drawn(&twin) > (width * height) as usize / 2,
            "the scene draws most pixels"
        );
        let differ = compare(
            &gpu,
            &twin,
            (&shape, &wide(&pos2), &tri),
            &format!("instanced {width}x{height}"),
        );
        assert!(
            differ * 200 < twin.keys.len(),
            "{differ} ambiguous pixels differ"
        );
        // Range mode: item 0 the first 50 triangles, item 1 triangles 30..90 (overlapping).
        let ranged = Shape {
            topology: Topology::Ranged(vec![[0, 50], [30, 60]]),
            ..shape.clone()
        };
        let gpu = hard.rasterize(&ctx, &ranged, &pos, &tri, None).unwrap();
        let twin = reference::rasterize(&ranged, &wide(&pos), &tri, None);
        compare(
            &gpu,
            &twin,
            (&ranged, &wide(&pos), &tri),
            &format!("ranged {width}x{height}"),
        );
        // Triangles of other ranges never appear.
        for (i, k) in twin.keys.iter().enumerate() {
            if let Some(k) = k {
                let item = i / (width * height) as usize;
                assert!(if item == 0 {
                    k.triangle < 50
                } else {
                    k.triangle >= 30
                });
            }
        }
    }
}

#[test]
fn depth_peeling_returns_every_layer_in_order_then_nothing() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let (pos, tri) = random_scene(7, 40, 60);
    let shape = Shape {
        width: 24,
        height: 20,
        vertex_count: 40,
        triangle_count: 60,
        topology: Topology::Instanced { batch: 1 },
    };
    let pos64 = wide(&pos);
    let mut gpu_prev: Option<Vec<[u32; 2]>> = None;
    let mut twin_prev: Option<Vec<Option<DepthKey>>> = None;
    let mut layers = 0;
    loop {
        let gpu = hard
            .rasterize(&ctx, &shape, &pos, &tri, gpu_prev.as_deref())
            .unwrap();
        let twin = reference::rasterize(&shape, &pos64, &tri, twin_prev.as_deref());
        // Where an earlier layer differed, the two peel from different surfaces: compare only
        // layers that agree so far (the scene is drawn clear of ambiguity in every test run).
        let differ = compare(
            &gpu,
            &twin,
            (&shape, &pos64, &tri),
            &format!("layer {layers}"),
        );
        assert_eq!(differ, 0, "layer {layers}");
        if let Some(prev) = &twin_prev {
            for (i, k) in twin.keys.iter().enumerate() {
                if let Some(k) = k {
                    let p = prev[i].expect("a surface behind one that was drawn");
                    assert!(
                        p.before(k),
                        "pixel {i}: layer {layers} is not behind the last"
                    );
                }
            }
        }
        if drawn(&twin) == 0 {
            assert!(gpu.rast.iter().all(|&v| v == 0.0));
            break;
        }
        layers += 1;
        gpu_prev = Some(gpu.keys);
        twin_prev = Some(twin.keys);
        assert!(layers < 60, "peeling does not end");
    }
    assert!(layers >= 4, "the scene has {layers} layers");
}

/// A tile whose run is longer than one depth pass visits (the driver's loop cap on lavapipe,
/// `HardPlan::depth_passes`) is finished by the later passes, from the keys the earlier left,
/// in the first layer and the next; partial tiles on the right and at the bottom.
#[test]
fn tiles_crowded_past_one_depth_pass_match_the_twin() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let (pos, tri) = random_scene(11, 300, 9000);
    let shape = Shape {
        width: 13,
        height: 9,
        vertex_count: 300,
        triangle_count: tri.len() as u32,
        topology: Topology::Instanced { batch: 1 },
    };
    let pos64 = wide(&pos);
    // The tile holding the image's centre (snapped (0, 0)) is binned every homogeneous item and
    // every snapped one whose box holds the centre.
    let crowd =
        tri.iter()
            .filter(|t| {
                let c = t.map(|v| std::array::from_fn(|k| pos64[4 * v as usize + k]));
                match reference::coverage(c, shape.width, shape.height) {
                    Some(Coverage::Snapped(q)) => (0..2)
                        .all(|k| q.p.iter().any(|p| p[k] <= 0) && q.p.iter().any(|p| p[k] >= 0)),
                    Some(Coverage::Homogeneous) => true,
                    None => false,
                }
            })
            .count() as u64;
    if ctx.info().shader_loop_limit().is_some() {
        let plan = HardPlan::new(&ctx, &shape).unwrap();
        assert!(
            plan.depth_passes(crowd) >= 2,
            "{crowd} items in the centre's tile fit one depth pass: the test crowds none past it"
        );
    }
    let first = hard.rasterize(&ctx, &shape, &pos, &tri, None).unwrap();
    let twin = reference::rasterize(&shape, &pos64, &tri, None);
    assert!(drawn(&twin) == 13 * 9, "the scene covers the image");
    let differ = compare(&first, &twin, (&shape, &pos64, &tri), "crowded, layer 0");
    assert_eq!(differ, 0, "crowded, layer 0");
    let next = hard
        .rasterize(&ctx, &shape, &pos, &tri, Some(&first.keys))
        .unwrap();
    let twin_next = reference::rasterize(&shape, &pos64, &tri, Some(&twin.keys));
    let differ = compare(
        &next,
        &twin_next,
        (&shape, &pos64, &tri),
        "crowded, layer 1",
    );
    assert_eq!(differ, 0, "crowded, layer 1");
}

#[test]
fn a_closed_mesh_from_fifty_views_has_no_hole_and_no_pixel_drawn_twice() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let assets = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets");
    let mesh = Mesh::load_obj(&assets.join("spot_triangulated.obj"), 1).unwrap();
    let tri = mesh.faces.clone();
    let (w, h) = (40u32, 32u32);
    let mut rng = common::rng(11);
    let (mut inside_total, mut on_edges, mut compared) = (0usize, 0usize, 0usize);
    for view in 0..50 {
        let dir = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize_or(Vec3::Z);
        let pos = clip(&mesh, dir * 3.2, w as f32 / h as f32);
        let pos64 = wide(&pos);
        // Per pixel: how many front-facing and back-facing snapped triangles cover its centre.
        let mut front = vec![0u32; (w * h) as usize];
        let mut back = vec![0u32; (w * h) as usize];
        for t in &tri {
            let c = t.map(|v| {
                let o = 4 * v as usize;
                [pos64[o], pos64[o + 1], pos64[o + 2], pos64[o + 3]]
            });
            let q = match reference::coverage(c, w, h) {
                Some(Coverage::Snapped(q)) => q,
                None => continue, // zero area once snapped: draws nothing
                Some(Coverage::Homogeneous) => panic!("view {view}: the mesh is in view"),
            };
            // Screen-space winding of the snapped corners as given (Snapped is reordered).
            let s = c.map(|v| reference::snap(&v, w, h, 0.0).0);
            let area = (s[1][0] - s[0][0]) * (s[2][1] - s[0][1])
                - (s[1][1] - s[0][1]) * (s[2][0] - s[0][0]);
            for y in 0..h {
                for x in 0..w {
                    if q.covers(reference::sample(x, y, w, h)) {
                        on_edges += usize::from((0..3).any(|k| {
                            reference::edge_function(
                                q.p[k],
                                q.p[(k + 1) % 3],
                                reference::sample(x, y, w, h),
                            ) == 0
                        }));
                        let i = (y * w + x) as usize;
                        if area > 0 {
                            front[i] += 1
                        } else {
                            back[i] += 1
                        }
                    }
                }
            }
        }
        // spot is closed: along every ray as many front faces as back faces. Pixels of its
        // silhouette are covered once each way or more (folds), never unevenly.
        for i in 0..(w * h) as usize {
            assert_eq!(
                front[i], back[i],
                "view {view}, pixel {i}: a hole or a pixel drawn twice"
            );
            inside_total += usize::from(front[i] > 0);
        }
        let shape = Shape {
            width: w,
            height: h,
            vertex_count: mesh.positions.len() as u32,
            triangle_count: tri.len() as u32,
            topology: Topology::Instanced { batch: 1 },
        };
        let gpu = hard.rasterize(&ctx, &shape, &pos, &tri, None).unwrap();
        let twin = reference::rasterize(&shape, &pos64, &tri, None);
        for (i, (k, f)) in twin.keys.iter().zip(&front).enumerate() {
            assert_eq!(k.is_some(), *f > 0, "view {view}: pixel {i}");
        }
        compared += (w * h) as usize
            - compare(
                &gpu,
                &twin,
                (&shape, &pos64, &tri),
                &format!("spot view {view}"),
            );
    }
    eprintln!(
        "{inside_total} centres inside the silhouettes, {on_edges} covers exactly on an edge, {compared} pixels agree"
    );
    assert!(inside_total > 50 * 200);
}

/// `Σ dy·rast + ddb·rast_db` of a twin layer over the pixels `keep` allows.
fn loss(layer: &Layer, dy: &[f64], ddb: &[f64], keep: &[bool]) -> f64 {
    let mut sum = 0.0;
    for (i, &k) in keep.iter().enumerate() {
        if k {
            for c in 0..2 {
                sum += dy[4 * i + c] * layer.rast[4 * i + c];
            }
            for c in 0..4 {
                sum += ddb[4 * i + c] * layer.rast_db[4 * i + c];
            }
        }
    }
    sum
}

#[test]
fn the_backward_matches_the_twin_which_matches_central_differences() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let (pos, tri) = random_scene(21, 24, 30);
    let mut pos2 = pos.clone();
    pos2.extend(pos.chunks(4).flat_map(|v| [v[1] * 0.9, v[0], v[2], v[3]]));
    for shape in [
        Shape {
            width: 19,
            height: 16,
            vertex_count: 24,
            triangle_count: 30,
            topology: Topology::Instanced { batch: 2 },
        },
        Shape {
            width: 16,
            height: 21,
            vertex_count: 24,
            triangle_count: 30,
            topology: Topology::Ranged(vec![[0, 20], [10, 20]]),
        },
    ] {
        let pos = if shape.pos_len() == pos2.len() {
            &pos2
        } else {
            &pos
        };
        let pos64 = wide(pos);
        let n = shape.pixels();
        let mut rng = common::rng(5);
        let dy: Vec<f32> = (0..4 * n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let ddb: Vec<f32> = (0..4 * n).map(|_| rng.random_range(-0.05..0.05)).collect();
        let layer = hard.rasterize(&ctx, &shape, pos, &tri, None).unwrap();
        let gpu = hard
            .rasterize_grad(&ctx, &shape, pos, &tri, &layer.rast, &dy, Some(&ddb))
            .unwrap();
        let gpu_again = hard
            .rasterize_grad(&ctx, &shape, pos, &tri, &layer.rast, &dy, Some(&ddb))
            .unwrap();
        assert_eq!(
            bytemuck::cast_slice::<f32, u8>(&gpu),
            bytemuck::cast_slice::<f32, u8>(&gpu_again),
            "the same bits twice"
        );
        let (dy64, ddb64) = (wide(&dy), wide(&ddb));
        let twin = reference::rasterize_grad(
            &shape,
            &pos64,
            &tri,
            &wide(&layer.rast),
            &dy64,
            Some(&ddb64),
        );
        let scale = twin.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        let mut worst = 0.0f64;
        for (k, (&g, &t)) in gpu.iter().zip(&twin).enumerate() {
            if k % 4 == 2 {
                assert_eq!(g, 0.0, "z takes no gradient");
            }
            worst = worst.max((f64::from(g) - t).abs() / (1e-4 * (1.0 + t.abs()) + 1e-6 * scale));
        }
        assert!(
            worst <= 1.0,
            "GPU backward at {worst} of its bound against the twin"
        );
        // The twin against central differences of its own forward, for fixed visibility:
        // pixels whose triangle changes under the step are left out of both sides.
        let base = reference::rasterize(&shape, &pos64, &tri, None);
        let h = 1e-6;
        let (mut fd_worst, mut skipped) = (0.0f64, 0);
        for k in (0..pos64.len()).filter(|k| k % 4 != 2) {
            let moved = |d: f64| {
                let mut p = pos64.clone();
                p[k] += d;
                reference::rasterize(&shape, &p, &tri, None)
            };
            let (plus, minus) = (moved(h), moved(-h));
            let keep: Vec<bool> = (0..n)
                .map(|i| {
                    base.keys[i].map(|k| k.triangle) == plus.keys[i].map(|k| k.triangle)
                        && base.keys[i].map(|k| k.triangle) == minus.keys[i].map(|k| k.triangle)
                })
                .collect();
            let mut masked = dy64.clone();
            let mut masked_db = ddb64.clone();
            for (i, &kp) in keep.iter().enumerate() {
                if !kp {
                    skipped += 1;
                    masked[4 * i..4 * i + 4].fill(0.0);
                    masked_db[4 * i..4 * i + 4].fill(0.0);
                }
            }
            let fd = (loss(&plus, &dy64, &ddb64, &keep) - loss(&minus, &dy64, &ddb64, &keep))
                / (2.0 * h);
            let g = reference::rasterize_grad(
                &shape,
                &pos64,
                &tri,
                &base.rast,
                &masked,
                Some(&masked_db),
            )[k];
            fd_worst = fd_worst.max((fd - g).abs() / (1.0 + g.abs()));
        }
        eprintln!(
            "{:?}: GPU at {worst:.3} of its bound; twin − central differences {fd_worst:.1e} ({skipped} pixel steps left out)",
            shape.topology
        );
        assert!(
            fd_worst < 1e-5,
            "twin against central differences: {fd_worst:e}"
        );
    }
}

#[test]
fn interpolate_and_its_backward_match_the_twin() {
    use softvk::raster::hard::reference::AttrLayout;
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let (pos, tri) = random_scene(31, 30, 40);
    let mut pos2 = pos.clone();
    pos2.extend(pos.chunks(4).flat_map(|v| [v[0] * 0.8, v[1], v[2], v[3]]));
    let shape = Shape {
        width: 23,
        height: 18,
        vertex_count: 30,
        triangle_count: 40,
        topology: Topology::Instanced { batch: 2 },
    };
    let layer = hard.rasterize(&ctx, &shape, &pos2, &tri, None).unwrap();
    let n = shape.pixels();
    let mut rng = common::rng(9);
    for (per_item, a, diff) in [
        (false, 3u32, vec![2u32, 0]),
        (true, 2, vec![1, 1, 0]),
        (false, 1, vec![]),
    ] {
        let layout = AttrLayout {
            vertex_count: 30,
            attr_count: a,
            per_item,
        };
        let rows = if per_item { 60 } else { 30 };
        let attr: Vec<f32> = (0..rows * a as usize)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let db = (!diff.is_empty()).then_some(&layer.rast_db[..]);
        let (out, out_da) = hard
            .interpolate(&ctx, &attr, layout, &layer.rast, &tri, [18, 23], db, &diff)
            .unwrap();
        let (tout, tda) = reference::interpolate(
            &wide(&attr),
            layout,
            &wide(&layer.rast),
            &tri,
            23 * 18,
            db.map(wide).as_deref(),
            &diff,
        );
        let err = |g: &[f32], t: &[f64]| {
            assert_eq!(g.len(), t.len());
            g.iter()
                .zip(t)
                .map(|(&g, &t)| (f64::from(g) - t).abs() / (1.0 + t.abs()))
                .fold(0.0, f64::max)
        };
        let (e_out, e_da) = (err(&out, &tout), err(&out_da, &tda));
        assert!(
            e_out < 1e-6 && e_da < 1e-5,
            "interpolate: {e_out:e}, {e_da:e}"
        );
        let dy: Vec<f32> = (0..n * a as usize)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let dda: Vec<f32> = (0..n * 2 * diff.len())
            .map(|_| rng.random_range(-0.1..0.1))
            .collect();
        let dda_opt = (!diff.is_empty()).then_some(&dda[..]);
        let g = hard
            .interpolate_grad(
                &ctx,
                &attr,
                layout,
                &layer.rast,
                &tri,
                [18, 23],
                db,
                &diff,
                &dy,
                dda_opt,
            )
            .unwrap();
        let again = hard
            .interpolate_grad(
                &ctx,
                &attr,
                layout,
                &layer.rast,
                &tri,
                [18, 23],
                db,
                &diff,
                &dy,
                dda_opt,
            )
            .unwrap();
        assert_eq!(g, again, "the same gradients twice");
        let t = reference::interpolate_grad(
            &wide(&attr),
            layout,
            &wide(&layer.rast),
            &tri,
            23 * 18,
            db.map(wide).as_deref(),
            &diff,
            &wide(&dy),
            dda_opt.map(wide).as_deref(),
        );
        let (ea, er, ed) = (
            err(&g.attr, &t.attr),
            err(&g.rast, &t.rast),
            err(&g.rast_db, &t.rast_db),
        );
        eprintln!(
            "interpolate A = {a}, per item {per_item}, diff {diff:?}: out {e_out:.1e}, da {e_da:.1e}; grads attr {ea:.1e} rast {er:.1e} rast_db {ed:.1e}"
        );
        assert!(
            ea < 1e-5 && er < 1e-5 && ed < 1e-5,
            "interpolate backward: {ea:e} {er:e} {ed:e}"
        );
    }
}

/// Every output of every primitive, forward and backward, on spot from two views at 40×28
/// with depth peeling, hashed: the same bytes on every run and, since no sum's order depends on
/// the lanes or the workgroups, at 4, 8 and 16 lanes and with GPU workgroup shapes (CI reruns
/// this file in each), against `tests/data/hard-golden.txt`. A change that alters an output on
/// purpose regenerates that list (`HARD_GOLDEN=print` prints it) and says why in its commit.
#[test]
fn every_primitive_writes_the_golden_bytes() {
    use softvk::raster::hard::antialias::TopologyHash;
    use softvk::raster::hard::gpu::AntialiasArgs;
    use softvk::raster::hard::reference::AttrLayout;
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    let assets = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets");
    let mesh = Mesh::load_obj(&assets.join("spot_triangulated.obj"), 1).unwrap();
    let tri = mesh.faces.clone();
    let (w, h) = (40u32, 28u32);
    let mut pos = clip(&mesh, Vec3::new(1.5, 1.0, 2.5), w as f32 / h as f32);
    pos.extend(clip(&mesh, Vec3::new(-2.8, 0.4, -1.2), w as f32 / h as f32));
    let v = mesh.positions.len() as u32;
    let shape = Shape {
        width: w,
        height: h,
        vertex_count: v,
        triangle_count: tri.len() as u32,
        topology: Topology::Instanced { batch: 2 },
    };
    let n = shape.pixels();
    let mut hashes: Vec<(String, u64)> = Vec::new();
    let first = hard.rasterize(&ctx, &shape, &pos, &tri, None).unwrap();
    let second = hard
        .rasterize(&ctx, &shape, &pos, &tri, Some(&first.keys))
        .unwrap();
    hashes.push(("rast".into(), fnv1a(&first.rast)));
    hashes.push(("rast_db".into(), fnv1a(&first.rast_db)));
    hashes.push(("rast layer 2".into(), fnv1a(&second.rast)));
    let colors: Vec<f32> = mesh
        .positions
        .iter()
        .flat_map(|p| [0.5 + 0.5 * p[0], 0.5 + 0.5 * p[1], 0.5 + 0.5 * p[2]])
        .collect();
    let layout = AttrLayout {
        vertex_count: v,
        attr_count: 3,
        per_item: false,
    };
    let (color, color_da) = hard
        .interpolate(
            &ctx,
            &colors,
            layout,
            &first.rast,
            &tri,
            [h, w],
            Some(&first.rast_db),
            &[0, 2],
        )
        .unwrap();
    hashes.push(("interpolate".into(), fnv1a(&color)));
    hashes.push(("interpolate derivatives".into(), fnv1a(&color_da)));
    let topology = TopologyHash::new(&tri);
    let args = AntialiasArgs {
        color: &color,
        rast: &first.rast,
        pos: &pos,
        instanced: true,
        vertex_count: v,
        tri: &tri,
        batch: 2,
        height: h,
        width: w,
        channels: 3,
    };
    let aa = hard.antialias(&ctx, &args, &topology).unwrap();
    hashes.push(("antialias".into(), fnv1a(&aa)));
    let dy: Vec<f32> = aa.iter().map(|c| 2.0 * (c - 0.3) / n as f32).collect();
    let (g_color, g_pos_aa) = hard
        .antialias_grad(&ctx, &args, &topology, &dy, 1.0)
        .unwrap();
    hashes.push(("antialias grad color".into(), fnv1a(&g_color)));
    hashes.push(("antialias grad pos".into(), fnv1a(&g_pos_aa)));
    let dda: Vec<f32> = (0..4 * n).map(|i| ((i % 7) as f32 - 3.0) * 1e-3).collect();
    let g = hard
        .interpolate_grad(
            &ctx,
            &colors,
            layout,
            &first.rast,
            &tri,
            [h, w],
            Some(&first.rast_db),
            &[0, 2],
            &g_color,
            Some(&dda),
        )
        .unwrap();
    hashes.push(("interpolate grad attr".into(), fnv1a(&g.attr)));
    hashes.push(("interpolate grad rast".into(), fnv1a(&g.rast)));
    hashes.push(("interpolate grad rast_db".into(), fnv1a(&g.rast_db)));
    let g_pos = hard
        .rasterize_grad(
            &ctx,
            &shape,
            &pos,
            &tri,
            &first.rast,
            &g.rast,
            Some(&g.rast_db),
        )
        .unwrap();
    hashes.push(("rasterize grad pos".into(), fnv1a(&g_pos)));
    let listing: String = hashes
        .iter()
        .map(|(k, h)| format!("{h:016x}  {k}\n"))
        .collect();
    if std::env::var("HARD_GOLDEN").is_ok_and(|v| v == "print") {
        print!("{listing}");
    }
    let golden = include_str!("data/hard-golden.txt");
    assert_eq!(
        listing, golden,
        "the primitives' bytes differ from tests/data/hard-golden.txt"
    );
}

#[test]
fn snapping_the_fill_rule_the_clamps_and_depth_ties_decide_as_nvdiffrast() {
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    // 8×8: pixel (3, 3)'s centre is at NDC x = −0.125. The triangle's left edge runs 1/40 pixel
    // to its right (x = −0.11875), so the exact triangle misses the centre; snapped to the
    // 1/16-pixel grid the edge passes through it (x·8W = −7.6 → −8 units, the centre's sample),
    // and the fill rule gives a centre on a left edge to the triangle. There u + v > 1 before
    // the clamps (the third corner's weight is negative): nvdiffrast scales both to sum to 1.
    let x_edge = -0.11875f32;
    let pos = vec![
        x_edge, 0.9, 0.2, 1.0, x_edge, -0.9, 0.2, 1.0, 0.9, 0.0, 0.2, 1.0, //
        x_edge, 0.9, 0.2, 1.0, x_edge, -0.9, 0.2, 1.0, 0.9, 0.0, 0.2, 1.0,
    ];
    let shape = Shape {
        width: 8,
        height: 8,
        vertex_count: 6,
        triangle_count: 2,
        topology: Topology::Instanced { batch: 1 },
    };
    // The same triangle twice: of two equal depths the later (id 2) wins.
    let tri = [[0u32, 1, 2], [3, 4, 5]];
    let gpu = hard.rasterize(&ctx, &shape, &pos, &tri, None).unwrap();
    let twin = reference::rasterize(&shape, &wide(&pos), &tri, None);
    let i = 4 * (3 * 8 + 3);
    for (what, r) in [
        (
            "GPU",
            gpu.rast[i..i + 4]
                .iter()
                .map(|&v| f64::from(v))
                .collect::<Vec<_>>(),
        ),
        ("twin", twin.rast[i..i + 4].to_vec()),
    ] {
        assert_eq!(
            r[3], 2.0,
            "{what}: the snapped edge's centre goes to the later triangle"
        );
        assert!(
            r[0] >= 0.0 && r[1] >= 0.0,
            "{what}: u, v clamped at 0: {r:?}"
        );
        assert!(
            (r[0] + r[1] - 1.0).abs() < 1e-6,
            "{what}: u + v scaled to 1: {r:?}"
        );
    }
    // One pixel to the left is not drawn, and without snapping (the exact edge) (3, 3) would
    // not be either.
    let j = 4 * (3 * 8 + 2);
    assert_eq!(gpu.rast[j + 3], 0.0);
    let f = reference::pixel_ndc(3, 3, 8, 8);
    assert!(f[0] < f64::from(x_edge), "the exact edge misses the centre");
    // A second layer: the earlier triangle at the same depth, then nothing.
    let second = hard
        .rasterize(&ctx, &shape, &pos, &tri, Some(&gpu.keys))
        .unwrap();
    assert_eq!(second.rast[i + 3], 1.0);
    let third = hard
        .rasterize(&ctx, &shape, &pos, &tri, Some(&second.keys))
        .unwrap();
    assert!(third.rast.iter().all(|&v| v == 0.0));
}

#[test]
fn the_guard_band_decides_snapping_as_the_kernel_does() {
    use softvk::raster::hard::reference::SNAP_LIMIT;
    let Some(ctx) = common::gpu() else { return };
    let mut hard = HardRasterizer::new(&ctx).unwrap();
    // 32×24: a vertex may project to |x/w| ≤ 2^21 / (8·32) = 8192 and still be snapped. Two
    // long slivers reaching far out of the viewport, one just inside that band (snapped), one
    // just past it (homogeneous), each crossing the image: the GPU must draw what the twin
    // draws, ids and values.
    let (w, h) = (32u32, 24u32);
    let limit = (SNAP_LIMIT / (8.0 * f64::from(w))) as f32;
    let pos = vec![
        -0.9,
        -0.8,
        0.1,
        1.0,
        0.98 * limit,
        0.3,
        0.1,
        1.0,
        -0.9,
        0.2,
        0.1,
        1.0, //
        -0.9,
        0.3,
        0.4,
        1.0,
        1.02 * limit,
        0.9,
        0.4,
        1.0,
        -0.9,
        0.9,
        0.4,
        1.0,
    ];
    let tri = [[0u32, 1, 2], [3, 4, 5]];
    let c = |t: usize| {
        tri[t].map(|v| {
            let o = 4 * v as usize;
            [pos[o], pos[o + 1], pos[o + 2], pos[o + 3]].map(f64::from)
        })
    };
    assert!(matches!(
        reference::coverage(c(0), w, h),
        Some(Coverage::Snapped(_))
    ));
    assert_eq!(reference::coverage(c(1), w, h), Some(Coverage::Homogeneous));
    let shape = Shape {
        width: w,
        height: h,
        vertex_count: 6,
        triangle_count: 2,
        topology: Topology::Instanced { batch: 1 },
    };
    let gpu = hard.rasterize(&ctx, &shape, &pos, &tri, None).unwrap();
    let twin = reference::rasterize(&shape, &wide(&pos), &tri, None);
    let drawn = |id: f64| twin.rast.chunks(4).filter(|p| p[3] == id).count();
    assert!(
        drawn(1.0) > 20 && drawn(2.0) > 20,
        "both slivers cross the image"
    );
    assert_eq!(
        compare(&gpu, &twin, (&shape, &wide(&pos), &tri), "guard band"),
        0
    );
}
