//! `softvk eval-recon --dataset DIR --model MODEL [--model MODEL ...] [--predicted LABEL=DIR]`:
//! the table of 3D IoU per class on the test split, a column per model (a mesh model's by
//! parity and by winding number) and per set of external predictions, beside the baselines
//! (retrieval, which knows the view; the mean shape, which knows the class; the visual hull),
//! then each column minus each baseline, and each column after the first minus the first, with
//! paired bootstrap intervals ([`softvk::recon::eval`]); `--report` adds the tables as text and
//! CSV and a picture of inputs beside reconstructions.

use std::path::{Path, PathBuf};

use clap::Args;
use softvk::fit::report;
use softvk::gpu::{Context, ContextOptions};
use softvk::lighting::Lighting;
use softvk::raster::gpu::{Method, Renderer};
use softvk::recon::dataset::{self, ClassData, Dataset, Split};
use softvk::recon::eval::{self, Mask, ScoreRow};
use softvk::recon::model::ReconModel;
use softvk::{Error, Result};

use super::output::AtomicFile;
use softvk::recon::reconstruct::{AnyReconstructor, spread_views, upscale, view_settings};

/// The flags of `softvk eval-recon`.
#[derive(Args, Clone, Debug)]
pub struct EvalReconArgs {
    /// Dataset folder (train split for the baselines, test split for the scores).
    #[arg(long, value_name = "DIR")]
    pub dataset: PathBuf,

    /// A model written by `softvk train-recon` (mesh or field); repeat it for a column per
    /// model (two for a mesh model: parity and winding-number voxelization).
    #[arg(long, value_name = "MODEL", required_unless_present = "predicted")]
    pub model: Vec<PathBuf>,

    /// Another program's predictions as a column named LABEL: per class,
    /// `DIR/<class>_test_predicted_voxels.npz`, array `arr_0`, uint8 0/1 of shape
    /// (N, 24, 32, 32, 32) (object n's voxels predicted from view v, in the order of the
    /// dataset's voxels); repeatable.
    #[arg(long, value_name = "LABEL=DIR", value_parser = label_dir)]
    pub predicted: Vec<(String, PathBuf)>,

    /// Inputs per test object: views spread evenly over the 24 (24: every view, as SoftRas).
    #[arg(long, value_name = "V", default_value_t = 24, value_parser = clap::value_parser!(u32).range(1..))]
    pub views: u32,

    /// Also write the table (text) and a picture of inputs beside reconstructions here.
    #[arg(long, value_name = "DIR")]
    pub report: Option<PathBuf>,

    /// How a predicted mesh becomes voxels: `parity` (voxel centres inside, the ground truth's
    /// convention) or `softras` (SoftRas's evaluation: the voxels the surface passes through
    /// and what they enclose, a column before the parity one). Each mesh model is also scored
    /// by winding number (centres where |w| ≥ 0.5), which a self-overlapping fold does not
    /// empty as it does parity.
    #[arg(long, value_enum, default_value_t = VoxelizeArg::Parity)]
    pub voxelize: VoxelizeArg,
}

/// `--voxelize` of `softvk eval-recon`: [`eval::Voxelizer`]'s two ways.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum VoxelizeArg {
    /// SoftRas's evaluation: the voxels the surface passes through and what they enclose.
    Softras,
    /// Voxel centres inside by parity (the ground truth's convention).
    Parity,
}

impl From<VoxelizeArg> for eval::Voxelizer {
    fn from(v: VoxelizeArg) -> Self {
        match v {
            VoxelizeArg::Softras => eval::Voxelizer::SoftRas,
            VoxelizeArg::Parity => eval::Voxelizer::Parity,
        }
    }
}

/// `--predicted LABEL=DIR`.
fn label_dir(s: &str) -> std::result::Result<(String, PathBuf), String> {
    match s.split_once('=') {
        Some((label, dir)) if !label.is_empty() && !dir.is_empty() => {
            Ok((label.to_owned(), PathBuf::from(dir)))
        }
        _ => Err(format!("`{s}`: expected LABEL=DIR")),
    }
}

