//! The forward-pass benchmark behind `softvk bench` (SPEC §6): four scenes, each rendered with
//! the tiled kernel at several tile sizes and with the brute-force baseline, timed as
//! resubmissions of one recorded command buffer, and written as the JSON records of the spec.
//!
//! Per scene, each method gets its own upload ([`Renderer::prepare`]), one [`Renderer::run`]
//! (tiled: it sizes the bins exactly) and one recording of [`Renderer::record_forward`]. Brute
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

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::camera::{Camera, Projection};
use crate::error::{Error, Result};
use crate::fit::driver::{Fit, Fitter};
use crate::gpu::{Context, Recorded, Timer};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::fine::check_tile_size;
use crate::raster::gpu::{Frames, GpuScene, Method, PairCounts, Renderer, ViewGroup};
use crate::raster::settings::{Dist, RasterSettings, Rgb};

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
pub const FIT_SCENES: [&str; 3] = ["fit-120", "fit-field", "fit-pose"];

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
            check_tile_size(tile)?;
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
            } else if !FIT_SCENES.contains(&name.as_str()) {
                return Err(Error::Input(format!(
                    "bench: unknown scene `{name}`; the scenes are {}, {}, {}",
                    SCENES.join(", "),
                    LARGE_SCENES.join(", "),
                    FIT_SCENES.join(", ")
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
    /// The pairs the fine kernels visit and accept ([`GpuScene::pair_counts`]), for the
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

/// A benchmark scene: what to render and how.
pub struct Scene {
    /// Its name in [`SCENES`]; a band's is `NAME[rows A..B]`.
    pub name: String,
    /// One line saying what it is (mesh, size, views, settings).
    pub description: String,
    /// The mesh.
    pub mesh: Mesh,
    /// One camera per view.
    pub cameras: Vec<Camera>,
    /// Lights.
    pub lighting: Lighting,
    /// Raster settings.
    pub settings: RasterSettings,
    /// For a band: the rows `[first, end)` of the full frame it renders.
    pub rows: Option<[u32; 2]>,
}

/// SoftRas's default camera distance, `1/tan 30° + 1`.
const DISTANCE: f64 = 2.732;

fn load(assets: &Path, file: &str, texture_res: u32) -> Result<Mesh> {
    Ok(Mesh::load_obj(&assets.join(file), texture_res)?)
}

impl Scene {
    /// Builds scene `name` from the meshes in `assets`.
    ///
    /// - `spot-256`, `blurry-256`: spot with R = 5 textures (as SoftRas's `demo_render.py`),
    ///   256², seen from distance 2.732, elevation 30°, azimuth 45° (the demo's σ/γ sweep view).
    /// - `sphere-64x120`: as SoftRas's `demo_deform.py` renders its template: the 1352-vertex
    ///   sphere scaled by 0.5, 64², viewing angle 15°, hard colour, σ = 1e-4, 120 views at
    ///   distance 2.732, elevation 30°, azimuths 0°, 3°, …, 357°.
    /// - `dense-1024`: the 1352-vertex sphere subdivided three times ([`Mesh::subdivided`]: 172 800
    ///   faces), 1024², the spot view.
    /// - `spot3-1024` ([`LARGE_SCENES`]): spot (R = 1) subdivided three times, 1024², the spot
    ///   view.
    /// - `blurry-1024` ([`LARGE_SCENES`]): `blurry-256` at 1024².
    /// - `crowded-327k`, `spread-327k` ([`LARGE_SCENES`]): an icosphere subdivided seven times
    ///   (327 680 faces), 64², σ 1e-5, the default camera: of radius 0.1 inside the tile of
    ///   pixels 16..24 (every face in that tile), or of radius 0.9 filling the frame.
    pub fn load(name: &str, assets: &Path) -> Result<Scene> {
        let spot_view = Camera::from_angles(DISTANCE, 30.0, 45.0);
        let spot_texture_res = 5;
        let base_settings = RasterSettings::default();
        Ok(match name {
            "spot-256" => Scene {
                name: "spot-256".into(),
                description: String::new(),
                mesh: load(assets, "spot_triangulated.obj", spot_texture_res)?,
                cameras: vec![spot_view],
                lighting: Lighting::default(),
                settings: RasterSettings {
                    width: 256,
                    height: 256,
                    sigma: 1e-5,
                    gamma: 1e-4,
                    ..base_settings
                },
                rows: None,
            },
            "sphere-64x120" => {
                let mut mesh = load(assets, "sphere_1352.obj", 1)?;
                for p in &mut mesh.positions {
                    *p = p.map(|c| c * 0.5);
                }
                let projection = Projection::Perspective {
                    viewing_angle_deg: 15.0,
                };
                Scene {
                    name: "sphere-64x120".into(),
                    description: String::new(),
                    mesh,
                    cameras: (0..120)
                        .map(|i| Camera {
                            projection,
                            ..Camera::from_angles(DISTANCE, 30.0, f64::from(3 * i))
                        })
                        .collect(),
                    lighting: Lighting::default(),
                    settings: RasterSettings {
                        width: 64,
                        height: 64,
                        sigma: 1e-4,
                        rgb: Rgb::Hard,
                        ..base_settings
                    },
                    rows: None,
                }
            }
            // Both subdivided three times (`Mesh::subdivided`), at 1024² from the spot view.
            "dense-1024" | "spot3-1024" => {
                let base = if name == "dense-1024" {
                    "sphere_1352.obj"
                } else {
                    "spot_triangulated.obj"
                };
                Scene {
                    name: name.into(),
                    description: String::new(),
                    mesh: load(assets, base, 1)?
                        .subdivided()?
                        .subdivided()?
                        .subdivided()?,
                    cameras: vec![spot_view],
                    lighting: Lighting::default(),
                    settings: RasterSettings {
                        width: 1024,
                        height: 1024,
                        sigma: 1e-5,
                        gamma: 1e-4,
                        ..base_settings
                    },
                    rows: None,
                }
            }
            "blurry-256" | "blurry-1024" => Scene {
                name: name.into(),
                description: String::new(),
                mesh: load(assets, "spot_triangulated.obj", spot_texture_res)?,
                cameras: vec![spot_view],
                lighting: Lighting::default(),
                settings: RasterSettings {
                    width: if name == "blurry-256" { 256 } else { 1024 },
                    height: if name == "blurry-256" { 256 } else { 1024 },
                    sigma: 3e-2,
                    gamma: 3e-1,
                    ..base_settings
                },
                rows: None,
            },
            "crowded-327k" | "spread-327k" => {
                let (radius, centre) = if name == "crowded-327k" {
                    (0.1, [-0.59, 0.59])
                } else {
                    (0.9, [0.0, 0.0])
                };
                let mut mesh = Mesh::icosphere(7);
                for p in &mut mesh.positions {
                    *p = [
                        radius * p[0] + centre[0],
                        radius * p[1] + centre[1],
                        radius * p[2],
                    ];
                }
                Scene {
                    name: name.into(),
                    description: String::new(),
                    mesh,
                    cameras: vec![Camera::default()],
                    lighting: Lighting::default(),
                    settings: RasterSettings {
                        width: 64,
                        height: 64,
                        sigma: 1e-5,
                        gamma: 1e-4,
                        ..base_settings
                    },
                    rows: None,
                }
            }
            _ => {
                return Err(Error::Input(format!(
                    "bench: unknown scene `{name}`; the scenes are {}",
                    SCENES.join(", ")
                )));
            }
        }
        .described())
    }

    /// The middle `rows` rows of this scene's frame as a scene of its own: the same faces over
    /// the same pixel centres, so every pixel visits the same faces as in the full frame.
    ///
    /// For an `N × N` frame the band is `N × rows` with `S = rows`, so pixel centres are the
    /// full frame's scaled by `k = N / rows`; screen space is scaled to match (perspective
    /// `tan a' = tan a / k`, orthographic `s' = k s`), and σ by `k²`, since euclidean coverage
    /// `sigmoid(δ d² / σ)` and its cut-off box are in screen units. Only f32 rounding differs.
    /// Needs a square frame, `N − rows` even, euclidean distance and no anti-aliasing.
    pub fn band(&self, rows: u32) -> Result<Scene> {
        let s = &self.settings;
        let n = s.height;
        if s.width != n
            || rows == 0
            || rows >= n
            || (n - rows) % 2 != 0
            || s.antialias
            || s.dist != Dist::Euclidean
        {
            return Err(Error::Input(format!(
                "bench: cannot take a {rows}-row band of {} ({}x{}, {:?} distance{}): a band \
                 needs a square frame, fewer rows than it, an even margin, euclidean distance \
                 and no anti-aliasing",
                self.name,
                s.width,
                s.height,
                s.dist,
                if s.antialias { ", anti-aliased" } else { "" },
            )));
        }
        let k = f64::from(n) / f64::from(rows);
        let cameras = self
            .cameras
            .iter()
            .map(|c| {
                let projection = match c.projection {
                    Projection::Perspective { viewing_angle_deg } => Projection::Perspective {
                        viewing_angle_deg: (viewing_angle_deg.to_radians().tan() / k)
                            .atan()
                            .to_degrees(),
                    },
                    Projection::Orthographic { scale } => {
                        Projection::Orthographic { scale: scale * k }
                    }
                    Projection::Matrix { .. } => {
                        return Err(Error::Input(
                            "bench: a band needs a perspective or orthographic camera".into(),
                        ));
                    }
                };
                Ok(Camera { projection, ..*c })
            })
            .collect::<Result<_>>()?;
        let first = (n - rows) / 2;
        Ok(Scene {
            name: format!("{}[rows {first}..{}]", self.name, first + rows),
            description: String::new(),
            mesh: self.mesh.clone(),
            cameras,
            lighting: self.lighting.clone(),
            settings: RasterSettings {
                height: rows,
                sigma: s.sigma * k * k,
                ..*s
            },
            rows: Some([first, first + rows]),
        }
        .described())
    }

    fn described(mut self) -> Self {
        let s = &self.settings;
        self.description = format!(
            "{}: {} faces (R = {}), {} view(s) of {}x{}, sigma {:e}, gamma {:e}, rgb {:?}{}",
            self.name,
            self.mesh.face_count(),
            self.mesh.texture_res,
            self.cameras.len(),
            s.width,
            s.height,
            s.sigma,
            s.gamma,
            s.rgb,
            match self.rows {
                Some([a, b]) => format!(
                    " (rows {a}..{b} of the {0}x{0} frame, screen space scaled to match)",
                    s.width
                ),
                None => String::new(),
            },
        );
        self
    }
}

/// Runs the benchmark: every scene of `opts`, brute force then each tile size, with one line of
/// `progress` per step (including the outcome of every bit-for-bit check).
pub fn run(
    ctx: &Context,
    opts: &BenchOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    let names = opts.checked_scenes()?;
    let assets = opts.assets.clone().unwrap_or_else(crate::assets::dir);
    let renderer = Renderer::new(ctx)?;
    let mut records = Vec::new();
    for name in names {
        let mut scene = Scene::load(name, &assets)?;
        if let Some(rows) = opts.band {
            scene = scene.band(rows)?;
        }
        progress(&scene.description);
        let mut brute = opts.brute.then(|| opts.brute_repeat.unwrap_or(opts.repeat));
        if let Some(limit) = loop_limit(ctx)
            && brute.is_some()
            && scene.mesh.face_count() as u64 > limit
        {
            progress(&format!(
                "{}: brute force skipped: {} ends a shader invocation's loops after {limit} \
                 iterations in all (Mesa's LP_MAX_TGSI_LOOP_ITERATIONS), so the brute-force \
                 kernel would silently skip faces {limit}.. of {}; the tiled sizes are checked \
                 against each other instead",
                scene.name,
                ctx.info().name,
                scene.mesh.face_count()
            ));
            brute = None;
        }
        records.extend(bench_scene(
            ctx,
            &renderer,
            &scene,
            opts,
            brute,
            &mut progress,
        )?);
    }
    Ok(records)
}

/// The most loop iterations one shader invocation may run, on a driver known to cap them:
/// llvmpipe (lavapipe) ends every loop of an invocation once 65 535 iterations have run in total,
/// over all its loops (Mesa's `LP_MAX_TGSI_LOOP_ITERATIONS`). The brute-force kernel loops once
/// per face, so there it silently drops every face past the 65 535th; the tiled kernel loops
/// about once per binned face of its tile.
pub fn loop_limit(ctx: &Context) -> Option<u64> {
    ctx.info().shader_loop_limit()
}

/// One method of one scene, set up for timing: its own copy of the scene on the GPU (so every
/// method's recording stays valid while the others run), its recording and its samples.
struct Variant<'a> {
    method: Method,
    repeats: u32,
    gpu: GpuScene,
    timer: Option<Timer>,
    recorded: Recorded<'a>,
    counts: PairCounts,
    entries: Option<u64>,
    samples: Samples,
}

/// Timed submissions of one recording: wall and GPU times, and each pass's GPU time.
#[derive(Default)]
struct Samples {
    wall_ms: Vec<f64>,
    gpu_ms: Vec<f64>,
    passes: Vec<(String, Vec<f64>)>,
}

impl Samples {
    /// Submits `recorded` once, waits, and records its times (GPU ones from `timer`, if any).
    fn take(
        &mut self,
        ctx: &Context,
        recorded: &Recorded<'_>,
        timer: Option<&Timer>,
    ) -> Result<()> {
        let start = Instant::now();
        recorded.submit_and_wait()?;
        self.wall_ms.push(start.elapsed().as_secs_f64() * 1e3);
        if let Some(timer) = timer {
            let times = timer.results(ctx)?;
            self.gpu_ms.push(times.iter().map(|t| t.ms).sum());
            // A pass recorded more than once (per view group or window) counts as one, summed.
            let mut merged: Vec<(&str, f64)> = Vec::new();
            for t in &times {
                match merged.iter_mut().find(|(name, _)| *name == t.name) {
                    Some((_, ms)) => *ms += t.ms,
                    None => merged.push((&t.name, t.ms)),
                }
            }
            if self.passes.is_empty() {
                self.passes = merged
                    .iter()
                    .map(|(name, _)| (name.to_string(), Vec::new()))
                    .collect();
            }
            for ((_, series), (_, ms)) in self.passes.iter_mut().zip(&merged) {
                series.push(*ms);
            }
        }
        Ok(())
    }

    fn len(&self) -> usize {
        self.wall_ms.len()
    }

    /// The medians.
    fn timing(&self) -> Timing {
        Timing::medians(&self.gpu_ms, &self.wall_ms, &self.passes)
    }
}

impl<'a> Variant<'a> {
    /// Uploads the scene, runs `method` once (sizing its bins) and records its whole forward.
    fn new(
        ctx: &'a Context,
        renderer: &Renderer,
        scene: &Scene,
        method: Method,
        repeats: u32,
    ) -> Result<Self> {
        let mut gpu = renderer.prepare(
            ctx,
            &scene.mesh,
            &scene.cameras,
            &scene.lighting,
            &scene.settings,
        )?;
        let entries = match method {
            Method::Brute => None,
            Method::Tiled { .. } => {
                renderer.run(ctx, &mut gpu, method)?;
                Some(gpu.binned_entries())
            }
        };
        // Brute force has not run yet (its setups are not made): counted after its first
        // timed submission ([`Variant::sample`]).
        let counts = match method {
            Method::Tiled { .. } => gpu.pair_counts(ctx, method)?,
            Method::Brute => PairCounts::default(),
        };
        // Face setup and downsampling, count, sort and fine pass per view group or window; a
        // device without timestamps still gets wall times.
        let mut timer = if ctx.info().timestamp_valid_bits > 0 {
            Some(Timer::new(ctx, 2 + 3 * gpu.groups().len() as u32)?)
        } else {
            None
        };
        let recorded = ctx.record(timer.as_mut(), |rec| {
            renderer.record_forward(rec, &gpu, method).map(|_| ())
        })?;
        Ok(Self {
            method,
            repeats,
            gpu,
            timer,
            recorded,
            counts,
            entries,
            samples: Samples::default(),
        })
    }

    fn label(&self) -> String {
        match self.method {
            Method::Brute => "brute".into(),
            Method::Tiled { tile } => format!("tiled {tile}"),
        }
    }

    /// One timed submission of the recording.
    fn sample(&mut self, ctx: &Context) -> Result<()> {
        self.samples
            .take(ctx, &self.recorded, self.timer.as_ref())?;
        if self.counts == PairCounts::default() {
            self.counts = self.gpu.pair_counts(ctx, self.method)?;
        }
        Ok(())
    }

    fn timing(&self) -> Timing {
        self.samples.timing()
    }
}

/// The medians of one method's timed submissions.
struct Timing {
    gpu_ms: Option<f64>,
    wall_ms: f64,
    passes: Vec<(String, f64)>,
}

impl Timing {
    /// The medians of GPU and wall times and of each pass's series (a pass without samples is
    /// left out).
    fn medians(gpu_ms: &[f64], wall_ms: &[f64], passes: &[(String, Vec<f64>)]) -> Timing {
        Timing {
            gpu_ms: median(gpu_ms),
            wall_ms: median(wall_ms).unwrap_or(f64::NAN),
            passes: passes
                .iter()
                .filter_map(|(name, series)| Some((name.clone(), median(series)?)))
                .collect(),
        }
    }
}

/// Times one scene with brute force (`brute`: its timed submissions, if any) and every tile size.
///
/// Brute force's first submission gives the reference images; every tiled method's first run is
/// checked against them bit for bit before it is timed (without brute force, against the first
/// tile size's). The timed submissions are interleaved, one per method per round, so that load
/// from other processes falls on every method alike; afterwards each method's images are checked
/// again.
fn bench_scene(
    ctx: &Context,
    renderer: &Renderer,
    scene: &Scene,
    opts: &BenchOptions,
    brute: Option<u32>,
    progress: &mut impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    let name = scene.name.as_str();
    let mut variants = Vec::new();
    // The bits every tiled render must reproduce, and what they came from.
    let mut reference: Option<(Bits, String)> = None;
    if let Some(repeats) = brute {
        let mut v = Variant::new(ctx, renderer, scene, Method::Brute, repeats)?;
        progress(&format!(
            "{name} brute: {} (pixel, face) pairs; first of {repeats} timed submission(s)",
            u64::from(v.gpu.face_count())
                * u64::from(scene.settings.width)
                * u64::from(scene.settings.height)
                * u64::from(v.gpu.view_count())
                * if scene.settings.antialias { 4 } else { 1 }
        ));
        v.sample(ctx)?;
        reference = Some((
            bits(&renderer.read_frames(ctx, &v.gpu)?),
            "brute force".into(),
        ));
        variants.push(v);
    }
    let check = |v: &Variant<'_>, reference: &mut Option<(Bits, String)>, when: &str| {
        let got = bits(&renderer.read_frames(ctx, &v.gpu)?);
        let Some((want, what)) = reference else {
            *reference = Some((got, v.label()));
            return Ok("the reference for the other tile sizes (brute force not run)".into());
        };
        if let Some(at) = first_difference(&got, want) {
            return Err(Error::Check(format!(
                "bench {name}: {} differs from {what} {when}, first at {at}",
                v.label()
            )));
        }
        Ok(format!("images and aux bit-identical to {what}"))
    };
    for &tile in &opts.tiles {
        let v = Variant::new(ctx, renderer, scene, Method::Tiled { tile }, opts.repeat)?;
        let outcome = check(&v, &mut reference, "in its first run")?;
        progress(&format!(
            "{name} {}: {outcome}; {} pairs, {} (face, tile) entries{}",
            v.label(),
            v.counts.binned,
            v.entries.unwrap_or(0),
            binnings(v.gpu.groups())
        ));
        variants.push(v);
    }

    let rounds = variants.iter().map(|v| v.repeats).max().unwrap_or(0);
    progress(&format!(
        "{name}: timing {} method(s) in {rounds} interleaved round(s)",
        variants.len()
    ));
    for _ in 0..rounds {
        for v in &mut variants {
            if (v.samples.len() as u32) < v.repeats {
                v.sample(ctx)?;
            }
        }
    }

    let brute_ms = brute.and(variants.first().map(|v| v.timing().wall_ms));
    let mut records = Vec::new();
    for v in &variants {
        if v.method != Method::Brute {
            check(v, &mut reference, "after its timed submissions")?;
        }
        let t = v.timing();
        let speedup = match (v.method, brute_ms) {
            (Method::Tiled { .. }, Some(b)) => {
                format!(", {:.2}x brute force's wall time", b / t.wall_ms)
            }
            _ => String::new(),
        };
        progress(&format!(
            "{name} {}: {}{speedup}{}",
            v.label(),
            summary(&t, v.repeats),
            per_pair_summary(&t.passes, &v.counts)
        ));
        records.push(BenchRecord {
            scene: name.to_string(),
            method: v.method,
            pass: "forward",
            gpu_ms: t.gpu_ms,
            wall_ms: t.wall_ms,
            pairs: v.counts.binned,
            counts: Some(v.counts),
            device: ctx.info().name.clone(),
            driver: ctx.info().driver.clone(),
            repeats: v.repeats,
            passes: t.passes,
            views: v.gpu.view_count(),
            faces: v.gpu.face_count(),
            width: scene.settings.width,
            height: scene.settings.height,
            rows: scene.rows,
            entries: v.entries,
            identical_to_brute: match v.method {
                Method::Tiled { .. } => brute.map(|_| true),
                Method::Brute => None,
            },
        });
    }
    Ok(records)
}

/// ` in N binnings (views a..b, tile rows c..d; ...)` when the entries took more than one.
fn binnings(groups: &[ViewGroup]) -> String {
    if groups.len() < 2 {
        return String::new();
    }
    let each: Vec<String> = groups
        .iter()
        .map(|g| {
            let (row, rows) = g.tile_rows;
            format!(
                "views {}..{}, tile rows {row}..{}: {}",
                g.first,
                g.first + g.views,
                row + rows,
                g.entries
            )
        })
        .collect();
    format!(" in {} binnings ({})", groups.len(), each.join("; "))
}

/// Nanoseconds of GPU time per visited (pixel, face) pair of each fine pass in `passes` (ms by
/// name): the forward's (`raster …`) per [`PairCounts::forward`], the backward's (`grad tiled`,
/// `grad brute`) per [`PairCounts::backward`].
pub fn ns_per_visited_pair(passes: &[(String, f64)], counts: &PairCounts) -> Vec<(String, f64)> {
    passes
        .iter()
        .filter_map(|(name, ms)| {
            let visited = match name.as_str() {
                "raster tiled" | "raster brute" => counts.forward,
                "grad tiled" | "grad brute" => counts.backward,
                _ => return None,
            };
            (visited > 0).then(|| (name.clone(), ms * 1e6 / visited as f64))
        })
        .collect()
}

/// `; visited pairs F fwd / B bwd (A accepted); ns per visited pair: raster tiled x, ...`.
fn per_pair_summary(passes: &[(String, f64)], counts: &PairCounts) -> String {
    let ns: Vec<String> = ns_per_visited_pair(passes, counts)
        .iter()
        .map(|(name, ns)| format!("{name} {ns:.2}"))
        .collect();
    format!(
        "; visited pairs {} fwd / {} bwd ({} accepted); ns per visited pair: {}",
        counts.forward,
        counts.backward,
        counts.accepted,
        ns.join(", ")
    )
}

fn summary(t: &Timing, repeats: u32) -> String {
    let gpu = t
        .gpu_ms
        .map_or("n/a".to_string(), |ms| format!("{ms:.3} ms"));
    let passes: Vec<String> = t
        .passes
        .iter()
        .map(|(name, ms)| format!("{name} {ms:.3}"))
        .collect();
    format!(
        "gpu {gpu}, wall {:.3} ms (medians of {repeats}) [{}]",
        t.wall_ms,
        passes.join(", ")
    )
}

/// The median (mean of the middle two for an even count); `None` for no samples.
fn median(samples: &[f64]) -> Option<f64> {
    let mut v = samples.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => Some(v[n / 2]),
        _ => Some((v[n / 2 - 1] + v[n / 2]) / 2.0),
    }
}

/// Image then aux bit patterns of a render, so that -0.0 vs 0.0 and NaN payloads count as
/// differences.
struct Bits {
    words: Vec<u32>,
    image_words: usize,
}

fn bits(f: &Frames) -> Bits {
    let mut words: Vec<u32> = f.images.iter().flatten().map(|c| c.to_bits()).collect();
    let image_words = words.len();
    words.extend_from_slice(bytemuck::cast_slice(&f.aux));
    Bits { words, image_words }
}

/// Where `got` first differs from `want`, as a message.
fn first_difference(got: &Bits, want: &Bits) -> Option<String> {
    if got.image_words != want.image_words || got.words.len() != want.words.len() {
        return Some(format!(
            "sizes ({} + {} words vs {} + {})",
            got.image_words,
            got.words.len() - got.image_words,
            want.image_words,
            want.words.len() - want.image_words
        ));
    }
    let i = (0..got.words.len()).find(|&i| got.words[i] != want.words[i])?;
    let (what, at) = if i < got.image_words {
        ("image", i)
    } else {
        ("aux", i - got.image_words)
    };
    Some(format!(
        "{what} word {at} ({:#010x} vs {:#010x})",
        got.words[i], want.words[i]
    ))
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

/// The backward benchmark: per scene of `opts` and method (brute force, each tile
/// size), the backward alone (`pass: "backward"`: per-face gradients, world chain, per-vertex
/// and per-texel sums; recorded once after a forward sized the bins) and forward + backward in
/// one recording (`"forward+backward"`), medians over `opts.repeat` submissions. The upstream
/// gradient is a fixed pattern over RGBA. A method the device cannot run (brute force past
/// llvmpipe's loop cap) is reported and skipped.
pub fn run_backward(
    ctx: &Context,
    opts: &BenchOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    use crate::raster::backward::GradBuffers;
    let names = opts.checked_scenes()?;
    let assets = opts.assets.clone().unwrap_or_else(crate::assets::dir);
    let renderer = Renderer::new(ctx)?;
    let mut records = Vec::new();
    for name in names {
        let mut scene = Scene::load(name, &assets)?;
        if let Some(rows) = opts.band {
            scene = scene.band(rows)?;
        }
        progress(&format!("{} (backward)", scene.description));
        let s = &scene.settings;
        let n = (s.width * s.height) as usize * scene.cameras.len();
        let d_image: Vec<[f32; 4]> = (0..n)
            .map(|i| {
                let t = i as f32 * 0.618_034;
                [t.sin(), (1.3 * t).cos(), (0.7 * t).sin(), (2.1 * t).cos()]
            })
            .collect();
        let mut methods: Vec<(Method, u32)> = opts
            .tiles
            .iter()
            .map(|&tile| (Method::Tiled { tile }, opts.repeat))
            .collect();
        if opts.brute {
            methods.insert(0, (Method::Brute, opts.brute_repeat.unwrap_or(opts.repeat)));
        }
        for (method, repeats) in methods {
            let label = match method {
                Method::Brute => "brute".to_string(),
                Method::Tiled { tile } => format!("tiled {tile}"),
            };
            let mut gpu = renderer.prepare(
                ctx,
                &scene.mesh,
                &scene.cameras,
                &scene.lighting,
                &scene.settings,
            )?;
            let prepared = renderer.run(ctx, &mut gpu, method).and_then(|binned| {
                let gb = GradBuffers::new(ctx, binned.scene(), method)?;
                gb.set_d_image(ctx, binned.scene(), &d_image)?;
                // A first, untimed backward: it also tells whether the device can run it.
                renderer.backward(ctx, &binned, &d_image, false)?;
                Ok((binned, gb))
            });
            let (binned, gb) = match prepared {
                Ok(prepared) => prepared,
                Err(Error::Limit(why)) => {
                    progress(&format!("{} {label}: skipped: {why}", scene.name));
                    continue;
                }
                Err(e) => return Err(e),
            };
            let gpu = binned.scene();
            let counts = gpu.pair_counts(ctx, method)?;
            let entries = match method {
                Method::Tiled { .. } => Some(gpu.binned_entries()),
                Method::Brute => None,
            };
            for pass in ["backward", "forward+backward"] {
                let mut timer = if ctx.info().timestamp_valid_bits > 0 {
                    Some(Timer::new(ctx, 16 + 3 * gpu.groups().len() as u32)?)
                } else {
                    None
                };
                let recorded = ctx.record(timer.as_mut(), |rec| {
                    let binned = if pass == "forward+backward" {
                        renderer.record_forward(rec, gpu, method)?
                    } else {
                        binned
                    };
                    renderer.grad_kernels().record(rec, &binned, &gb, &gb.io())
                })?;
                let mut samples = Samples::default();
                for _ in 0..repeats {
                    samples.take(ctx, &recorded, timer.as_ref())?;
                }
                drop(recorded);
                let t = samples.timing();
                progress(&format!(
                    "{} {label} {pass}: {}{}",
                    scene.name,
                    summary(&t, repeats),
                    per_pair_summary(&t.passes, &counts)
                ));
                records.push(BenchRecord {
                    scene: scene.name.clone(),
                    method,
                    pass: if pass == "backward" {
                        "backward"
                    } else {
                        "forward+backward"
                    },
                    gpu_ms: t.gpu_ms,
                    wall_ms: t.wall_ms,
                    pairs: counts.binned,
                    counts: Some(counts),
                    device: ctx.info().name.clone(),
                    driver: ctx.info().driver.clone(),
                    repeats,
                    passes: t.passes,
                    views: gpu.view_count(),
                    faces: gpu.face_count(),
                    width: scene.settings.width,
                    height: scene.settings.height,
                    rows: scene.rows,
                    entries,
                    identical_to_brute: None,
                });
            }
        }
    }
    Ok(records)
}

/// The sphere-probing benchmark (`softvk bench --scene fit-field`): a `softvk fit-field`
/// iteration at its defaults ([`FieldFitOptions::default`](crate::fit::field_fit::FieldFitOptions),
/// scaled to the cube) on the silhouettes of spot (`spot_triangulated.obj`) rendered hard at 64²
/// from 24 views (elevation 30°, azimuth every 15°, distance 2.732, viewing angle 15°: setup A
/// of RESULTS.md), in the cube [`auto_cube`](crate::fit::field_fit::auto_cube) gives.
///
/// After one untimed iteration, `opts.repeat` iterations run as the fit runs them, each in one
/// submission ([`FieldFitter::run`](crate::fit::field_fit::FieldFitter::run), with GPU
/// timestamps; a fit runs `log_every` of them per submission): `wall_ms` is the median wall
/// time of a whole iteration (recording, submission, the gate's status read), `gpu_ms` the
/// median of the sum of its passes, and `passes` every pass (parts of a pass indented, after
/// it). `pairs` is 0 (not counted for probing); `entries` is the binning's (anchor, tile)
/// entry count of the last iteration.
fn run_field_fit(
    ctx: &Context,
    opts: &BenchOptions,
    assets: &Path,
    progress: &mut impl FnMut(&str),
) -> Result<BenchRecord> {
    use crate::fit::field_fit::{FieldFitOptions, FieldFitter, auto_cube, scaled_to_cube};
    use crate::probe::Targets;
    let name = "fit-field";
    let size = 64;
    let spot = load(assets, "spot_triangulated.obj", 1)?;
    let cameras: Vec<Camera> = (0..24)
        .map(|i| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(DISTANCE, 30.0, 15.0 * f64::from(i))
        })
        .collect();
    let hard = RasterSettings {
        width: size,
        height: size,
        dist: Dist::Hard,
        alpha: crate::raster::settings::Alpha::Hard,
        ..RasterSettings::default()
    };
    let masks: Vec<f32> =
        Renderer::new(ctx)?.render_silhouettes(ctx, &spot, &cameras, &hard, Method::default())?;
    let targets = Targets::new(&cameras, size, size, masks)?;
    let cube = auto_cube(&targets, crate::fit::field_fit::DEFAULT_CUBE_MARGIN)?;
    let defaults = FieldFitOptions::default();
    let fit_opts = FieldFitOptions {
        probe: scaled_to_cube(&defaults.probe, &cube),
        ..defaults
    };
    let mut fitter = FieldFitter::new(ctx, &targets, &fit_opts)?;
    let s = fit_opts.probe;
    progress(&format!(
        "{name}: spot silhouettes, {} views of {size}x{size}, field {:?}, {} rays per view, {} \
         anchors, tau {:.4}, tile {}, cube centre {:?} half-edge {:.4}",
        cameras.len(),
        fit_opts.field,
        s.rays_per_view,
        s.anchors,
        s.tau,
        s.tile_size,
        cube.center,
        cube.half
    ));
    let mut it = 1u32;
    fit_iterations(&mut fitter, &mut it, 1, None, progress, name)?;
    let mut timer = if ctx.info().timestamp_valid_bits > 0 {
        Some(Timer::new(ctx, 24)?)
    } else {
        None
    };
    let (mut wall, mut gpu) = (Vec::new(), Vec::new());
    let mut passes: Vec<(String, Vec<f64>)> = Vec::new();
    for _ in 0..opts.repeat {
        wall.push(fit_iterations(
            &mut fitter,
            &mut it,
            1,
            timer.as_mut(),
            progress,
            name,
        )?);
        if let Some(timer) = &timer {
            let times = timer.results(ctx)?;
            // Parts of a pass (indented names) are inside it: not summed again.
            gpu.push(
                times
                    .iter()
                    .filter(|t| !t.name.starts_with(' '))
                    .map(|t| t.ms)
                    .sum(),
            );
            for t in times {
                match passes.iter_mut().find(|(n, _)| *n == t.name) {
                    Some((_, series)) => series.push(t.ms),
                    None => passes.push((t.name.clone(), vec![t.ms])),
                }
            }
        }
    }
    let entries = fitter.last_entries();
    let timing = Timing::medians(&gpu, &wall, &passes);
    progress(&format!(
        "{name} fit-iteration: {entries} entries; {}",
        summary(&timing, opts.repeat)
    ));
    Ok(BenchRecord {
        scene: name.to_string(),
        method: Method::Tiled { tile: s.tile_size },
        pass: "fit-iteration",
        gpu_ms: timing.gpu_ms,
        wall_ms: timing.wall_ms,
        pairs: 0,
        counts: None,
        device: ctx.info().name.clone(),
        driver: ctx.info().driver.clone(),
        repeats: opts.repeat,
        passes: timing.passes,
        views: cameras.len() as u32,
        faces: spot.face_count() as u32,
        width: size,
        height: size,
        rows: None,
        entries: Some(entries),
        identical_to_brute: None,
    })
}

/// The pose-fitting benchmark (`softvk bench --scene fit-pose`): a `softvk fit-pose`
/// iteration at its defaults ([`PoseFitOptions::default`](crate::fit::pose::PoseFitOptions):
/// 48², σ/γ schedule, tile 8) fitting spot (`spot_triangulated.obj`, R = 5, SoftRas's default
/// lighting) seen from distance 2.732, elevation 20°, azimuth 30° to its own render at the rest
/// pose, from 20° off about an oblique axis.
///
/// After one untimed iteration, `opts.repeat` iterations run one per submission with GPU
/// timestamps (`fit-iteration`: medians, every pass), then [`FIT_BATCH`] iterations in one
/// submission (`fit-loop-k10`: wall and GPU time per iteration, and the host overhead).
fn run_pose_fit(
    ctx: &Context,
    opts: &BenchOptions,
    assets: &Path,
    progress: &mut impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    use crate::fit::pose::{Pose, PoseFitOptions, PoseFitter};
    use crate::lighting::Lighting;
    let name = "fit-pose";
    let spot = load(assets, "spot_triangulated.obj", 5)?;
    let camera = Camera::from_angles(DISTANCE, 20.0, 30.0);
    let lighting = Lighting::default();
    let iterations = opts.repeat + FIT_BATCH + 1;
    let fit_opts = PoseFitOptions {
        iterations,
        ..PoseFitOptions::default()
    };
    let s = fit_opts.settings;
    let target = Renderer::new(ctx)?
        .render_views(ctx, &spot, &[camera], &lighting, &s, Method::default())?
        .images;
    let axis = glam::DVec3::new(1.0, 2.0, 0.5).normalize();
    let init = Pose {
        rotation: axis * 20f64.to_radians(),
        translation: glam::DVec3::ZERO,
    };
    let mut fitter = PoseFitter::new(ctx, &spot, &camera, &lighting, &target, &init, &fit_opts)?;
    progress(&format!(
        "{name}: spot (R = 5, {} faces) at {}x{}, sigma/gamma schedule over {iterations} \
         iterations, tile {}; entry capacity {}",
        spot.face_count(),
        s.width,
        s.height,
        fit_opts.tile,
        fitter.capacity()
    ));
    let mut it = 1u32;
    fit_iterations(&mut fitter, &mut it, 1, None, progress, name)?;
    let mut timer = if ctx.info().timestamp_valid_bits > 0 {
        Some(Timer::new(ctx, 32)?)
    } else {
        None
    };
    let (mut wall, mut gpu) = (Vec::new(), Vec::new());
    let mut passes: Vec<(String, Vec<f64>)> = Vec::new();
    for _ in 0..opts.repeat {
        wall.push(fit_iterations(
            &mut fitter,
            &mut it,
            1,
            timer.as_mut(),
            progress,
            name,
        )?);
        if let Some(timer) = &timer {
            let times = timer.results(ctx)?;
            gpu.push(times.iter().map(|t| t.ms).sum());
            for t in times {
                match passes.iter_mut().find(|(n, _)| *n == t.name) {
                    Some((_, series)) => series.push(t.ms),
                    None => passes.push((t.name.clone(), vec![t.ms])),
                }
            }
        }
    }
    let timing = Timing::medians(&gpu, &wall, &passes);
    progress(&format!(
        "{name} fit-iteration: {} entries; {}",
        fitter.last_entries(),
        summary(&timing, opts.repeat)
    ));
    let record = |pass: &'static str, gpu_ms, wall_ms, passes, repeats, entries| BenchRecord {
        scene: name.to_string(),
        method: Method::Tiled {
            tile: fit_opts.tile,
        },
        pass,
        gpu_ms,
        wall_ms,
        pairs: 0,
        counts: None,
        device: ctx.info().name.clone(),
        driver: ctx.info().driver.clone(),
        repeats,
        passes,
        views: 1,
        faces: spot.face_count() as u32,
        width: s.width,
        height: s.height,
        rows: None,
        entries: Some(entries),
        identical_to_brute: None,
    };
    let mut records = vec![record(
        "fit-iteration",
        timing.gpu_ms,
        timing.wall_ms,
        timing.passes,
        opts.repeat,
        fitter.last_entries(),
    )];
    let t = time_fit_loop(
        ctx,
        &mut fitter,
        &mut it,
        FIT_BATCH,
        progress,
        name,
        "fit-loop-k10",
    )?;
    records.push(record(
        "fit-loop-k10",
        t.gpu_ms,
        t.wall_ms,
        t.passes,
        FIT_BATCH,
        fitter.last_entries(),
    ));
    Ok(records)
}

