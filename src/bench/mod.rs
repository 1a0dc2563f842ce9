//! The scene benchmarks behind `softvk bench` (SPEC §6), written as the JSON records of the spec:
//! render scenes, each rendered with the tiled kernel at several tile sizes and with the
//! brute-force baseline, timed as resubmissions of one recorded command buffer (`forward.rs`:
//! [`run`]; `backward.rs`: [`run_backward`]); one iteration of each fit and its loop (`fits.rs`:
//! [`run_fit`]) and of reconstruction training (`recon.rs`); the scenes themselves
//! (`scenes.rs`: [`Scene`]).
//! Whole workloads only: micro-benchmarks of single kernels and networks (scan, sort, the MLP
//! field, the reconstruction network) are criterion's, in `benches/`, which use the library's
//! kernels and nothing from here.
//!
//! Per scene, each method gets its own upload ([`Renderer::prepare`](crate::raster::gpu::Renderer::prepare)), one [`Renderer::run`](crate::raster::gpu::Renderer::run)
//! (tiled: it sizes the bins exactly) and one recording of [`Renderer::record_forward`](crate::raster::gpu::Renderer::record_forward). Brute
//! force's first submission gives the reference images; every tiled method's images and aux
//! must equal them bit for bit before it is timed, and again after. A mismatch is an error
//! ([`Error::Check`]): a benchmark of a wrong image is worthless. The timed submissions are
//! interleaved, one per method per round, so that load from other processes falls on all
//! methods alike. Where brute force cannot be right ([`loop_limit`]), it is skipped and the tile
//! sizes are checked against each other.
//!
//! Times are medians over the repeats: `wall_ms` is host time from submit to fence, `gpu_ms` the
//! sum of the GPU timestamps of the passes (`face setup`, `bin count`, `bin sort`, `raster tiled`
//! or `raster brute`, `downsample 2x2`), each also reported on its own in `passes`.

use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::raster::gpu::{Method, PairCounts};

mod backward;
mod fits;
mod forward;
mod hard;
mod iteration;
mod recon;
mod scenes;

pub use backward::run_backward;
pub use forward::{loop_limit, ns_per_visited_pair, run};
#[cfg(feature = "json")]
pub use hard::hard_to_json;
pub use hard::{HARD_SCENES, HardRecord, run_hard};
pub use iteration::fit_pass_share;
pub use scenes::Scene;

/// The scenes of SPEC §6, in the order a plain `softvk bench` runs them.
pub const SCENES: [&str; 4] = ["spot-256", "sphere-64x120", "dense-1024", "blurry-256"];

/// Render scenes run only when named, for their size: `spot3-1024`, spot subdivided three times
/// (374 784 faces) at 1024², whose worst case (faces × tiles) passes 2^32 entries at 8-pixel
/// tiles although its real entries fit one binding; and `blurry-1024`,
/// blurry-256 at 1024², whose one view holds more (face, tile) entries at 8-pixel tiles than one
/// storage-buffer binding holds on lavapipe (2^27 bytes: 16.8 million), so it is binned and
/// rendered in windows of tile rows; `crowded-327k` and `spread-327k`, the same 327 680-face
/// sphere at 64² shrunk into one 8-pixel tile (past llvmpipe's loop cap: the forward folds the
/// tile in passes) and filling the frame (no tile near the cap), for the cost of the passes.
pub const LARGE_SCENES: [&str; 4] = ["spot3-1024", "blurry-1024", "crowded-327k", "spread-327k"];

/// The fitting benchmark's scenes ([`run_fit`]); run only when named (`--scene fit-120`,
/// `--scene fit-field`).
pub const FIT_SCENES: [&str; 5] = [
    "fit-120",
    "fit-field",
    "fit-pose",
    "train-recon",
    "train-recon-field",
];

/// Iterations per submission that [`run_fit`]'s loop timing compares with one.
pub const FIT_BATCH: u32 = 10;

/// Tile sizes timed by default (64 is slow on a CPU device and never wins there; see
/// BENCHMARKS.md).
pub const DEFAULT_TILES: [u32; 3] = [8, 16, 32];

/// Timed submissions per (scene, method) by default.
pub const DEFAULT_REPEAT: u32 = 5;