/// `softvk eval-recon`.
pub fn evaluate(args: &EvalReconArgs) -> Result<()> {
    let models = args
        .model
        .iter()
        .map(|p| ReconModel::load(p))
        .collect::<Result<Vec<_>>>()?;
    let train = Dataset::open(&args.dataset, Split::Train)?;
    let test = Dataset::open(&args.dataset, Split::Test)?;
    if test.classes.is_empty() {
        return Err(Error::Input(format!(
            "{}: no test split (`<class>_test_images.npz`)",
            args.dataset.display()
        )));
    }
    // Every class's external predictions, read and checked before any work.
    let predicted = args
        .predicted
        .iter()
        .map(|(_, dir)| {
            test.classes
                .iter()
                .map(|c| eval::read_predictions(dir, c))
                .collect::<Result<Vec<_>>>()
        })
        .collect::<Result<Vec<_>>>()?;
    let ctx = Context::new(&ContextOptions::from_env())?;
    let recons = models
        .iter()
        .map(|m| AnyReconstructor::new(&ctx, m, 32))
        .collect::<Result<Vec<_>>>()?;
    // A mesh model's columns: `--voxelize softras` when asked, parity and winding always.
    let mesh_voxelizers: Vec<eval::Voxelizer> = match args.voxelize {
        VoxelizeArg::Softras => vec![eval::Voxelizer::SoftRas],
        VoxelizeArg::Parity => vec![],
    }
    .into_iter()
    .chain([eval::Voxelizer::Parity, eval::Voxelizer::Winding])
    .collect();
    let stem = |p: &Path| {
        p.file_stem()
            .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned())
    };
    // The examples' names (one per model) and the table's network columns.
    let names: Vec<String> = args
        .model
        .iter()
        .zip(&recons)
        .map(|(p, r)| format!("{} ({})", stem(p), r.kind()))
        .collect();
    let mut columns: Vec<String> = Vec::new();
    for (p, r) in args.model.iter().zip(&recons) {
        match r {
            AnyReconstructor::Mesh(_) => columns.extend(
                mesh_voxelizers
                    .iter()
                    .map(|v| format!("{} (mesh, {})", stem(p), v.name())),
            ),
            AnyReconstructor::Field(_) => columns.push(format!("{} (field)", stem(p))),
        }
    }
    columns.extend(
        args.predicted
            .iter()
            .map(|(label, _)| format!("{label} (predicted)")),
    );
    let views = spread_views(args.views);
    // Retrieval: every training object's silhouette per view.
    let train_objects: Vec<(&ClassData, usize)> = train
        .classes
        .iter()
        .flat_map(|c| (0..c.count).map(move |n| (c, n)))
        .collect();
    let alpha = |c: &ClassData, n: usize, v: usize| {
        let px = dataset::IMAGE_SIZE * dataset::IMAGE_SIZE;
        Mask::from_alpha(&c.image(n, v)[3 * px..])
    };
    let masks: Vec<Vec<Mask>> = (0..dataset::VIEWS)
        .map(|v| train_objects.iter().map(|&(c, n)| alpha(c, n, v)).collect())
        .collect();
    // The retrieved objects' visual hulls, made when first retrieved.
    let mut train_hulls: Vec<Option<Vec<bool>>> = vec![None; train_objects.len()];
    let mut rows = Vec::new();
    let per_object = |v: &[f64]| eval::per_object(v, views.len());
    for (ci, class) in test.classes.iter().enumerate() {
        let inputs: Vec<(usize, usize)> = (0..class.count)
            .flat_map(|n| views.iter().map(move |&v| (n, v)))
            .collect();
        let mut networks = Vec::with_capacity(columns.len());
        for r in &recons {
            for c in r.columns(&ctx, class, &inputs, &mesh_voxelizers)? {
                networks.push(per_object(&c));
            }
        }
        for p in &predicted {
            networks.push(per_object(&eval::predicted_ious(&p[ci], class, &inputs)?));
        }
        let mut retrieval = Vec::with_capacity(inputs.len());
        let mut retrieval_hull = Vec::with_capacity(inputs.len());
        for &(n, v) in &inputs {
            let best = eval::retrieve(&alpha(class, n, v), &masks[v])
                .ok_or_else(|| Error::Input("no training objects to retrieve from".into()))?;
            let (c, m) = train_objects[best];
            retrieval.push(eval::voxel_iou(c.voxels_of(m), class.voxels_of(n))?);
            if train_hulls[best].is_none() {
                train_hulls[best] = Some(eval::visual_hull_voxels(c, m)?);
            }
            let hull = train_hulls[best].as_deref().expect("made above");
            retrieval_hull.push(eval::voxel_iou(hull, class.voxels_of(n))?);
        }
        let same: Vec<&[bool]> = train
            .classes
            .iter()
            .filter(|c| c.class_id == class.class_id)
            .flat_map(|c| (0..c.count).map(move |n| c.voxels_of(n)))
            .collect();
        let mean = eval::mean_shape(&same).map_err(|_| {
            Error::Input(format!(
                "class {} has no training objects for its mean shape",
                class.class_id
            ))
        })?;
        let mean_iou = (0..class.count)
            .map(|n| eval::voxel_iou(&mean, class.voxels_of(n)))
            .collect::<Result<Vec<f64>>>()?;
        let hull = (0..class.count)
            .map(|n| eval::visual_hull_iou(class, n))
            .collect::<Result<Vec<f64>>>()?;
        rows.push(ScoreRow {
            class: class_label(class),
            inputs: inputs.len(),
            networks,
            baselines: [
                per_object(&retrieval),
                per_object(&retrieval_hull),
                mean_iou,
                hull,
            ],
        });
    }
    let comparison = eval::compare(&rows)?;
    let mut table = eval::format_table(&columns, &rows);
    if recons
        .iter()
        .any(|r| matches!(r, AnyReconstructor::Mesh(_)))
    {
        if args.voxelize == VoxelizeArg::Softras {
            table.push_str(
                "mesh predictions voxelized by softras: SoftRas's evaluation (surface voxels \
                 and what they enclose)\n",
            );
        }
        table.push_str(
            "mesh predictions voxelized by parity: voxel centres inside by the parity of \
             crossings along x (a fold that overlaps the surface empties what it doubles)\n\
             mesh predictions voxelized by winding: voxel centres where the winding number is \
             ≥ 0.5 in magnitude (a doubled region stays inside)\n",
        );
    }
    if recons
        .iter()
        .any(|r| matches!(r, AnyReconstructor::Field(_)))
    {
        table.push_str("field predictions: φ > 0.5 at the voxel centres\n");
    }
    if !args.predicted.is_empty() {
        table.push_str(
            "predicted: another program's voxels per input \
             (`<class>_test_predicted_voxels.npz`)\n",
        );
    }
    for line in eval::BASELINE_LEGEND {
        table.push_str(&format!("baseline {line}\n"));
    }
    table.push('\n');
    table.push_str(&eval::format_comparison(&columns, &rows, &comparison));
    print!("{table}");
    if let Some(dir) = &args.report {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::Input(format!("cannot create {}: {e}", dir.display())))?;
        AtomicFile::create(&dir.join("table.txt"))?.commit(table.as_bytes())?;
        AtomicFile::create(&dir.join("table.csv"))?
            .commit(eval::table_csv(&columns, &rows, &comparison).as_bytes())?;
        write_examples(&ctx, &names, &recons, &test, dir)?;
    }
    Ok(())
}