/// The fit loop: [`FIT_BATCH`] iterations of `fitter`, `k` per submission, from `it`. Wall and
/// GPU time per iteration (means), and as the one pass the `host overhead`, wall minus GPU
/// (recording, submission, fence, the gate's status read), which is what batching cuts; on a
/// shared CPU device the GPU time itself moves with the load. Says so through `progress`.
fn time_fit_loop(
    ctx: &Context,
    fitter: &mut Fitter<'_, impl Fit>,
    it: &mut u32,
    k: u32,
    progress: &mut impl FnMut(&str),
    name: &str,
    pass: &str,
) -> Result<LoopTiming> {
    let mut timer = if ctx.info().timestamp_valid_bits > 0 {
        Some(Timer::new(ctx, 20 * FIT_BATCH)?)
    } else {
        None
    };
    let (mut wall, mut gpu) = (0.0, 0.0);
    for _ in 0..FIT_BATCH / k {
        wall += fit_iterations(fitter, it, k, timer.as_mut(), progress, name)?;
        if let Some(timer) = &timer {
            gpu += timer.results(ctx)?.iter().map(|t| t.ms).sum::<f64>();
        }
    }
    let n = f64::from(FIT_BATCH);
    let gpu_ms = timer.is_some().then_some(gpu / n);
    let host = gpu_ms.map(|g| wall / n - g);
    progress(&format!(
        "{name} {pass}: {:.1} ms wall per iteration over {FIT_BATCH} iterations, {k} per \
         submission; gpu {}, host overhead {} per iteration",
        wall / n,
        gpu_ms.map_or("n/a".into(), |g| format!("{g:.1} ms")),
        host.map_or("n/a".into(), |h| format!("{h:.2} ms")),
    ));
    let passes = host
        .map(|h| vec![("host overhead".to_string(), h)])
        .unwrap_or_default();
    Ok(LoopTiming {
        gpu_ms,
        wall_ms: wall / n,
        passes,
    })
}

