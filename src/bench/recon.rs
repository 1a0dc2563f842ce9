//! The reconstruction trainers' iterations (`softvk bench --scene train-recon`,
//! `--scene train-recon-field`): where a `softvk train-recon` iteration at its defaults spends
//! its time, pass by pass, for the mesh network and the conditioned field.

use super::iteration::{Shape, time_fit_iteration};
use super::{BenchOptions, BenchRecord};
use crate::error::Result;
use crate::gpu::Context;
use crate::raster::gpu::{Method, Renderer};
use crate::recon::dataset::{DatasetOptions, Split, render_shapes, split_shapes};
use crate::recon::field::{FieldReconTraining, FieldTrainOptions};
use crate::recon::train::{ReconTraining, TrainImages, TrainOptions, template};

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
    let mut trainer = ReconTraining::fitter(ctx, &data, &train_opts, None)?;
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
    let shape = Shape {
        name,
        method: Method::Tiled {
            tile: train_opts.tile,
        },
        views: 2 * inputs,
        faces: template().face_count() as u32,
        width: size,
        height: size,
        counts: None,
    };
    let mut it = 1u32;
    let timing = time_fit_iteration(ctx, opts, &mut trainer, &mut it, 160, false, progress, name)?;
    Ok(shape.record(
        ctx,
        "fit-iteration",
        timing,
        opts.repeat,
        trainer.last_entries(),
    ))
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
    let mut trainer = FieldReconTraining::fitter(ctx, &data, &train_opts, None)?;
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
    let shape = Shape {
        name,
        method: Method::Tiled {
            tile: probe.tile_size,
        },
        views: train_opts.batch * crate::recon::dataset::VIEWS as u32,
        faces: 0,
        width: size,
        height: size,
        counts: None,
    };
    let mut it = 1u32;
    let timing = time_fit_iteration(
        ctx,
        opts,
        &mut trainer,
        &mut it,
        1024,
        false,
        progress,
        name,
    )?;
    Ok(shape.record(
        ctx,
        "fit-iteration",
        timing,
        opts.repeat,
        trainer.last_entries(),
    ))
}
