//! `softvk bench [--json OUT.json] [--scene NAME]... [--repeat N] [--assets DIR]` (SPEC §6): the
//! forward benchmark ([`softvk::bench::run`]: tiled at each tile size vs brute force, checked bit
//! for bit) and the backward one ([`softvk::bench::run_backward`]: backward and
//! forward+backward), as the JSON records of the spec; with `--scene fit-120`, the fitting
//! iteration ([`softvk::bench::run_fit`]). Progress goes to stderr.

use std::path::PathBuf;

use clap::Args;
use softvk::Result;
use softvk::bench::{self, BenchOptions};
use softvk::gpu::{Context, ContextOptions};

use super::output::AtomicFile;

/// The flags of `softvk bench`.
#[derive(Args, Clone, Debug)]
pub struct BenchArgs {
    /// Write the records here (else to stdout).
    #[arg(long, value_name = "OUT.json")]
    pub json: Option<PathBuf>,
    /// Scene to run (repeatable; default all: spot-256, sphere-64x120, dense-1024, blurry-256).
    /// `spot3-1024` renders spot subdivided three times (374 784 faces) at 1024², `blurry-1024`
    /// blurry-256 at 1024² (more entries than one binding holds), `crowded-327k` and
    /// `spread-327k` a 327 680-face sphere at 64² in one tile (folded in passes) and filling
    /// the frame; `fit-120`
    /// times a mesh-fitting iteration at SoftRas's demo setting, `fit-field` a `softvk
    /// fit-field` iteration at its defaults on spot, `fit-pose` a `softvk fit-pose` iteration
    /// at its defaults on spot, `train-recon` a `softvk train-recon` iteration at its defaults,
    /// `train-recon-field` one of `softvk train-recon --field`; `nv-spot-256`, `nv-512` and
    /// `nv-1024` nvdiffrast's primitives on spot (each only when named, the nv-… ones alone).
    #[arg(long = "scene", value_name = "NAME")]
    pub scenes: Vec<String>,
    /// Timed submissions per (scene, method, pass); times are medians.
    #[arg(long, value_name = "N", default_value_t = bench::DEFAULT_REPEAT)]
    pub repeat: u32,
    /// Timed submissions of brute force (default: --repeat; each takes seconds on a CPU device).
    #[arg(long, value_name = "N")]
    pub brute_repeat: Option<u32>,
    /// Tile size (repeatable; default 8, 16, 32).
    #[arg(long = "tile", value_name = "N")]
    pub tiles: Vec<u32>,
    /// Skip brute force (and the bit-for-bit check against it).
    #[arg(long)]
    pub no_brute: bool,
    /// Forward only (no backward or forward+backward records).
    #[arg(long, conflicts_with = "backward_only")]
    pub forward_only: bool,
    /// Backward and forward+backward only (no forward records).
    #[arg(long)]
    pub backward_only: bool,
    /// Render only the middle N rows of every scene (quick runs).
    #[arg(long, value_name = "ROWS")]
    pub band: Option<u32>,
    /// Folder of the meshes (default: SOFTVK_ASSETS, else the project's assets/).
    #[arg(long, value_name = "DIR")]
    pub assets: Option<PathBuf>,
}

/// Runs `softvk bench`.
pub fn run(args: &BenchArgs) -> Result<()> {
    let opts = BenchOptions {
        scenes: args.scenes.clone(),
        repeat: args.repeat,
        brute_repeat: args.brute_repeat,
        tiles: if args.tiles.is_empty() {
            bench::DEFAULT_TILES.to_vec()
        } else {
            args.tiles.clone()
        },
        brute: !args.no_brute,
        band: args.band,
        assets: args.assets.clone(),
    };
    let render_scenes = opts.checked_scenes()?;
    let hard_scenes: Vec<&str> = bench::HARD_SCENES
        .iter()
        .copied()
        .filter(|s| opts.scenes.iter().any(|n| n == s))
        .collect();
    if !hard_scenes.is_empty() && hard_scenes.len() != opts.scenes.len() {
        return Err(softvk::Error::Input(
            "bench: name the nv-… scenes on their own (their records have other fields)".into(),
        ));
    }
    let fit_scenes = opts.checked_fit_scenes()?;
    let out = args.json.as_deref().map(AtomicFile::create).transpose()?;
    let ctx = Context::new(&ContextOptions::from_env())?;
    eprintln!("device: {} / {}", ctx.info().name, ctx.info().driver);
    if !hard_scenes.is_empty() {
        let assets = opts.assets.clone().unwrap_or_else(softvk::assets::dir);
        let records = bench::run_hard(&ctx, &hard_scenes, opts.repeat, &assets, |line| {
            eprintln!("{line}")
        })?;
        ctx.check_validation()?;
        let json = bench::hard_to_json(&records);
        return match out {
            Some(file) => file.commit(json.as_bytes()),
            None => {
                print!("{json}");
                Ok(())
            }
        };
    }
    let mut records = Vec::new();
    if !render_scenes.is_empty() {
        if !args.backward_only {
            records = bench::run(&ctx, &opts, |line| eprintln!("{line}"))?;
        }
        if !args.forward_only {
            records.extend(bench::run_backward(&ctx, &opts, |line| {
                eprintln!("{line}")
            })?);
        }
    }
    if !fit_scenes.is_empty() {
        records.extend(bench::run_fit(&ctx, &opts, |line| eprintln!("{line}"))?);
    }
    ctx.check_validation()?;
    let json = bench::to_json(&records);
    match out {
        Some(file) => file.commit(json.as_bytes()),
        None => {
            print!("{json}");
            Ok(())
        }
    }
}
