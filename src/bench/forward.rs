//! The forward pass per scene: tiled (per tile size) against brute force, checked bit for bit
//! against each other before and after timing.

use std::time::Instant;

use super::{BenchOptions, BenchRecord, Scene};
use crate::error::{Error, Result};
use crate::gpu::{Context, PassTime, Recorded, Timer};
use crate::raster::gpu::{
    Binned, ExactRun, Frames, GpuScene, Method, PairCounts, Renderer, ViewGroup,
};

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
pub(super) struct Samples {
    wall_ms: Vec<f64>,
    gpu_ms: Vec<f64>,
    passes: Vec<(String, Vec<f64>)>,
}

impl Samples {
    /// Submits `recorded` once, waits, and records its times (GPU ones from `timer`, if any).
    pub(super) fn take(
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
            self.gpu_ms.push(PassTime::top_level_ms(&times));
            // A pass recorded more than once (per view group or window) counts as one, summed.
            let mut merged: Vec<(String, f64)> = Vec::new();
            for t in &times {
                let name = t.indented();
                match merged.iter_mut().find(|(n, _)| *n == name) {
                    Some((_, ms)) => *ms += t.ms,
                    None => merged.push((name, t.ms)),
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

    pub(super) fn len(&self) -> usize {
        self.wall_ms.len()
    }

    /// The medians.
    pub(super) fn timing(&self) -> Timing {
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
        // Brute force is recorded without a first run (it bins nothing, and its setups are
        // counted after its first timed submission, [`Variant::sample`]).
        let run = match method {
            Method::Brute => ExactRun::brute(&gpu),
            Method::Tiled { .. } => renderer.run(ctx, &mut gpu, method)?,
        };
        let binned = run.binned();
        let (entries, counts) = match method {
            Method::Brute => (None, PairCounts::default()),
            Method::Tiled { .. } => (Some(binned.entries()), binned.pair_counts(ctx)?),
        };
        // Face setup and downsampling, count, sort and fine pass per view group or window; a
        // device without timestamps still gets wall times.
        let mut timer = if ctx.info().timestamp_valid_bits > 0 {
            Some(Timer::new(ctx, 2 + 3 * binned.groups().len() as u32)?)
        } else {
            None
        };
        let recorded = ctx.record(timer.as_mut(), |rec| {
            renderer.record_forward(rec, &run).map(|_| ())
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
            self.counts = self.binned().pair_counts(ctx)?;
        }
        Ok(())
    }

    fn timing(&self) -> Timing {
        self.samples.timing()
    }

    /// The binning of the recorded forward.
    fn binned(&self) -> Binned<'_> {
        match self.method {
            Method::Brute => ExactRun::brute(&self.gpu).binned(),
            Method::Tiled { .. } => self
                .gpu
                .last_run()
                .expect("a tiled variant ran, and nothing changed its scene")
                .binned(),
        }
    }
}

/// The medians of one method's timed submissions.
pub(super) struct Timing {
    pub(super) gpu_ms: Option<f64>,
    pub(super) wall_ms: f64,
    pub(super) passes: Vec<(String, f64)>,
}

impl Timing {
    /// The medians of GPU and wall times and of each pass's series (a pass without samples is
    /// left out).
    pub(super) fn medians(
        gpu_ms: &[f64],
        wall_ms: &[f64],
        passes: &[(String, Vec<f64>)],
    ) -> Timing {
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
        reference = Some((bits(&v.gpu.read_frames(ctx)?), "brute force".into()));
        variants.push(v);
    }
    let check = |v: &Variant<'_>, reference: &mut Option<(Bits, String)>, when: &str| {
        let got = bits(&v.gpu.read_frames(ctx)?);
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
            binnings(v.binned().groups())
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
pub(super) fn per_pair_summary(passes: &[(String, f64)], counts: &PairCounts) -> String {
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

pub(super) fn summary(t: &Timing, repeats: u32) -> String {
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
pub(super) fn median(samples: &[f64]) -> Option<f64> {
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
