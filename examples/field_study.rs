//! The sphere-probing measurements of `RESULTS.md` ("Sphere probing"), reproducible by one
//! command each.
//!
//! ```text
//! cargo run --release --example field_study -- spot [key=value ...]
//! cargo run --release --example field_study -- sphere [key=value ...]
//! cargo run --release --example field_study -- sweep NAME [key=value ...]
//! cargo run --release --example field_study -- throughput [key=value ...]
//! cargo run --release --example field_study -- write DIR [va=15]
//! cargo run --release --example field_study -- iou M.obj [va=15]
//! ```
//!
//! `spot`: spot's hard silhouettes at 24 views (elevation 30°, azimuth every 15°, distance
//! 2.732, viewing angle 15°, 64², rendered by the project's rasterizer), the cube around their
//! visual hull (`auto_cube`, as `fit-field` by default), a field fit, and the 3D IoU at 64³ (same
//! cube) of the fitted field, of the visual hull of the same 24 views, against spot voxelized.
//! `sphere`: the same on an analytic sphere of radius 0.5 (exact silhouettes).
//! `sweep NAME`: runs `spot` for each value of one parameter (see `sweeps()`), sequentially.
//! `throughput`: rays probed per second against marching every ray densely through the field.
//! `write DIR`: spot's silhouettes and cameras as `softvk fit-field` reads them; `iou M.obj`:
//! the 3D IoU of a fitted mesh (voxelized at 64³ in the same cube) against spot.
//!
//! Keys (defaults are `FieldFitOptions::default()` and `fit-field`'s): `iters`, `field`
//! (grid|mlp), `res`, `layers`, `width`, `freqs`, `lr`, `b1`, `b2`, `init` (initial logit),
//! `seed`, `log`, `margin` (auto cube), and the probe settings in cube units: `rays`,
//! `ray_uniform`, `contour_sigma`, `anchors`, `anchor_uniform`, `anchor_sigma`, `hull_res`,
//! `tau`, `tau_out` (the outside rays' radius), `agg` (max|lse|union), `temp`, `boundary` (0|1),
//! `tile`, `geo_n`, `geo_uniform`, `geo_delta`, `geo_dn`, `geo_eps`, `geo_p`, `lambda`; `size`
//! (image side), `va` (viewing angle, degrees; 15), `eval_res` (IoU grid), `mc` (write the
//! marching-cubes OBJ and preview to this folder), `diag=1` (where the fit differs from the
//! object, split by the visual hull: [`diagnose`]), `stages=TAU:ITERS,...` (τ in stages, each a
//! fresh fitter starting from the previous stage's field; the other keys as usual), `close=1`
//! (fit the silhouettes closed by a 3 × 3 square: [`closed_targets`]; the hull and the scores stay
//! those of the silhouettes as given), `carve=1` (also score the fit carved by the silhouettes
//! afterwards: [`carve_study`]).

use std::collections::BTreeMap;
use std::time::Instant;

use softvk::camera::{Camera, Projection};
use softvk::field::mcubes::MarchingCubes;
use softvk::field::preview::{PreviewOptions, render_preview};
use softvk::field::voxel::{self, Occupancy};
use softvk::field::{Cube, Field, FieldKind};
use softvk::fit::AdamOptions;
use softvk::fit::field_fit::{
    FieldFit, FieldFitLog, FieldFitOptions, auto_cube, fit_field, scaled_to_cube,
};
use softvk::fit::session::Session;
use softvk::gpu::{Context, ContextOptions};
use softvk::io::Silhouettes;
use softvk::mesh::Mesh;
use softvk::probe::{Aggregate, ProbeSettings, Targets};
use softvk::raster::gpu::{Method, Renderer};
use softvk::raster::settings::{Alpha, Dist, RasterSettings};
use softvk::recon::shapes::{self, Category};

type Keys = BTreeMap<String, String>;

fn parse_keys(args: &[String]) -> Keys {
    args.iter()
        .map(|a| {
            let (k, v) = a
                .split_once('=')
                .unwrap_or_else(|| panic!("`{a}`: expected key=value"));
            (k.to_string(), v.to_string())
        })
        .collect()
}

fn get<T: std::str::FromStr>(keys: &Keys, key: &str, default: T) -> T {
    keys.get(key).map_or(default, |v| {
        v.parse()
            .unwrap_or_else(|_| panic!("{key}={v}: not a valid value"))
    })
}

