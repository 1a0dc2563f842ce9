//! `softvk dataset --out DIR [--categories chair,table,...] [--train N] [--val N] [--test N]
//! [--seed S]`: a procedural dataset in the NMR/SoftRas layout ([`softvk::recon::dataset`]):
//! per category and split, `<synset>_<split>_images.npz` (N × 24 views × RGBA × 64 × 64, uint8)
//! and `<synset>_<split>_voxels.npz` (N × 32³, uint8), plus `contact_sheet.png`: a few objects
//! of each category, eight of their views each, over grey.
//!
//! Every file is written atomically. A first Ctrl-C stops after the class and split in flight
//! (the files written are whole; the rest are not written), a second at once.

use std::path::PathBuf;

use clap::Args;
use softvk::gpu::{Context, ContextOptions};
use softvk::recon::dataset::{self, Dataset, DatasetOptions, IMAGE_SIZE, Split, VIEWS};
use softvk::recon::shapes::Category;
use softvk::{Error, Result};

use super::args::positive;
use super::interrupt;
use super::output::{AtomicFile, ImageFormat};

/// The flags of `softvk dataset`.
#[derive(Args, Clone, Debug)]
pub struct DatasetArgs {
    /// The folder to write into (created if missing; files of the same names are replaced).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,

    /// Categories, comma-separated names or ShapeNet synset ids. Known: airplane, bench,
    /// cabinet, car, chair, display, lamp, sofa, table.
    #[arg(
        long,
        value_name = "LIST",
        value_delimiter = ',',
        default_value = "airplane,bench,car,chair,lamp,table"
    )]
    pub categories: Vec<String>,

    /// Training objects per category (the defaults, 6 classes × 500 / 32 / 32, take about 4
    /// minutes on 2 cores with lavapipe and 132 MB of disk).
    #[arg(long, value_name = "N", default_value_t = 500)]
    pub train: usize,

    /// Validation objects per category.
    #[arg(long, value_name = "N", default_value_t = 32)]
    pub val: usize,

    /// Test objects per category.
    #[arg(long, value_name = "N", default_value_t = 32)]
    pub test: usize,

    /// Seed of the objects: the same flags give the same bytes.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub seed: u64,

    /// Objects rendered in one GPU batch (24 views each; the same bytes whatever N; a batch
    /// past what one storage binding holds renders in parts). One at a time is fastest on
    /// lavapipe; a GPU may prefer more.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub batch: usize,

    /// σ of the coverage sigmoid (small: crisp silhouettes).
    #[arg(long, value_name = "S", default_value_t = 1e-5, value_parser = positive)]
    pub sigma: f64,

    /// Render at 1× instead of 2× averaged (faster, aliased edges).
    #[arg(long)]
    pub no_antialias: bool,
}

/// Objects per category and views per object on the contact sheet.
const SHEET_OBJECTS: usize = 3;
const SHEET_VIEWS: usize = 8;

/// Runs `softvk dataset`.
pub fn run(args: &DatasetArgs) -> Result<()> {
    let categories = args
        .categories
        .iter()
        .map(|c| Category::parse(c))
        .collect::<Result<Vec<_>>>()?;
    if args.batch == 0 {
        return Err(Error::Input("--batch must be at least 1".into()));
    }
    if args.out.is_file() {
        return Err(Error::Input(format!(
            "{}: is a file, not a folder",
            args.out.display()
        )));
    }
    let options = DatasetOptions {
        categories,
        train: args.train,
        val: args.val,
        test: args.test,
        seed: args.seed,
        batch: args.batch,
        sigma: args.sigma,
        antialias: !args.no_antialias,
    };
    let ctx = Context::new(&ContextOptions::from_env())?;
    let start = std::time::Instant::now();
    let written = dataset::write_dataset(&ctx, &args.out, &options, &mut |c, s, n| {
        println!(
            "{} ({}) {}: {n} objects ({:.1} s)",
            c.synset(),
            c.name(),
            s.name(),
            start.elapsed().as_secs_f64()
        );
        interrupt::requested().is_none()
    })?;
    if interrupt::requested().is_some() {
        return Ok(());
    }
    let sheet = args.out.join("contact_sheet.png");
    write_contact_sheet(&args.out, &options, &sheet)?;
    println!(
        "wrote {} files and {} in {:.1} s",
        written.len(),
        sheet.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The first split with objects, read back, as rows of [`SHEET_VIEWS`] views of up to
/// [`SHEET_OBJECTS`] objects per class, composited over grey.
fn write_contact_sheet(
    dir: &std::path::Path,
    options: &DatasetOptions,
    path: &std::path::Path,
) -> Result<()> {
    let Some(split) = Split::ALL.into_iter().find(|&s| options.count(s) > 0) else {
        return Ok(());
    };
    let data = Dataset::open(dir, split)?;
    let s = IMAGE_SIZE;
    let rows: Vec<(usize, usize)> = data
        .classes
        .iter()
        .enumerate()
        .flat_map(|(c, class)| (0..class.count.min(SHEET_OBJECTS)).map(move |n| (c, n)))
        .collect();
    let (w, h) = (SHEET_VIEWS * s, rows.len().max(1) * s);
    let grey = 0.8f32;
    let mut pixels = vec![[grey, grey, grey, 1.0]; w * h];
    let plane = s * s;
    for (row, &(c, n)) in rows.iter().enumerate() {
        for col in 0..SHEET_VIEWS {
            let image = data.classes[c].image(n, col * VIEWS / SHEET_VIEWS);
            for p in 0..plane {
                let a = f32::from(image[3 * plane + p]) / 255.0;
                let (y, x) = (row * s + p / s, col * s + p % s);
                // The colour already has the black background blended in by coverage.
                pixels[y * w + x] = std::array::from_fn(|ch| {
                    if ch == 3 {
                        1.0
                    } else {
                        f32::from(image[ch * plane + p]) / 255.0 + (1.0 - a) * grey
                    }
                });
            }
        }
    }
    let bytes = ImageFormat::Png
        .encode(&pixels, w as u32, h as u32)
        .map_err(|e| Error::Input(format!("{}: {e}", path.display())))?;
    AtomicFile::create(path)?.commit(&bytes)
}