/// What [`time_fit_loop`] measured, per iteration.
struct LoopTiming {
    gpu_ms: Option<f64>,
    wall_ms: f64,
    /// The host overhead (wall minus GPU), where the GPU was timed.
    passes: Vec<(String, f64)>,
}

/// Runs iterations `it .. it + k` of `fitter` in one submission (again from a stopped one, until
/// all ran) and advances `it`; the wall time of the submission that ran them all, ms.
fn fit_iterations(
    fitter: &mut Fitter<'_, impl Fit>,
    it: &mut u32,
    k: u32,
    mut timer: Option<&mut Timer>,
    progress: &mut impl FnMut(&str),
    name: &str,
) -> Result<f64> {
    loop {
        let start = Instant::now();
        let stopped = fitter.run(*it, *it + k - 1, timer.as_deref_mut())?;
        let wall = start.elapsed().as_secs_f64() * 1e3;
        match stopped {
            None => {
                *it += k;
                return Ok(wall);
            }
            Some(again) => {
                progress(&format!(
                    "{name}: iteration {again} outgrew the entry capacity; now {} (re-run, not \
                     timed)",
                    Fit::capacity(&**fitter)
                ));
                *it = again;
            }
        }
    }
}

/// Which share of a fitting iteration a timed pass belongs to: `render` (face setup and the
/// binning's count, sort and fine pass), `backward` (the grad passes) or `rest` (deformation,
/// gate, loss, regularizers, deformation backward, Adam).
pub fn fit_pass_share(pass: &str) -> &'static str {
    match pass {
        "face setup" | "bin count" | "bin sort" | "raster tiled" | "downsample 2x2" => "render",
        _ if pass.starts_with("grad ") => "backward",
        _ => "rest",
    }
}