/// What to run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BenchOptions {
    /// Scenes by name (see [`SCENES`]); empty runs them all.
    pub scenes: Vec<String>,
    /// Timed submissions per (scene, method); times are medians over them.
    pub repeat: u32,
    /// Timed submissions of brute force (tens of seconds each on a CPU device); `None`: `repeat`.
    pub brute_repeat: Option<u32>,
    /// Tile sizes of the tiled method (multiples of 8).
    pub tiles: Vec<u32>,
    /// Time brute force too. Without it, tiled images are not checked against it.
    pub brute: bool,
    /// Render only the middle `N` rows of every scene ([`Scene::band`]) instead of the full
    /// frame: quick runs and smoke tests.
    pub band: Option<u32>,
    /// Folder of the meshes; `None` is [`crate::assets::dir`] (`SOFTVK_ASSETS`).
    pub assets: Option<PathBuf>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            scenes: Vec::new(),
            repeat: DEFAULT_REPEAT,
            brute_repeat: None,
            tiles: DEFAULT_TILES.to_vec(),
            brute: true,
            band: None,
            assets: None,
        }
    }
}

impl BenchOptions {
    /// The scenes to run, in order, after checking every option (no GPU work happens before
    /// the options are known to be good).
    pub fn checked_scenes(&self) -> Result<Vec<&'static str>> {
        if self.repeat == 0 || self.brute_repeat == Some(0) {
            return Err(Error::Input("bench: --repeat must be at least 1".into()));
        }
        for &tile in &self.tiles {
            Method::check_tile(tile)?;
        }
        if self.band == Some(0) {
            return Err(Error::Input("bench: a band needs at least one row".into()));
        }
        if self.tiles.is_empty() && !self.brute {
            return Err(Error::Input("bench: no method to time".into()));
        }
        if self.scenes.is_empty() {
            return Ok(SCENES.to_vec());
        }
        let mut render = Vec::new();
        for name in &self.scenes {
            if let Some(s) = SCENES.iter().chain(&LARGE_SCENES).find(|s| *s == name) {
                render.push(*s);
            } else if !FIT_SCENES.contains(&name.as_str()) && !HARD_SCENES.contains(&name.as_str())
            {
                return Err(Error::Input(format!(
                    "bench: unknown scene `{name}`; the scenes are {}, {}, {}, {}",
                    SCENES.join(", "),
                    LARGE_SCENES.join(", "),
                    FIT_SCENES.join(", "),
                    HARD_SCENES.join(", ")
                )));
            }
        }
        Ok(render)
    }

    /// The fitting scenes named ([`FIT_SCENES`]; none unless named), after checking the options.
    pub fn checked_fit_scenes(&self) -> Result<Vec<&'static str>> {
        self.checked_scenes()?;
        Ok(FIT_SCENES
            .iter()
            .copied()
            .filter(|s| self.scenes.iter().any(|n| n == s))
            .collect())
    }
}

/// One timed (scene, method) of the forward pass: the fields of SPEC §6 first, then extras.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchRecord {
    /// Scene name.
    pub scene: String,
    /// Brute force, or tiled with its tile size.
    pub method: Method,
    /// Always `"forward"` here (the backward is not benchmarked yet).
    pub pass: &'static str,
    /// Median GPU time (sum of the passes' timestamps), ms; `None` on a device without
    /// timestamps.
    pub gpu_ms: Option<f64>,
    /// Median host time from submit to fence, ms.
    pub wall_ms: f64,
    /// (pixel, face) pairs binned: every pixel of a tile times its binned faces, or every pixel
    /// times every face for brute force ([`PairCounts::binned`]).
    pub pairs: u64,
    /// The pairs the fine kernels visit and accept ([`Binned::pair_counts`](crate::raster::gpu::Binned::pair_counts)), for the
    /// per-pair costs ([`ns_per_visited_pair`]).
    pub counts: Option<PairCounts>,
    /// Device name, as `softvk info` prints it.
    pub device: String,
    /// Driver name and version.
    pub driver: String,
    /// Timed submissions the medians are over.
    pub repeats: u32,
    /// Median GPU time of every pass, ms, in recording order.
    pub passes: Vec<(String, f64)>,
    /// Views rendered per submission.
    pub views: u32,
    /// Faces per view.
    pub faces: u32,
    /// Output width.
    pub width: u32,
    /// Output height.
    pub height: u32,
    /// For a band ([`Scene::band`]): the rows `[first, end)` of the full frame it renders.
    pub rows: Option<[u32; 2]>,
    /// (face, tile) entries binned (tiled only).
    pub entries: Option<u64>,
    /// Whether images and aux were checked equal to brute force's bit for bit (`None`: brute
    /// force not run on this frame, or this is brute force).
    pub identical_to_brute: Option<bool>,
}