/// The fit options of `keys` (lengths in cube units), before the cube is known.
fn options(keys: &Keys) -> FieldFitOptions {
    let d = FieldFitOptions::default();
    let p = d.probe;
    let field = match get(keys, "field", "grid".to_string()).as_str() {
        "grid" => FieldKind::Grid {
            res: get(keys, "res", softvk::fit::field_fit::DEFAULT_GRID_RES),
        },
        "mlp" => FieldKind::Mlp {
            hidden_layers: get(keys, "layers", 4),
            width: get(keys, "width", 64),
            frequencies: get(keys, "freqs", 4),
        },
        other => panic!("field={other}: grid or mlp"),
    };
    let aggregate = match get(keys, "agg", "max".to_string()).as_str() {
        "max" => Aggregate::Max,
        "lse" => Aggregate::LogSumExp,
        "union" => Aggregate::Union,
        other => panic!("agg={other}: max, lse or union"),
    };
    FieldFitOptions {
        field,
        probe: ProbeSettings {
            rays_per_view: get(keys, "rays", p.rays_per_view),
            ray_uniform_fraction: get(keys, "ray_uniform", p.ray_uniform_fraction),
            contour_sigma: get(keys, "contour_sigma", p.contour_sigma),
            anchors: get(keys, "anchors", p.anchors),
            anchor_uniform_fraction: get(keys, "anchor_uniform", p.anchor_uniform_fraction),
            anchor_sigma: get(keys, "anchor_sigma", p.anchor_sigma),
            hull_resolution: get(keys, "hull_res", p.hull_resolution),
            tau: get(keys, "tau", p.tau),
            tau_outside: keys
                .get("tau_out")
                .map(|v| v.parse().expect("tau_out: a number"))
                .or(p.tau_outside),
            aggregate,
            temperature: get(keys, "temp", p.temperature),
            boundary_aware: get(keys, "boundary", u8::from(p.boundary_aware)) != 0,
            tile_size: get(keys, "tile", p.tile_size),
            geo_candidates: get(keys, "geo_n", p.geo_candidates),
            geo_uniform_fraction: get(keys, "geo_uniform", p.geo_uniform_fraction),
            geo_delta: get(keys, "geo_delta", p.geo_delta),
            geo_normal_delta: get(keys, "geo_dn", p.geo_normal_delta),
            geo_epsilon: get(keys, "geo_eps", p.geo_epsilon),
            geo_p: get(keys, "geo_p", p.geo_p),
            geo_lambda: get(keys, "lambda", p.geo_lambda),
            seed: get(keys, "seed", p.seed),
            ..p
        },
        adam: AdamOptions {
            lr: get(keys, "lr", d.adam.lr),
            betas: (
                get(keys, "b1", d.adam.betas.0),
                get(keys, "b2", d.adam.betas.1),
            ),
            eps: 1e-8,
        },
        iterations: get(keys, "iters", d.iterations),
        log_every: get(keys, "log", d.log_every),
        init_logit: get(keys, "init", d.init_logit),
    }
}

fn spot_cameras(viewing_angle_deg: f64) -> Vec<Camera> {
    (0..24)
        .map(|i| Camera {
            projection: Projection::Perspective { viewing_angle_deg },
            ..Camera::from_angles(2.732, 30.0, 15.0 * f64::from(i))
        })
        .collect()
}

