//! Runs the forward benchmark through the library entry point that `softvk bench` calls, for use
//! before (or beside) the CLI: progress on stderr, the JSON records to `--json` or stdout.
//!
//! ```sh
//! cargo run --release --example bench -- --json bench/out.json [--scene spot-256]... \
//!     [--repeat 5] [--brute-repeat N] [--tile 16]... [--no-brute] [--band ROWS] \
//!     [--assets DIR]
//! ```

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use softvk::bench::{self, BenchOptions};
use softvk::gpu::{Context, ContextOptions};

#[derive(Parser)]
struct Args {
    /// Write the records here (else to stdout).
    #[arg(long)]
    json: Option<PathBuf>,
    /// Scene to run (repeatable; default all).
    #[arg(long = "scene")]
    scenes: Vec<String>,
    /// Timed submissions per (scene, method).
    #[arg(long, default_value_t = bench::DEFAULT_REPEAT)]
    repeat: u32,
    /// Timed submissions of brute force (default: --repeat).
    #[arg(long)]
    brute_repeat: Option<u32>,
    /// Tile size (repeatable; default 8, 16, 32).
    #[arg(long = "tile")]
    tiles: Vec<u32>,
    /// Skip brute force (and the bit-for-bit check against it).
    #[arg(long)]
    no_brute: bool,
    /// Render only the middle N rows of every scene.
    #[arg(long)]
    band: Option<u32>,
    /// Folder of the meshes (default SOFTVK_ASSETS).
    #[arg(long)]
    assets: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let opts = BenchOptions {
        scenes: args.scenes,
        repeat: args.repeat,
        brute_repeat: args.brute_repeat,
        tiles: if args.tiles.is_empty() {
            bench::DEFAULT_TILES.to_vec()
        } else {
            args.tiles
        },
        brute: !args.no_brute,
        band: args.band,
        assets: args.assets,
    };
    let result = Context::new(&ContextOptions::from_env()).and_then(|ctx| {
        eprintln!("device: {} / {}", ctx.info().name, ctx.info().driver);
        bench::run(&ctx, &opts, |line| eprintln!("{line}"))
    });
    let records = match result {
        Ok(records) => records,
        Err(e) => {
            eprintln!("bench: error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let json = bench::to_json(&records);
    match args.json {
        Some(path) => {
            // Write whole or not at all.
            let tmp = path.with_extension("json.tmp");
            if let Err(e) = std::fs::write(&tmp, &json).and_then(|()| std::fs::rename(&tmp, &path))
            {
                eprintln!("bench: error: {}: {e}", path.display());
                return ExitCode::FAILURE;
            }
        }
        None => print!("{json}"),
    }
    ExitCode::SUCCESS
}