/// The fitting benchmark (`softvk bench --scene fit-120`): SoftRas's deformation demo setting,
/// the 1352-vertex sphere (`sphere_1352.obj` scaled by 0.5) fitted to the silhouettes of the
/// demo's generated target ([`crate::fit::mesh_fit::demo_target`]) from 120 views (elevation
/// 30°, azimuth every 3°, distance 2.732, viewing angle 15°) at 64², σ 1e-4, hard colour,
/// `1 − IoU + 0.03 Laplacian + 0.0003 flatten`, Adam (0.01, 0.5, 0.99), tile 8
/// ([`MeshFitOptions::default`](crate::fit::mesh_fit::MeshFitOptions)).
///
/// After one untimed iteration, `opts.repeat` iterations run one per submission with GPU
/// timestamps: record `fit-iteration` (medians; `passes` starts with the `render`, `backward`
/// and `rest` shares of [`fit_pass_share`], then every pass). Then the fit loop: [`FIT_BATCH`]
/// iterations one per submission (`fit-loop-k1`) and the next [`FIT_BATCH`] in one submission
/// (`fit-loop-k10`): wall and GPU time per iteration (means), and as its one pass the `host
/// overhead`, wall minus GPU (recording, submission, fence, the gate's status read).
/// The fit goes on from iteration to iteration (the shape changes a little), as a real fit
/// does; an iteration stopped by the gate (its entries outgrew the capacity) is re-run and not
/// counted.
pub fn run_fit(
    ctx: &Context,
    opts: &BenchOptions,
    mut progress: impl FnMut(&str),
) -> Result<Vec<BenchRecord>> {
    use crate::fit::mesh_fit::{MeshFitOptions, MeshFitter, default_template, demo_target};
    let names = opts.checked_fit_scenes()?;
    let mut records = Vec::new();
    for name in names {
        if name == "fit-field" {
            let assets = opts.assets.clone().unwrap_or_else(crate::assets::dir);
            records.push(run_field_fit(ctx, opts, &assets, &mut progress)?);
            continue;
        }
        if name == "fit-pose" {
            let assets = opts.assets.clone().unwrap_or_else(crate::assets::dir);
            records.extend(run_pose_fit(ctx, opts, &assets, &mut progress)?);
            continue;
        }
        // SoftRas's template, as `softvk fit-mesh` uses it by default.
        let template = default_template();
        let fit_opts = MeshFitOptions {
            log_every: 1,
            ..MeshFitOptions::default()
        };
        let s = fit_opts.settings;
        let cameras: Vec<Camera> = (0..120)
            .map(|i| Camera {
                projection: Projection::Perspective {
                    viewing_angle_deg: 15.0,
                },
                ..Camera::from_angles(DISTANCE, 30.0, f64::from(3 * i))
            })
            .collect();
        let hard = RasterSettings {
            dist: Dist::Hard,
            alpha: crate::raster::settings::Alpha::Hard,
            rgb: Rgb::Hard,
            ..s
        };
        let targets: Vec<f32> = Renderer::new(ctx)?.render_silhouettes(
            ctx,
            &demo_target(),
            &cameras,
            &hard,
            Method::default(),
        )?;
        let mut fitter = MeshFitter::new(ctx, &template, &cameras, &targets, &fit_opts)?;
        let method = Method::Tiled {
            tile: fit_opts.tile,
        };
        progress(&format!(
            "{name}: sphere_1352 x0.5 ({} faces) fitted to the demo target's silhouettes, {} \
             views of {}x{}, sigma {:e}, rgb {:?}, tile {}; entry capacity {}",
            template.face_count(),
            cameras.len(),
            s.width,
            s.height,
            s.sigma,
            s.rgb,
            fit_opts.tile,
            fitter.capacity()
        ));
        let mut it = 1u32;
        fit_iterations(&mut fitter, &mut it, 1, None, &mut progress, name)?;
        progress(&format!(
            "{name}: warm-up done, {} entries; timing {} iterations",
            fitter.last_entries(),
            opts.repeat
        ));
        let mut timer = if ctx.info().timestamp_valid_bits > 0 {
            Some(Timer::new(ctx, 32)?)
        } else {
            None
        };
        let mut wall = Vec::new();
        let mut gpu = Vec::new();
        let mut passes: Vec<(String, Vec<f64>)> = Vec::new();
        for _ in 0..opts.repeat {
            wall.push(fit_iterations(
                &mut fitter,
                &mut it,
                1,
                timer.as_mut(),
                &mut progress,
                name,
            )?);
            if let Some(timer) = &timer {
                let times = timer.results(ctx)?;
                gpu.push(times.iter().map(|t| t.ms).sum());
                let mut row: Vec<(String, f64)> = ["render", "backward", "rest"]
                    .iter()
                    .map(|share| {
                        let ms = times
                            .iter()
                            .filter(|t| fit_pass_share(&t.name) == *share)
                            .map(|t| t.ms)
                            .sum();
                        (share.to_string(), ms)
                    })
                    .collect();
                row.extend(times.iter().map(|t| (t.name.clone(), t.ms)));
                if passes.is_empty() {
                    passes = row.iter().map(|(n, _)| (n.clone(), Vec::new())).collect();
                }
                for ((_, series), (_, ms)) in passes.iter_mut().zip(&row) {
                    series.push(*ms);
                }
            }
        }
        let timing = Timing::medians(&gpu, &wall, &passes);
        progress(&format!(
            "{name} fit-iteration: {}",
            summary(&timing, opts.repeat)
        ));
        let counts = fitter.scene().pair_counts(ctx, method)?;
        progress(&format!(
            "{name} fit-iteration per pair:{}",
            per_pair_summary(&timing.passes, &counts)
        ));
        let record = |pass: &'static str, gpu_ms, wall_ms, passes, repeats, entries| BenchRecord {
            scene: name.to_string(),
            method,
            pass,
            gpu_ms,
            wall_ms,
            pairs: counts.binned,
            counts: Some(counts),
            device: ctx.info().name.clone(),
            driver: ctx.info().driver.clone(),
            repeats,
            passes,
            views: cameras.len() as u32,
            faces: template.face_count() as u32,
            width: s.width,
            height: s.height,
            rows: None,
            entries: Some(entries),
            identical_to_brute: None,
        };
        records.push(record(
            "fit-iteration",
            timing.gpu_ms,
            timing.wall_ms,
            timing.passes,
            opts.repeat,
            fitter.last_entries(),
        ));
        // The loop, one and ten iterations per submission.
        for (pass, k) in [("fit-loop-k1", 1), ("fit-loop-k10", FIT_BATCH)] {
            let t = time_fit_loop(ctx, &mut fitter, &mut it, k, &mut progress, name, pass)?;
            records.push(record(
                pass,
                t.gpu_ms,
                t.wall_ms,
                t.passes,
                FIT_BATCH,
                fitter.last_entries(),
            ));
        }
    }
    Ok(records)
}

#[cfg(test)]
mod tests {
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
        assert!(crate::mesh::tests::is_closed_and_consistent(&dense));
        assert!(Scene::load("nope", &assets).is_err());
    }
}