/// `02691156 (airplane)` for a class softvk generates, else the class id.
fn class_label(class: &ClassData) -> String {
    match class.category {
        Some(c) => format!("{} ({})", class.class_id, c.name()),
        None => class.class_id.clone(),
    }
}

/// `examples.png`: per class, the first test object's views 0 and 9 as inputs beside each
/// model's reconstructions, shaded and seen from the input's camera; and each input as
/// `input-<class>-<view>.png` (what `softvk recon --image` takes).
fn write_examples(
    ctx: &Context,
    names: &[String],
    recons: &[AnyReconstructor],
    test: &Dataset,
    dir: &Path,
) -> Result<()> {
    const SIZE: u32 = 128;
    let size = dataset::IMAGE_SIZE as u32;
    let px = (size * size) as usize;
    let settings = view_settings(SIZE);
    let renderer = Renderer::new(ctx)?;
    let mut rows: Vec<image::RgbaImage> = Vec::new();
    for class in &test.classes {
        let mut cells: Vec<(String, Vec<[f32; 4]>)> = Vec::new();
        for v in [0usize, 9] {
            let input = class.image(0, v);
            let mut shaded = Vec::with_capacity(recons.len());
            for recon in recons {
                // An empty field shows as an empty (black) cell.
                let images = match recon.mesh(ctx, input)? {
                    Some(mesh) => {
                        renderer
                            .render_views(
                                ctx,
                                &mesh,
                                &[dataset::view_camera(v)],
                                &Lighting::default(),
                                &settings,
                                Method::default(),
                            )?
                            .images
                    }
                    None => vec![[0.0; 4]; (SIZE * SIZE) as usize],
                };
                shaded.push(images);
            }
            let name = format!("input-{}-{v}.png", class.class_id);
            let rgba: Vec<u8> = (0..px)
                .flat_map(|p| [0, 1, 2, 3].map(|c| input[c * px + p]))
                .collect();
            let img = image::RgbaImage::from_raw(size, size, rgba).expect("64² RGBA");
            report::write_png(&dir.join(&name), &img)?;
            cells.push((
                format!(
                    "{}, view {v}",
                    class.category.map_or(&class.class_id[..], |c| c.name())
                ),
                upscale(input, size, SIZE),
            ));
            for (name, images) in names.iter().zip(shaded) {
                cells.push((name.clone(), images));
            }
        }
        let refs: Vec<(&str, &[[f32; 4]])> =
            cells.iter().map(|(n, i)| (n.as_str(), &i[..])).collect();
        rows.push(report::side_by_side(&refs, SIZE, SIZE));
    }
    let (w, h) = (
        rows.iter().map(|r| r.width()).max().unwrap_or(1),
        rows.iter().map(|r| r.height()).sum::<u32>().max(1),
    );
    let mut sheet = image::RgbaImage::from_pixel(w, h, image::Rgba([0, 0, 0, 255]));
    let mut y = 0;
    for r in &rows {
        image::imageops::overlay(&mut sheet, r, 0, i64::from(y));
        y += r.height();
    }
    report::write_png(&dir.join("examples.png"), &sheet)
}