/// The records as a JSON list, one record per line, SPEC §6's fields first: `scene`, `method`
/// (`"tiled"` | `"brute"`), `tile` (null for brute), `pass`, `gpu_ms`, `wall_ms`, `pairs`,
/// `device`; then `driver`, `repeats`, `views`, `faces`, `width`, `height`, `rows` (`[first,
/// end)` of a band, else null), `entries`, `identical_to_brute`, `passes` (`{name: ms}`, median
/// GPU time per pass) and, where counted, `visited_pairs`, `accepted_pairs` and
/// `ns_per_visited_pair`. Times are in ms to the nanosecond; a missing or non-finite one is null.
#[cfg(feature = "json")]
pub fn to_json(records: &[BenchRecord]) -> String {
    use serde::Serialize;
    use serde_json::{Map, Value, json};
    let ms = |v: f64| -> Value {
        if v.is_finite() {
            json!((v * 1e6).round() / 1e6)
        } else {
            Value::Null
        }
    };
    let by_name = |entries: &[(String, f64)]| -> Value {
        Value::Object(
            entries
                .iter()
                .map(|(name, v)| (name.clone(), ms(*v)))
                .collect::<Map<_, _>>(),
        )
    };
    let lines: Vec<String> = records
        .iter()
        .map(|r| {
            let (method, tile) = match r.method {
                Method::Brute => ("brute", None),
                Method::Tiled { tile } => ("tiled", Some(tile)),
            };
            let mut o = json!({
                "scene": r.scene,
                "method": method,
                "tile": tile,
                "pass": r.pass,
                "gpu_ms": r.gpu_ms.map_or(Value::Null, ms),
                "wall_ms": ms(r.wall_ms),
                "pairs": r.pairs,
                "device": r.device,
                "driver": r.driver,
                "repeats": r.repeats,
                "views": r.views,
                "faces": r.faces,
                "width": r.width,
                "height": r.height,
                "rows": r.rows,
                "entries": r.entries,
                "identical_to_brute": r.identical_to_brute,
                "passes": by_name(&r.passes),
            });
            if let (Some(c), Value::Object(fields)) = (&r.counts, &mut o) {
                fields.insert(
                    "visited_pairs".into(),
                    json!({"forward": c.forward, "backward": c.backward}),
                );
                fields.insert("accepted_pairs".into(), json!(c.accepted));
                fields.insert(
                    "ns_per_visited_pair".into(),
                    by_name(&ns_per_visited_pair(&r.passes, c)),
                );
            }
            let mut line = Vec::new();
            o.serialize(&mut serde_json::Serializer::with_formatter(
                &mut line, Spaced,
            ))
            .expect("JSON into memory");
            String::from_utf8(line).expect("serde_json writes UTF-8")
        })
        .collect();
    if lines.is_empty() {
        "[]\n".into()
    } else {
        format!("[\n  {}\n]\n", lines.join(",\n  "))
    }
}

/// serde_json's compact form with a space after each `:` and `,` (`{"pass": "forward", ...}`):
/// one record per line that people can still read.
#[cfg(feature = "json")]
struct Spaced;

#[cfg(feature = "json")]
impl serde_json::ser::Formatter for Spaced {
    fn begin_object_key<W: ?Sized + std::io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> std::io::Result<()> {
        if first { Ok(()) } else { w.write_all(b", ") }
    }

    fn begin_object_value<W: ?Sized + std::io::Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        w.write_all(b": ")
    }

    fn begin_array_value<W: ?Sized + std::io::Write>(
        &mut self,
        w: &mut W,
        first: bool,
    ) -> std::io::Result<()> {
        if first { Ok(()) } else { w.write_all(b", ") }
    }
}