fn render_masks(ctx: &Context, mesh: &Mesh, cams: &[Camera], size: u32) -> Vec<f32> {
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

/// The problem: targets and the object's occupancy at `eval_res` in the cube.
struct Problem {
    name: String,
    targets: Targets,
    cube: Cube,
    object: Occupancy,
    hull: Occupancy,
}

fn silhouettes(t: &Targets) -> Silhouettes {
    Silhouettes {
        width: t.width,
        height: t.height,
        names: (0..t.views.len()).map(|v| format!("{v:03}.png")).collect(),
        masks: t.masks.clone(),
    }
}

fn problem(ctx: &Context, which: &str, keys: &Keys) -> Problem {
    let size = get(keys, "size", 64u32);
    let eval_res = get(keys, "eval_res", 64u32);
    let margin = get(keys, "margin", softvk::fit::field_fit::DEFAULT_CUBE_MARGIN);
    let cams = spot_cameras(get(keys, "va", 15.0));
    let mut shape = None;
    let (name, targets, mesh) = match which {
        "spot" => {
            let spot =
                Mesh::load_obj(&softvk::assets::dir().join("spot_triangulated.obj"), 1).unwrap();
            let masks = render_masks(ctx, &spot, &cams, size);
            let s = size as usize;
            let border = masks
                .chunks(s * s)
                .map(|m| {
                    (0..s * s)
                        .filter(|&i| {
                            let (r, c) = (i / s, i % s);
                            (r == 0 || c == 0 || r == s - 1 || c == s - 1) && m[i] > 0.5
                        })
                        .count()
                })
                .sum::<usize>();
            println!("spot: {border} inside pixels on the image borders over the 24 views");
            (
                "spot",
                Targets::new(&cams, size, size, masks).unwrap(),
                Some(spot),
            )
        }
        "sphere" => (
            "sphere",
            softvk::probe::targets::sphere_silhouettes(&cams, size, size, 0.5).unwrap(),
            None,
        ),
        thin if thin.starts_with("thin:") => {
            // A procedural object of the reconstruction dataset (`thin:CATEGORY:SEED`): legs,
            // rods, plates, wings and frames; a union of closed parts.
            let mut it = thin.split(':').skip(1);
            let category = Category::parse(it.next().expect("thin:CATEGORY:SEED")).unwrap();
            let seed: u64 = it.next().map_or(0, |s| s.parse().expect("a seed"));
            let object = shapes::generate(category, seed);
            let mesh = object.mesh().unwrap();
            let masks = render_masks(ctx, &mesh, &cams, size);
            shape = Some(object);
            (
                thin,
                Targets::new(&cams, size, size, masks).unwrap(),
                Some(mesh),
            )
        }
        other => panic!("{other}: spot, sphere or thin:CATEGORY:SEED"),
    };
    let cube = auto_cube(&targets, margin).unwrap();
    let object = match (&shape, &mesh) {
        (Some(shape), _) => shape.voxelize(&cube, eval_res).unwrap(),
        (None, Some(m)) => {
            let v = voxel::voxelize_mesh(&m.positions, &m.faces, &cube, eval_res).unwrap();
            assert_eq!(v.odd_rays, 0, "the mesh voxelizes watertight");
            v.occupancy
        }
        (None, None) => voxel::occupancy_from_fn(&cube, eval_res, |p| {
            (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() < 0.5
        }),
    };
    let hull =
        voxel::visual_hull(&silhouettes(&targets), &targets.cameras, &cube, eval_res).unwrap();
    Problem {
        name: name.to_string(),
        targets,
        cube,
        object,
        hull,
    }
}

/// The targets with every mask closed by a 3 × 3 square (dilation, then erosion): one-pixel gaps
/// in thin parts filled, straight edges unchanged. Also how many pixels changed.
fn closed_targets(t: &Targets) -> (Targets, usize) {
    let (w, h) = (t.width as usize, t.height as usize);
    let pass = |m: &[f32], dilate: bool| -> Vec<f32> {
        (0..w * h)
            .map(|i| {
                let (r, c) = ((i / w) as i64, (i % w) as i64);
                let mut any = false;
                let mut all = true;
                for dr in -1..=1 {
                    for dc in -1..=1 {
                        let (rr, cc) = (r + dr, c + dc);
                        // Beyond the image border: no evidence either way.
                        if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                            continue;
                        }
                        let v = m[rr as usize * w + cc as usize] > 0.5;
                        any |= v;
                        all &= v;
                    }
                }
                f32::from(u8::from(if dilate { any } else { all }))
            })
            .collect()
    };
    let mut changed = 0;
    let masks: Vec<f32> = t
        .masks
        .chunks(w * h)
        .flat_map(|m| {
            let out = pass(&pass(m, true), false);
            changed += out.iter().zip(m).filter(|(a, b)| a != b).count();
            out
        })
        .collect();
    (
        Targets::new(&t.cameras, t.width, t.height, masks).unwrap(),
        changed,
    )
}

/// How many views see `c` (in front of the camera, in frame) outside their silhouette.
fn vetoes(t: &Targets, c: glam::DVec3) -> usize {
    let (w, h) = (t.width, t.height);
    t.cameras
        .iter()
        .enumerate()
        .filter(|(v, cam)| {
            let [x, y, z] = cam.to_screen(c);
            let m = &t.masks[*v * (w * h) as usize..][..(w * h) as usize];
            z > 0.0
                && voxel::screen_to_pixel(x, y, w, h)
                    .is_some_and(|(col, row)| m[(row * w + col) as usize] <= 0.5)
        })
        .count()
}

/// The fit carved by the silhouettes afterwards: a voxel goes when its centre falls outside the
/// silhouette in at least k of the views that see it (in frame, in front of the camera; a view
/// that does not see a point says nothing about it), with the silhouettes as given and closed.
fn carve_study(p: &Problem, occ: &Occupancy, label: &str, hull_iou: f64) {
    let res = occ.res;
    let centres: Vec<glam::DVec3> = (0..res.pow(3))
        .map(|i| glam::DVec3::from(occ.center([i % res, (i / res) % res, i / (res * res)])))
        .collect();
    let (closed, _) = closed_targets(&p.targets);
    for (name, t) in [("as given", &p.targets), ("closed", &closed)] {
        let vetoes: Vec<usize> = centres.iter().map(|&c| vetoes(t, c)).collect();
        let ratios: Vec<String> = (1..=3)
            .map(|k| {
                let mut carved = occ.clone();
                for (c, &n) in carved.inside.iter_mut().zip(&vetoes) {
                    *c &= n < k;
                }
                format!("{:.3}", voxel::iou(&carved, &p.object).unwrap() / hull_iou)
            })
            .collect();
        println!(
            "{} {label}: carved by the silhouettes {name} (k = 1, 2, 3 vetoes): ratio {}",
            p.name,
            ratios.join(" ")
        );
    }
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

/// τ in stages (`stages=TAU:ITERS,...`, τ in cube units, the other options from `keys`): each
/// stage a fresh fitter (fresh Adam moments) from the last one's field, its iterations numbered
/// on from the last one's so that its samples are new. The field and the iterations run.
fn staged_fit(
    ctx: &Context,
    p: &Problem,
    targets: &Targets,
    keys: &Keys,
    stages: &str,
) -> (Field, u32) {
    let mut field = None::<Field>;
    let mut done = 0;
    for stage in stages.split(',') {
        let (tau, n) = stage.split_once(':').expect("stages=TAU:ITERS,...");
        let mut o = options(keys);
        o.probe.tau = tau.parse().expect("stages: a number for τ");
        o.probe = scaled_to_cube(&o.probe, &p.cube);
        let n: u32 = n.parse().expect("stages: a number of iterations");
        let mut f = FieldFit::fitter(ctx, targets, &o).unwrap();
        if let Some(before) = &field {
            f.field()
                .set_params(ctx, &before.read_params(ctx).unwrap())
                .unwrap();
        }
        let mut first = done + 1;
        while first <= done + n {
            let last = (first + 49).min(done + n);
            // `Some(i)`: the entry buffers grew at iteration i, run again from there.
            first = f.run(first, last, None).unwrap().unwrap_or(last + 1);
        }
        done += n;
        field = Some(f.into_fit().into_field());
    }
    (field.expect("stages: at least one"), done)
}

/// One fit (`fit_field`, or [`staged_fit`] with `stages=`): prints a result line; returns the
/// fitted IoU.
fn run_fit(ctx: &Context, p: &Problem, keys: &Keys, label: &str) -> f64 {
    let mut opts = options(keys);
    opts.probe = scaled_to_cube(&opts.probe, &p.cube);
    let verbose = get(keys, "verbose", 1u8) != 0;
    let load_before = load();
    let t = Instant::now();
    let closed;
    let targets = if get(keys, "close", 0u8) != 0 {
        let changed;
        (closed, changed) = closed_targets(&p.targets);
        println!("  closing changed {changed} pixels");
        &closed
    } else {
        &p.targets
    };
    let (field, summary) = if let Some(stages) = keys.get("stages") {
        let (field, iterations) = staged_fit(ctx, p, targets, keys, stages);
        let summary = format!("{iterations} its, {:.1} s", t.elapsed().as_secs_f64());
        (field, summary)
    } else {
        let r = fit_field(
            ctx,
            targets,
            &opts,
            Session::new().on_row(|l: &FieldFitLog| {
                if verbose {
                    eprintln!(
                        "  it {:4}  L_sil {:.5}  L_geo {:.5}  total {:.5}  {:.1} s",
                        l.iteration, l.silhouette, l.geo, l.total, l.seconds
                    );
                }
                true
            }),
        )
        .unwrap();
        let last = r.log.last().copied();
        let summary = format!(
            "{} its, fit {:.1} s (setup {:.1} s, logging {:.1} s, {} regrowths), {:.0} ms/it | \
             L_sil {:.5} L_geo {:.5} | load {load_before} → {}",
            r.iterations,
            t.elapsed().as_secs_f64(),
            r.timings.setup_s,
            r.timings.log_s,
            r.timings.regrowths,
            1e3 * r.timings.iterations_s / f64::from(r.iterations.max(1)),
            last.map_or(f32::NAN, |l| l.silhouette),
            last.map_or(f32::NAN, |l| l.geo),
            load()
        );
        (r.field, summary)
    };
    let occ = voxel::field_occupancy(ctx, &field, &p.cube, p.object.res).unwrap();
    let iou = voxel::iou(&occ, &p.object).unwrap();
    let hull_iou = voxel::iou(&p.hull, &p.object).unwrap();
    println!(
        "{} {label}: 3D IoU {iou:.4} (hull {hull_iou:.4}, ratio {:.3}) | {summary}",
        p.name,
        iou / hull_iou,
    );
    if get(keys, "carve", 0u8) != 0 {
        carve_study(p, &occ, label, hull_iou);
    }
    if get(keys, "diag", 0u8) != 0 {
        diagnose(p, &occ);
    }
    if let Some(dir) = keys.get("mc") {
        let dir = std::path::Path::new(dir);
        std::fs::create_dir_all(dir).unwrap();
        let mc = MarchingCubes::new(ctx).unwrap();
        let iso = mc.extract(ctx, &field, 64).unwrap();
        iso.write_obj(&dir.join(format!("{}-{label}.obj", p.name)))
            .unwrap();
        let cam = Camera::from_angles(2.732, 30.0, 45.0);
        let img = render_preview(
            ctx,
            &field,
            &Camera {
                projection: Projection::Perspective {
                    viewing_angle_deg: 15.0,
                },
                ..cam
            },
            &PreviewOptions::default(),
        )
        .unwrap();
        softvk::fit::report::write_png(&dir.join(format!("{}-{label}.png", p.name)), &img).unwrap();
    }
    iou
}

/// Where a fitted occupancy differs from the object, split by the visual hull: what the fit adds
/// outside the hull, and what it carves from the hull (rightly: not object; wrongly: object).
fn diagnose(p: &Problem, fit: &Occupancy) {
    let res = fit.res;
    let centre = |i: usize| {
        let i = i as u32;
        glam::DVec3::from(fit.center([i % res, (i / res) % res, i / (res * res)]))
    };
    let (mut tp, mut fp_out, mut fp_in, mut fn_in, mut fn_out, mut carved_right) =
        (0, 0, 0, 0, 0, 0);
    for i in 0..fit.inside.len() {
        let (f, o, h) = (fit.inside[i], p.object.inside[i], p.hull.inside[i]);
        match (f, o, h) {
            (true, true, _) => tp += 1,
            (true, false, false) => fp_out += 1,
            (true, false, true) => fp_in += 1,
            (false, true, true) => fn_in += 1,
            (false, true, false) => fn_out += 1,
            (false, false, true) => carved_right += 1,
            _ => {}
        }
    }
    // How far outside the silhouettes the fit's voxels outside the hull are: per voxel, the
    // largest distance (pixels) from its projection to the nearest inside pixel centre over the
    // views that veto it; a histogram by that distance.
    let (w, h) = (p.targets.width, p.targets.height);
    let inside_px: Vec<Vec<(f64, f64)>> = (0..p.targets.views.len())
        .map(|v| {
            let m = &p.targets.masks[v * (w * h) as usize..(v + 1) * (w * h) as usize];
            (0..w * h)
                .filter(|&i| m[i as usize] > 0.5)
                .map(|i| softvk::camera::pixel_center(i % w, i / w, w, h))
                .collect()
        })
        .collect();
    let mut hist = [0usize; 6];
    for i in 0..fit.inside.len() {
        if !(fit.inside[i] && !p.object.inside[i] && !p.hull.inside[i]) {
            continue;
        }
        let c = centre(i);
        let mut worst = 0.0f64;
        for (v, cam) in p.targets.cameras.iter().enumerate() {
            let [x, y, _] = cam.to_screen(c);
            let d = inside_px[v]
                .iter()
                .map(|&(px, py)| ((px - x).powi(2) + (py - y).powi(2)).sqrt())
                .fold(f64::INFINITY, f64::min)
                * f64::from(w.min(h))
                / 2.0;
            worst = worst.max(d);
        }
        hist[match worst {
            d if d < 0.5 => 0,
            d if d < 0.75 => 1,
            d if d < 1.0 => 2,
            d if d < 1.5 => 3,
            d if d < 2.5 => 4,
            _ => 5,
        }] += 1;
    }
    // The fit carved by every view that sees a voxel's centre in its frame: what a perfect
    // space-carving term would leave.
    let mut carved = fit.clone();
    for i in 0..fit.inside.len() {
        carved.inside[i] &= fit.inside[i] && vetoes(&p.targets, centre(i)) == 0;
    }
    let hull_iou = voxel::iou(&p.hull, &p.object).unwrap();
    println!(
        "  carved in frame: {} voxels, 3D IoU {:.4}, ratio {:.3}",
        carved.count(),
        voxel::iou(&carved, &p.object).unwrap(),
        voxel::iou(&carved, &p.object).unwrap() / hull_iou
    );
    println!(
        "  outside-hull voxels by pixels outside (<0.5, <0.75, <1, <1.5, <2.5, more): {hist:?}"
    );
    println!(
        "  {}: object {} hull {} fit {} | fit∩object {tp} | fit−object: outside hull {fp_out}, inside {fp_in} | object−fit: inside hull {fn_in}, outside {fn_out} | hull carved rightly {carved_right}",
        p.name,
        p.object.count(),
        p.hull.count(),
        fit.count()
    );
}

/// Named sweeps: (key, values).
fn sweeps() -> Vec<(&'static str, &'static str, Vec<&'static str>)> {
    vec![
        ("res", "res", vec!["16", "24", "32", "48"]),
        ("tau", "tau", vec!["0.03", "0.045", "0.06", "0.09"]),
        ("anchors", "anchors", vec!["2048", "4096", "8192"]),
        ("rays", "rays", vec!["256", "512", "1024"]),
        ("lambda", "lambda", vec!["0", "0.0001", "0.001", "0.01"]),
        ("lr", "lr", vec!["0.02", "0.05", "0.1", "0.2"]),
        ("init", "init", vec!["-1", "0", "1"]),
        ("agg", "agg", vec!["max", "lse", "union"]),
        ("mlp_lr", "lr", vec!["0.002", "0.005", "0.01"]),
    ]
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(mode) = args.first() else {
        eprintln!("usage: field_study spot|sphere|sweep NAME|throughput [key=value ...]");
        std::process::exit(2);
    };
    let ctx = Context::new(&ContextOptions::from_env()).expect("a Vulkan device");
    println!(
        "device {} | date {} | load {}",
        ctx.info().name,
        std::process::Command::new("date")
            .arg("-I")
            .output()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
            .unwrap_or_default(),
        load()
    );
    match mode.as_str() {
        "thinset" => {
            // Every shape of `thin_set()` and spot, one fit each with the same options.
            let keys = parse_keys(&args[1..]);
            let mut ratios = Vec::new();
            let set: u64 = get(&keys, "set", 0);
            for which in thin_set(set) {
                let which = which.as_str();
                let p = problem(&ctx, which, &keys);
                let mut k = keys.clone();
                k.entry("verbose".into()).or_insert_with(|| "0".into());
                let iou = run_fit(&ctx, &p, &k, &args[1..].join(" "));
                ratios.push((
                    which.to_string(),
                    iou / voxel::iou(&p.hull, &p.object).unwrap(),
                ));
            }
            let min = ratios.iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
            let mean = ratios.iter().map(|r| r.1).sum::<f64>() / ratios.len() as f64;
            println!("ratios {ratios:?}: min {min:.3}, mean {mean:.3}");
        }
        which if which == "spot" || which == "sphere" || which.starts_with("thin:") => {
            let keys = parse_keys(&args[1..]);
            let p = problem(&ctx, which, &keys);
            println!(
                "{}: cube centre {:?} half {:.4}; object {} voxels, hull {} voxels at {}³",
                p.name,
                p.cube.center.map(|c| (c * 1e4).round() / 1e4),
                p.cube.half,
                p.object.count(),
                p.hull.count(),
                p.object.res
            );
            let label = args[1..].join(" ");
            run_fit(
                &ctx,
                &p,
                &keys,
                if label.is_empty() { "defaults" } else { &label },
            );
        }
        "sweep" => {
            let name = args.get(1).expect("sweep NAME");
            let keys = parse_keys(&args[2..]);
            let (_, key, values) = sweeps()
                .into_iter()
                .find(|(n, _, _)| n == name)
                .unwrap_or_else(|| panic!("no sweep {name}"));
            let which = keys
                .get("problem")
                .map_or("spot", String::as_str)
                .to_string();
            let p = problem(&ctx, &which, &keys);
            for v in values {
                let mut k = keys.clone();
                k.insert(key.to_string(), v.to_string());
                k.insert("verbose".into(), "0".into());
                run_fit(&ctx, &p, &k, &format!("{key}={v}"));
            }
        }
        "throughput" => {
            let keys = parse_keys(&args[1..]);
            throughput(&ctx, &keys);
        }
        "write" => {
            // The spot problem as `fit-field` reads it: DIR/silhouettes/*.png, DIR/cameras.csv.
            let dir = std::path::PathBuf::from(args.get(1).expect("write DIR"));
            let keys = parse_keys(&args[2..]);
            let p = problem(&ctx, "spot", &keys);
            use softvk::io;
            let rows: Vec<io::CameraRow> = (0..24)
                .map(|i| io::CameraRow {
                    distance: 2.732,
                    elevation: 30.0,
                    azimuth: 15.0 * f64::from(i),
                })
                .collect();
            let (w, h) = (p.targets.width, p.targets.height);
            io::write_silhouettes(
                &dir.join("silhouettes"),
                &io::silhouette_names(24),
                w,
                h,
                &p.targets.masks,
            )
            .unwrap();
            io::write_cameras(&dir.join("cameras.csv"), &rows).unwrap();
            println!("wrote {}", dir.display());
        }
        "iou" => {
            // 3D IoU of a fitted OBJ (voxelized in the problem's cube) against spot and the hull.
            let obj = std::path::PathBuf::from(args.get(1).expect("iou OBJ"));
            let keys = parse_keys(&args[2..]);
            let p = problem(&ctx, "spot", &keys);
            let m = Mesh::load_obj(&obj, 1).unwrap();
            let v = voxel::voxelize_mesh(&m.positions, &m.faces, &p.cube, p.object.res).unwrap();
            println!(
                "{}: 3D IoU {:.4} (hull {:.4}); {} rays with an odd crossing count",
                obj.display(),
                voxel::iou(&v.occupancy, &p.object).unwrap(),
                voxel::iou(&p.hull, &p.object).unwrap(),
                v.odd_rays
            );
        }
        other => panic!("{other}: spot, sphere, sweep or throughput"),
    }
}

/// The thin-structure set: one procedural object per thin-parted category (seed
/// `set` each, not chosen: set 0 tuned the defaults, set 1 is held out), then spot, fitted with
/// the same options.
fn thin_set(set: u64) -> Vec<String> {
    ["chair", "table", "airplane", "lamp", "bench", "display"]
        .iter()
        .map(|c| format!("thin:{c}:{set}"))
        .chain(["spot".to_string()])
        .collect()
}

/// Median of `v`.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Rays probed per second against dense marching at the grid's node spacing, forward and
/// forward + backward, GPU timestamps (medians over `reps`).
fn throughput(ctx: &Context, keys: &Keys) {
    use softvk::fit::GradOut;
    use softvk::gpu::{MemoryKind, Timer};
    use softvk::probe::dense::DenseMarch;
    use softvk::probe::sampler::Ray;
    use softvk::probe::{GpuTargets, Prober, Sampler};

    let reps = get(keys, "reps", 5usize);
    let p = problem(ctx, "spot", keys);
    let mut opts = options(keys);
    opts.probe = scaled_to_cube(&opts.probe, &p.cube);
    let s = opts.probe;
    // Dense marching steps one grid node spacing (for an MLP: of a `step_res` grid).
    let res = match opts.field {
        FieldKind::Grid { res } => get(keys, "step_res", res),
        _ => get(keys, "step_res", 32u32),
    };
    let field = Field::new(ctx, opts.field, p.cube, 0).unwrap();
    // A field with structure (random logits) so that the max has work to do.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let params: Vec<f32> = (0..field.param_count())
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 40) as f32 / (1u64 << 24) as f32) * 4.0 - 2.0
        })
        .collect();
    field.set_params(ctx, &params).unwrap();
    let gpu = GpuTargets::new(ctx, &p.targets).unwrap();
    let sampler = Sampler::new(ctx, &p.targets, &gpu, &s).unwrap();
    let mut prober = Prober::new(ctx, &gpu, &s).unwrap();
    ctx.submit_and_wait(|rec| sampler.record(rec, &gpu, 1))
        .unwrap();
    let n_rays = sampler.ray_count() as usize;
    let rays: Vec<Ray> = ctx.read_buffer(sampler.rays(), 0, n_rays).unwrap();
    let na = u64::from(s.anchors);
    let phi_a = ctx
        .create_buffer("phi anchors", 4 * na, MemoryKind::Device)
        .unwrap();
    let d_a = ctx
        .create_buffer("d anchors", 4 * na, MemoryKind::Device)
        .unwrap();
    let d_params = ctx
        .create_buffer(
            "d params",
            4 * field.param_count() as u64,
            MemoryKind::Device,
        )
        .unwrap();
    let step = 2.0 * p.cube.half / f64::from(res - 1);
    let dense = DenseMarch::new(ctx, &p.targets, &rays, &p.cube, step).unwrap();
    let mut timer = Timer::new(ctx, 16).unwrap();
    let total = |t: &Timer, names: &[&str]| -> f64 {
        t.results(ctx)
            .unwrap()
            .iter()
            .filter(|x| names.contains(&x.name.as_str()))
            .map(|x| x.ms)
            .sum()
    };
    let (mut pf, mut pfb, mut df, mut dfb) = (vec![], vec![], vec![], vec![]);
    let (mut pf_wall, mut df_wall) = (vec![], vec![]);
    let mut entries = 0;
    for _ in 0..reps {
        // Probing: items + binning count, read-back, then sort + φ at anchors + forward, and
        // the backward (probe backward + field backward at the anchors).
        let t = Instant::now();
        ctx.submit_and_wait_timed(Some(&mut timer), |rec| {
            rec.pass("count", |rec| {
                prober.record_count(rec, &gpu, sampler.anchors().whole())
            })
        })
        .unwrap();
        let count_ms = total(&timer, &["count"]);
        entries = prober.finish_count(ctx).unwrap();
        ctx.submit_and_wait_timed(Some(&mut timer), |rec| {
            let a = sampler.anchors().whole();
            rec.pass("eval", |rec| {
                field.record_eval(rec, a, s.anchors, phi_a.whole())
            })?;
            rec.pass("forward", |rec| {
                prober.record_forward(rec, &gpu, a, phi_a.whole(), sampler.rays().whole())
            })?;
            rec.pass("backward", |rec| {
                prober.record_backward(
                    rec,
                    &gpu,
                    a,
                    phi_a.whole(),
                    sampler.rays().whole(),
                    GradOut::write(d_a.whole()),
                )
            })?;
            rec.pass("field backward", |rec| {
                field.record_backward(rec, a, s.anchors, d_a.whole(), d_params.whole())
            })
        })
        .unwrap();
        pf_wall.push(t.elapsed().as_secs_f64() * 1e3);
        let f = count_ms + total(&timer, &["eval", "forward"]);
        pf.push(f);
        pfb.push(f + total(&timer, &["backward", "field backward"]));
        // Dense marching: samples, φ at the samples, max; backward: dL/dφ per sample + field
        // backward over all samples.
        let t = Instant::now();
        ctx.submit_and_wait_timed(Some(&mut timer), |rec| {
            rec.pass("points", |rec| {
                dense.record_points(rec, &gpu, sampler.rays().whole())
            })?;
            rec.pass("eval", |rec| {
                field.record_eval(
                    rec,
                    dense.points().whole(),
                    dense.sample_count(),
                    dense.phi().whole(),
                )
            })?;
            rec.pass("max", |rec| {
                dense.record_max(rec, sampler.rays().whole(), false)
            })?;
            rec.pass("max grad", |rec| {
                dense.record_max(rec, sampler.rays().whole(), true)
            })?;
            rec.pass("field backward", |rec| {
                field.record_backward(
                    rec,
                    dense.points().whole(),
                    dense.sample_count(),
                    dense.d_phi().whole(),
                    d_params.whole(),
                )
            })
        })
        .unwrap();
        df_wall.push(t.elapsed().as_secs_f64() * 1e3);
        let f = total(&timer, &["points", "eval", "max"]);
        df.push(f);
        dfb.push(f + total(&timer, &["max grad", "field backward"]));
    }
    ctx.check_validation().unwrap();
    let rays_per_s = |ms: f64| n_rays as f64 / (ms * 1e-3);
    println!(
        "throughput on spot ({} views × {} rays = {n_rays} rays, 64²), {:?} (dense step of a \
         {res}³ grid), cube half {:.4}; probing: {} anchors, τ {:.4}, tile {}, {entries} binned entries; dense: step \
         {:.4} (one node spacing), {} samples ({:.1} per ray); medians of {reps}",
        p.targets.views.len(),
        s.rays_per_view,
        opts.field,
        p.cube.half,
        s.anchors,
        s.tau,
        s.tile_size,
        step,
        dense.sample_count(),
        f64::from(dense.sample_count()) / n_rays as f64
    );
    let (a, b, c, d) = (median(pf), median(pfb), median(df), median(dfb));
    println!(
        "  forward:            probing {a:8.1} ms GPU = {:10.0} rays/s | dense {c:8.1} ms GPU = \
         {:10.0} rays/s | probing/dense {:.2}x",
        rays_per_s(a),
        rays_per_s(c),
        c / a
    );
    println!(
        "  forward + backward: probing {b:8.1} ms GPU = {:10.0} rays/s | dense {d:8.1} ms GPU = \
         {:10.0} rays/s | probing/dense {:.2}x",
        rays_per_s(b),
        rays_per_s(d),
        d / b
    );
    println!(
        "  wall (forward + backward, with submit and wait): probing {:.1} ms, dense {:.1} ms | \
         load {}",
        median(pf_wall),
        median(df_wall),
        load()
    );
}
