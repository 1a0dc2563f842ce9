//! The reconstruction trainers' iterations (`softvk bench --scene train-recon`,
//! `--scene train-recon-field`): where a `softvk train-recon` iteration at its defaults spends
//! its time, pass by pass, for the mesh network and the conditioned field.

use super::fits::{fit_iterations, time_iterations};
use super::forward::summary;
use super::{BenchOptions, BenchRecord};
use crate::error::Result;
use crate::fit::driver::{Fit, Fitter};
use crate::gpu::Context;
use crate::raster::gpu::{Method, Renderer};
use crate::recon::dataset::{DatasetOptions, Split, render_shapes, split_shapes};
use crate::recon::field::{FieldReconTrainer, FieldTrainOptions};
use crate::recon::train::{ReconTrainer, TrainImages, TrainOptions, template};

/// Objects per class of the benchmark's data: the iteration's cost does not depend on how many
/// objects there are to draw from, only on the batch.
const OBJECTS_PER_CLASS: usize = 4;

/// A `softvk train-recon` iteration at its defaults ([`TrainOptions::default`]: SoftRas's
/// recipe, batch 64, so 128 input images and 256 renders of the 1280-face template at 64²), on
/// [`OBJECTS_PER_CLASS`] training objects of each of `softvk dataset`'s default classes.
///
/// After one untimed iteration, `opts.repeat` iterations run one per submission with GPU
/// timestamps: `wall_ms` is the median wall time of an iteration (recording, staging the
/// batch's views, submission, the gate's status read), `gpu_ms` the median sum of its
/// top-level passes, and `passes` every pass (parts of a pass indented, after it). `entries` is
/// the binning's entry count of the last iteration.
pub(super) fn run_recon_train(
    ctx: &Context,
    opts: &BenchOptions,
    progress: &mut impl FnMut(&str),
) -> Result<BenchRecord> {
    let name = "train-recon";
    let train_opts = TrainOptions::default();
    let data = bench_data(ctx, train_opts.net.image)?;
    let mut trainer = ReconTrainer::new(ctx, &data, &train_opts, None)?;
    let inputs = train_opts.inputs();
    progress(&format!(
        "{name}: {:?} recipe, batch {} ({inputs} input images, {} renders of {} faces at \
         {}²), network {:?}, tile {}; entry capacity {}",
        train_opts.recipe,
        train_opts.batch,
        2 * inputs,
        template().face_count(),
        train_opts.net.image,
        train_opts.net,
        train_opts.tile,
        trainer.capacity()
    ));
    let size = train_opts.net.image;
    time_training(
        ctx,
        opts,
        &mut trainer,
        Shape {
            name,
            tile: train_opts.tile,
            timer_passes: 160,
            views: 2 * inputs,
            faces: template().face_count() as u32,
            size,
        },
        progress,
    )
}

/// [`OBJECTS_PER_CLASS`] training objects of each of `softvk dataset`'s default classes, at
/// `size`².
fn bench_data(ctx: &Context, size: u32) -> Result<TrainImages> {
    let data_opts = DatasetOptions {
        train: OBJECTS_PER_CLASS,
        ..DatasetOptions::default()
    };
    let renderer = Renderer::new(ctx)?;
    let mut images = Vec::new();
    let mut classes = Vec::new();
    for &category in &data_opts.categories {
        let shapes = split_shapes(&data_opts, category, Split::Train);
        let first = (classes.len() * OBJECTS_PER_CLASS) as u32;
        classes.push((
            category.name().to_string(),
            first..first + OBJECTS_PER_CLASS as u32,
        ));
        images.extend(render_shapes(ctx, &renderer, &shapes, &data_opts)?);
    }
    Ok(TrainImages {
        images,
        classes,
        size,
    })
}

/// A `softvk train-recon --field` iteration at its defaults ([`FieldTrainOptions::default`]:
/// batch 16, each object probed with 64 rays in each of its 24 views and 2 048 anchors), on the
/// data of [`run_recon_train`], timed the same way. `entries` is the probers' binned entries of
/// the last iteration (the largest of the batch).
pub(super) fn run_field_recon_train(
    ctx: &Context,
    opts: &BenchOptions,
    progress: &mut impl FnMut(&str),
) -> Result<BenchRecord> {
    let name = "train-recon-field";
    let train_opts = FieldTrainOptions::default();
    let data = bench_data(ctx, train_opts.net.net.image)?;
    let mut trainer = FieldReconTrainer::new(ctx, &data, &train_opts, None)?;
    let probe = train_opts.probe;
    progress(&format!(
        "{name}: batch {} objects, {} rays per view and {} anchors each, network {:?}; entry \
         capacity {}",
        train_opts.batch,
        probe.rays_per_view,
        probe.anchors,
        train_opts.net,
        trainer.capacity()
    ));
    let size = train_opts.net.net.image;
    time_training(
        ctx,
        opts,
        &mut trainer,
        Shape {
            name,
            tile: probe.tile_size,
            timer_passes: 1024,
            views: train_opts.batch * crate::recon::dataset::VIEWS as u32,
            faces: 0,
            size,
        },
        progress,
    )
}

/// What a trainer's benchmark record says of its iteration besides the times.
struct Shape {
    name: &'static str,
    tile: u32,
    /// Room for this many passes in an iteration.
    timer_passes: u32,
    /// Renders (mesh) or probed views (field) an iteration.
    views: u32,
    /// Faces a render (0: no mesh).
    faces: u32,
    /// The images' side.
    size: u32,
}

/// One untimed iteration of `trainer`, then `opts.repeat` timed ones ([`time_iterations`]):
/// the `fit-iteration` record of `shape.name`, with the last iteration's binned entries.
fn time_training(
    ctx: &Context,
    opts: &BenchOptions,
    trainer: &mut Fitter<'_, impl Fit>,
    shape: Shape,
    progress: &mut impl FnMut(&str),
) -> Result<BenchRecord> {
    let name = shape.name;
    let mut it = 1u32;
    fit_iterations(trainer, &mut it, 1, None, progress, name)?;
    let timing = time_iterations(
        ctx,
        trainer,
        &mut it,
        opts.repeat,
        shape.timer_passes,
        false,
        progress,
        name,
    )?;
    let entries = trainer.last_entries();
    progress(&format!(
        "{name} fit-iteration: {entries} entries; {}",
        summary(&timing, opts.repeat)
    ));
    Ok(BenchRecord {
        scene: name.to_string(),
        method: Method::Tiled { tile: shape.tile },
        pass: "fit-iteration",
        gpu_ms: timing.gpu_ms,
        wall_ms: timing.wall_ms,
        pairs: 0,
        counts: None,
        device: ctx.info().name.clone(),
        driver: ctx.info().driver.clone(),
        repeats: opts.repeat,
        passes: timing.passes,
        views: shape.views,
        faces: shape.faces,
        width: shape.size,
        height: shape.size,
        rows: None,
        entries: Some(entries),
        identical_to_brute: None,
    })
}