/// The fitting benchmarks (`softvk bench --scene fit-120` and the rest of [`FIT_SCENES`]): each
/// named scene's records, in the order asked (`fits.rs`'s for the fits, `recon.rs`'s for the
/// trainers). Each times one iteration per submission with its passes after an untimed one,
/// and the mesh fit also its loop at 1 and [`FIT_BATCH`] iterations per submission.
pub fn run_fit(
    ctx: &Context,
    opts: &BenchOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    let assets = opts.assets.clone().unwrap_or_else(crate::assets::dir);
    let mut records = Vec::new();
    for name in opts.checked_fit_scenes()? {
        match name {
            "fit-field" => records.push(fits::run_field_fit(ctx, opts, &assets, &mut progress)?),
            "fit-pose" => records.extend(fits::run_pose_fit(ctx, opts, &assets, &mut progress)?),
            "train-recon" => records.push(recon::run_recon_train(ctx, opts, &mut progress)?),
            "train-recon-field" => {
                records.push(recon::run_field_recon_train(ctx, opts, &mut progress)?)
            }
            // `fit-120`, the one left of FIT_SCENES.
            _ => records.extend(fits::run_mesh_fit(ctx, opts, name, &mut progress)?),
        }
    }
    Ok(records)
}

#[cfg(test)]
mod tests {
    use super::forward::median;
    use super::*;

    #[cfg(feature = "json")]
    fn sample(method: Method, gpu_ms: Option<f64>) -> BenchRecord {
        BenchRecord {
            scene: "spot-256".into(),
            method,
            pass: "forward",
            gpu_ms,
            wall_ms: 12.5,
            pairs: 1 << 40,
            counts: None,
            device: "llvmpipe \"quoted\" \\ (LLVM)\n".into(),
            driver: "Mesa".into(),
            repeats: 5,
            passes: vec![("face setup".into(), 0.25), ("raster brute".into(), 9.0)],
            views: 1,
            faces: 5856,
            width: 256,
            height: 256,
            rows: None,
            entries: matches!(method, Method::Tiled { .. }).then_some(77),
            identical_to_brute: matches!(method, Method::Tiled { .. }).then_some(true),
        }
    }

    #[test]
    #[cfg(feature = "json")]
    fn json_has_the_spec_fields_with_their_types() {
        let records = [
            sample(Method::Brute, Some(10.125)),
            sample(Method::Tiled { tile: 16 }, None),
        ];
        let text = to_json(&records);
        let v: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
        let list = v.as_array().expect("a list");
        assert_eq!(list.len(), 2);
        let keys: Vec<&str> = [
            "scene", "method", "tile", "pass", "gpu_ms", "wall_ms", "pairs", "device",
        ]
        .to_vec();
        for r in list {
            for k in &keys {
                assert!(r.get(k).is_some(), "missing {k} in {r}");
            }
            assert_eq!(r["scene"], "spot-256");
            assert_eq!(r["pass"], "forward");
            assert_eq!(r["wall_ms"].as_f64(), Some(12.5));
            assert_eq!(r["pairs"].as_u64(), Some(1 << 40));
            assert_eq!(r["device"], "llvmpipe \"quoted\" \\ (LLVM)\n");
            assert_eq!(r["repeats"].as_u64(), Some(5));
        }
        assert_eq!(list[0]["method"], "brute");
        assert!(list[0]["tile"].is_null());
        assert_eq!(list[0]["gpu_ms"].as_f64(), Some(10.125));
        assert!(list[0]["entries"].is_null());
        assert!(list[0]["identical_to_brute"].is_null());
        assert_eq!(list[0]["passes"]["raster brute"].as_f64(), Some(9.0));
        assert_eq!(list[1]["method"], "tiled");
        assert_eq!(list[1]["tile"].as_u64(), Some(16));
        assert!(list[1]["gpu_ms"].is_null());
        assert_eq!(list[1]["entries"].as_u64(), Some(77));
        assert_eq!(list[1]["identical_to_brute"], true);
        // SPEC's fields come first, in its order.
        let first = text.lines().nth(1).unwrap();
        let at = |k: &str| first.find(&format!("\"{k}\":")).unwrap();
        assert!(keys.windows(2).all(|w| at(w[0]) < at(w[1])));
    }

    #[test]
    #[cfg(feature = "json")]
    fn json_of_nothing_is_an_empty_list_and_non_finite_times_are_null() {
        let v: serde_json::Value = serde_json::from_str(&to_json(&[])).unwrap();
        assert_eq!(v, serde_json::json!([]));
        let mut r = sample(Method::Brute, Some(f64::INFINITY));
        r.wall_ms = f64::NAN;
        let v: serde_json::Value = serde_json::from_str(&to_json(&[r])).unwrap();
        assert!(v[0]["gpu_ms"].is_null() && v[0]["wall_ms"].is_null());
    }

    #[test]
    fn medians_of_odd_and_even_counts() {
        assert_eq!(median(&[]), None);
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Some(2.5));
    }

    #[test]
    fn options_are_checked_before_any_work() {
        let ok = BenchOptions::default();
        assert_eq!(ok.checked_scenes().unwrap(), SCENES.to_vec());
        let pick = BenchOptions {
            scenes: vec!["blurry-256".into(), "spot-256".into()],
            ..ok.clone()
        };
        assert_eq!(pick.checked_scenes().unwrap(), ["blurry-256", "spot-256"]);
        assert!(pick.checked_fit_scenes().unwrap().is_empty());
        assert!(
            ok.checked_fit_scenes().unwrap().is_empty(),
            "fit-120 runs only when named"
        );
        let fit = BenchOptions {
            scenes: vec!["fit-120".into()],
            ..ok.clone()
        };
        assert!(fit.checked_scenes().unwrap().is_empty());
        assert_eq!(fit.checked_fit_scenes().unwrap(), ["fit-120"]);
        let both = BenchOptions {
            scenes: vec!["fit-120".into(), "spot-256".into()],
            ..ok.clone()
        };
        assert_eq!(both.checked_scenes().unwrap(), ["spot-256"]);
        assert_eq!(both.checked_fit_scenes().unwrap(), ["fit-120"]);
        for bad in [
            BenchOptions {
                scenes: vec!["spot-512".into()],
                ..ok.clone()
            },
            BenchOptions {
                repeat: 0,
                ..ok.clone()
            },
            BenchOptions {
                brute_repeat: Some(0),
                ..ok.clone()
            },
            BenchOptions {
                tiles: vec![12],
                ..ok.clone()
            },
            BenchOptions {
                tiles: vec![],
                brute: false,
                ..ok.clone()
            },
        ] {
            assert!(
                matches!(bad.checked_scenes(), Err(Error::Input(_))),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn fit_passes_fall_into_render_backward_and_rest() {
        for (pass, share) in [
            ("face setup", "render"),
            ("bin count", "render"),
            ("bin sort", "render"),
            ("raster tiled", "render"),
            ("grad tiled", "backward"),
            ("grad reduce", "backward"),
            ("grad gather", "backward"),
            ("deform", "rest"),
            ("gate", "rest"),
            ("silhouette loss", "rest"),
            ("adam", "rest"),
        ] {
            assert_eq!(fit_pass_share(pass), share, "{pass}");
        }
    }

    #[test]
    fn every_scene_loads_from_the_assets_with_its_spec_parameters() {
        let assets = crate::assets::dir();
        let want = [
            ("spot-256", 5856, 1, 256, 1e-5, 1e-4),
            ("sphere-64x120", 2700, 120, 64, 1e-4, 1e-4),
            ("dense-1024", 2700 * 64, 1, 1024, 1e-5, 1e-4),
            ("blurry-256", 5856, 1, 256, 3e-2, 3e-1),
        ];
        for (name, faces, views, size, sigma, gamma) in want {
            let s = Scene::load(name, &assets).unwrap();
            assert_eq!(s.name, name);
            assert_eq!(s.mesh.face_count(), faces, "{name}");
            assert_eq!(s.cameras.len(), views, "{name}");
            assert_eq!(
                (s.settings.width, s.settings.height),
                (size, size),
                "{name}"
            );
            assert_eq!(
                (s.settings.sigma, s.settings.gamma),
                (sigma, gamma),
                "{name}"
            );
            assert!(s.description.starts_with(name));
        }
        // The subdivided sphere is as watertight as the asset.
        let dense = Scene::load("dense-1024", &assets).unwrap().mesh;
        assert!(dense.is_closed_and_consistent());
        assert!(Scene::load("nope", &assets).is_err());
    }
}
