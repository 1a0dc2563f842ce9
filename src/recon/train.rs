//! Training the reconstruction network through the soft rasterizer, SoftRas's recipe
//! (`examples/recon/train.py`, `models.py`), every iteration on the GPU:
//!
//! ```text
//! schedule rows ─[BatchGather]→ inputs, targets (alphas of views a, b), rotations
//! inputs ─[Sequential]→ outputs ─[MeshDecoder]→ meshes, 2 copies each (turned per view)
//! outputs, inputs ─[MeshDecoder colour generator]→ vertex colours of the copies, sampled
//!   from each input image (with a colour loss)
//! copies ─(guarded soft rasterizer, one camera)→ images ─[SilhouetteLoss, ImageMse]→ L, d_image
//! d_image ─(render backward)→ d_copies, d_colours;  meshes ─[Regularizers]→ L_lap, L_flat
//! d_copies, d_colours, d_meshes ─[MeshDecoder backward]→ d_outputs ─[Sequential backward]
//!   → d_params ─[Adam]
//! ```
//!
//! **Recipes** ([`Recipe`]). SoftRas's (the default): each of the batch's B objects gives two
//! inputs, its views a and b, so the network sees 2B images; each prediction is rendered from
//! both views (SoftRas's `predict_multiview`: 4B renders), and
//! `L = mean of the four IoU losses + λ_col L_col + λ_lap mean L_lap + λ_flat mean L_flat`
//! over the 2B predicted meshes (`multiview_iou_loss`), with `dist_eps` 1e-10 and σ stepped
//! with the learning rate (`adjust_sigma`). The one-view recipe encodes view a only and sums
//! its two IoU losses (`L_iou(a) + L_iou(b)`), so its regularizers weigh half as much
//! relative to the silhouettes. `L_iou` is SoftRas's `iou_loss` over its renders and `L_col`
//! the mean squared error of the rendered RGBA against the views' (unlit vertex colours from
//! the colour generator, [`super::colors`]: each vertex learns which samples of its input image
//! to take, shading included; with `λ_col = 0` the copies render as silhouettes only, which is
//! cheaper, and the generator is not trained). [`SilhouetteLoss`]
//! averages over all renders (SoftRas's mean; the one-view recipe takes it with weight 2); the
//! regularizers sum over the batch's meshes (one block-diagonal mesh of templates), so theirs
//! are taken with weight `λ / meshes`.
//!
//! **Batches** come from a schedule computed from the seed and the iteration number alone
//! ([`schedule_entry`]): SoftRas's sampler (a class uniformly, an object of it uniformly, two
//! views uniformly; in SoftRas's recipe each row is followed by its views swapped), so a run
//! resumed at iteration `i` sees what an uninterrupted one saw.
//!
//! **k iterations per submission**: [`ReconTrainer::run`] records iterations `first ..= last`
//! into one command buffer (the schedule rows uploaded before it, nothing read back between
//! iterations); the binning is guarded ([`crate::gpu::gate`]), and an iteration that outgrows
//! the entry capacity stops the rest, which grow the capacity and run again.

use std::ops::Range;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::fit::driver::{Fit, Fitter};
use crate::fit::{Adam, AdamOptions, ImageMse, Regularizers, SilhouetteLoss};
use crate::gpu::GradOut;
use crate::gpu::gate::IterationGate;
use crate::gpu::{Buffer, Context, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::nn::{Activation, Conv2d, Layer, Linear, Sequential};
use crate::raster::backward::GradBuffers;
use crate::raster::gpu::{GpuScene, GuardedBins, Renderer};
use crate::raster::settings::{ColorMode, RasterSettings};
use crate::rng::SplitMix64;

use super::batch::{BatchBuffers, BatchGather, BatchShape};
use super::decode::{MeshDecoder, view_rotation};

use super::dataset::{self, Dataset, view_camera};

/// Views per object in the NMR data.
pub const VIEWS: u32 = super::dataset::VIEWS as u32;

/// View `v`'s azimuth in degrees: SoftRas's loader passes `-v · 15` to
/// `get_points_from_angles` ([`view_camera`]).
pub fn view_azimuth(view: u32) -> f64 {
    -super::dataset::AZIMUTH_STEP * f64::from(view)
}

/// The network's shape: SoftRas's encoder (three strided 5×5 convolutions, two fully connected
/// layers) and decoder (two fully connected layers to the mesh head), narrower by default so
/// that it trains on a CPU. SoftRas's batch norm is left out: with the small batches a CPU can
/// afford its statistics are noise, and it would make the forward depend on the batch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetShape {
    /// Square input images, a multiple of 8 (SoftRas: 64).
    pub image: u32,
    /// The three convolutions' output channels (SoftRas: 64, 128, 256).
    pub channels: [u32; 3],
    /// The latent code's width (SoftRas: 512, after a 1024-wide layer).
    pub latent: u32,
    /// The decoder's hidden width (SoftRas: 1024 then 2048).
    pub hidden: u32,
}

impl Default for NetShape {
    fn default() -> Self {
        Self {
            image: 64,
            channels: [16, 32, 64],
            latent: 256,
            hidden: 512,
        }
    }
}

impl NetShape {
    /// The layers, for a mesh head of `outputs` values per object: conv 4→c0, c0→c1, c1→c2
    /// (5×5, stride 2, padding 2, ReLU), then fully connected to the latent (ReLU), latent
    /// (ReLU), hidden (ReLU) and the head (identity).
    pub fn layers(&self, outputs: u64) -> Result<Vec<Layer>> {
        if self.image == 0 || self.image % 8 != 0 || self.channels.contains(&0) {
            return Err(Error::Input(format!(
                "network {self:?}: the image side must be a positive multiple of 8 and every \
                 width positive"
            )));
        }
        let outputs = u32::try_from(outputs)
            .map_err(|_| Error::Input(format!("a mesh head of {outputs} outputs")))?;
        let mut layers = Vec::new();
        let (mut c, mut side) = (4, self.image);
        for &out in &self.channels {
            layers.push(Layer::Conv2d(Conv2d {
                in_channels: c,
                out_channels: out,
                kernel: 5,
                stride: 2,
                padding: 2,
                in_h: side,
                in_w: side,
                activation: Activation::Relu,
            }));
            c = out;
            side /= 2;
        }
        let fc = |i: u32, o: u32, activation| {
            Layer::Linear(Linear {
                in_features: i,
                out_features: o,
                activation,
            })
        };
        layers.push(fc(c * side * side, self.latent, Activation::Relu));
        layers.push(fc(self.latent, self.latent, Activation::Relu));
        layers.push(fc(self.latent, self.hidden, Activation::Relu));
        layers.push(fc(self.hidden, outputs, Activation::Identity));
        for l in &layers {
            l.validate()?;
        }
        Ok(layers)
    }
}

/// Outputs per image of a network of `net`'s shape: the mesh head's `3 V + 3` and the colour
/// generator's ([`MeshDecoder::outputs_per_object`] without a device).
pub fn head_outputs(net: &NetShape) -> u64 {
    let v = template().vertex_count() as u32;
    3 * u64::from(v) + 3 + super::colors::outputs_per_object(v, net.image)
}

/// Parameters of a network of `net`'s shape with the reconstruction's mesh head and colour
/// generator.
pub fn param_count(net: &NetShape) -> Result<u64> {
    Ok(crate::nn::param_offsets(&net.layers(head_outputs(net))?).1)
}

/// How a batch's objects are seen and scored. Both render every prediction from its object's
/// two sampled views a and b and score the renders against those views' silhouettes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Recipe {
    /// SoftRas's (`examples/recon`): both views of an object are inputs, each prediction is
    /// rendered from both views (four renders per object), the silhouette loss is the mean of
    /// the four IoU losses, and the regularizers are the mean over the 2B predicted meshes.
    /// The renderer's `dist_eps` is SoftRas's 1e-10, and σ steps with the learning rate
    /// (SoftRas's `adjust_sigma`).
    #[default]
    SoftRas,
    /// View a only is the input (two renders per object), the silhouette loss is the sum of the
    /// two IoU losses, and the renderer keeps its defaults.
    OneView,
}

impl Recipe {
    /// Inputs (and predictions) per object of a batch.
    pub fn inputs_per_object(self) -> u32 {
        match self {
            Recipe::SoftRas => 2,
            Recipe::OneView => 1,
        }
    }

    /// The silhouette loss's weight on [`SilhouetteLoss`]'s mean over all renders: SoftRas
    /// averages its four IoU losses (1); the one-view recipe sums its two.
    fn silhouette_weight(self) -> f32 {
        match self {
            Recipe::SoftRas => 1.0,
            Recipe::OneView => COPIES as f32,
        }
    }

    /// The number a checkpoint stores for the recipe.
    pub fn code(self) -> f64 {
        match self {
            Recipe::SoftRas => 1.0,
            Recipe::OneView => 2.0,
        }
    }
}

/// What training needs besides the data.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainOptions {
    /// The network.
    pub net: NetShape,
    /// How objects are seen and scored.
    pub recipe: Recipe,
    /// Objects per batch (SoftRas: 64); the network sees
    /// [`Recipe::inputs_per_object`] times as many images.
    pub batch: u32,
    /// Adam (SoftRas: lr 1e-4, β = (0.9, 0.999)).
    pub adam: AdamOptions,
    /// The learning rate's step, if any (SoftRas's `step` method: × 0.3 from iteration
    /// 150 000 on).
    pub lr_step: Option<LrStep>,
    /// λ of the Laplacian regularizer (SoftRas: 5e-3), on the mean over predicted meshes.
    pub laplacian: f32,
    /// λ of the flatten regularizer (SoftRas: 5e-4).
    pub flatten: f32,
    /// λ of the colour loss (0: silhouettes only).
    pub color: f32,
    /// The renderer's σ (SoftRas: 1e-4); SoftRas's recipe multiplies it by the learning
    /// rate's step factor from the step on.
    pub sigma: f64,
    /// Tile side of the guarded binning.
    pub tile: u32,
    /// Seeds the parameters and the schedule.
    pub seed: u64,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            net: NetShape::default(),
            recipe: Recipe::SoftRas,
            batch: 64,
            adam: AdamOptions {
                lr: 1e-4,
                ..AdamOptions::default()
            },
            lr_step: None,
            laplacian: 5e-3,
            flatten: 5e-4,
            color: 1.0,
            sigma: 1e-4,
            tile: 16,
            seed: 1,
        }
    }
}

/// A step in the learning rate: iterations `at` and later run at `factor` × the base rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LrStep {
    /// The first iteration at the lower rate (from 1).
    pub at: u32,
    /// The rate's multiplier from then on.
    pub factor: f64,
}

impl TrainOptions {
    /// The learning rate of iteration `it` (from 1).
    pub fn lr_at(&self, it: u32) -> f64 {
        match self.lr_step {
            Some(s) if it >= s.at => self.adam.lr * s.factor,
            _ => self.adam.lr,
        }
    }

    /// The renderer's σ at iteration `it` (from 1): stepped with the learning rate in
    /// SoftRas's recipe.
    pub fn sigma_at(&self, it: u32) -> f64 {
        match (self.recipe, self.lr_step) {
            (Recipe::SoftRas, Some(s)) if it >= s.at => self.sigma * s.factor,
            _ => self.sigma,
        }
    }

    /// Images the network sees per iteration (its batch).
    pub fn inputs(&self) -> u32 {
        self.batch.saturating_mul(self.recipe.inputs_per_object())
    }

    /// The renderer's settings: the image size, the options' σ, vertex colours, and SoftRas's
    /// `dist_eps` in its recipe.
    pub fn raster_settings(&self) -> RasterSettings {
        let defaults = RasterSettings::default();
        RasterSettings {
            width: self.net.image,
            height: self.net.image,
            sigma: self.sigma,
            color_mode: ColorMode::Vertex,
            dist_eps: match self.recipe {
                Recipe::SoftRas => 1e-10,
                Recipe::OneView => defaults.dist_eps,
            },
            ..defaults
        }
    }
}

/// Training images in the NMR layout: uint8 RGBA `[object][view][channel][row][column]`, the
/// objects grouped by class.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainImages {
    /// The bytes.
    pub images: Vec<u8>,
    /// Each class's name and its objects' range.
    pub classes: Vec<(String, Range<u32>)>,
    /// Square image side.
    pub size: u32,
}

impl TrainImages {
    /// The train split as the trainer takes it (each class's images freed once copied: the
    /// default data are 1.2 GB).
    pub fn from_dataset(data: Dataset) -> TrainImages {
        let mut images = Vec::with_capacity(data.classes.iter().map(|c| c.images.len()).sum());
        let mut classes = Vec::new();
        let mut start = 0u32;
        for c in data.classes {
            images.extend_from_slice(&c.images);
            let end = start + c.count as u32;
            classes.push((c.class_id, start..end));
            start = end;
        }
        TrainImages {
            images,
            classes,
            size: dataset::IMAGE_SIZE as u32,
        }
    }

    /// Objects in all classes.
    pub fn objects(&self) -> u32 {
        self.classes.iter().map(|c| c.1.end).max().unwrap_or(0)
    }

    /// [`Error::Input`] unless the bytes hold every class's objects' views and no class is
    /// empty.
    pub fn validate(&self) -> Result<()> {
        let per = u64::from(VIEWS) * 4 * u64::from(self.size) * u64::from(self.size);
        if self.classes.is_empty() || self.classes.iter().any(|c| c.1.is_empty()) {
            return Err(Error::Input("training data with an empty class".into()));
        }
        if self.images.len() as u64 != per * u64::from(self.objects()) {
            return Err(Error::Input(format!(
                "{} image bytes for {} objects of {VIEWS} views of {}²",
                self.images.len(),
                self.objects(),
                self.size
            )));
        }
        Ok(())
    }
}

/// SplitMix64's output for one counter value: the schedule is a stateless function of the
/// seed and the position, so a resumed run needs no generator state.
fn mix(z: u64) -> u64 {
    SplitMix64(z).next()
}

/// Uniform in `0..n` from a 64-bit word (Lemire's multiply-shift; the bias is below 2^-32).
fn below(word: u64, n: u32) -> u32 {
    (((word >> 32) * u64::from(n)) >> 32) as u32
}

/// Batch slot `slot` of iteration `iteration`: `(object, view a, view b, 0)`, SoftRas's
/// sampler (a class uniformly, an object of it uniformly, two views uniformly), from the seed
/// and the position alone.
pub fn schedule_entry(
    seed: u64,
    iteration: u32,
    slot: u32,
    classes: &[(String, Range<u32>)],
) -> [u32; 4] {
    let key = mix(seed ^ mix((u64::from(iteration) << 32) | u64::from(slot)));
    let class = &classes[below(mix(key ^ 1), classes.len() as u32) as usize].1;
    let object = class.start + below(mix(key ^ 2), class.end - class.start);
    [
        object,
        below(mix(key ^ 3), VIEWS),
        below(mix(key ^ 4), VIEWS),
        0,
    ]
}

/// Host bytes staged for one submission: written to host-visible memory and copied to a device
/// buffer at the submission's start (no submission of their own); both grow as submissions
/// need. The trainers stage their schedule rows and the views those rows name through it.
pub(crate) struct Staged {
    name: &'static str,
    device: Buffer,
    upload: Buffer,
    /// Bytes staged for the next copy.
    staged: u64,
}

impl Staged {
    /// Room for `bytes` to start with.
    pub(crate) fn new(ctx: &Context, name: &'static str, bytes: u64) -> Result<Self> {
        let bytes = bytes.max(4);
        Ok(Self {
            name,
            device: ctx.create_buffer(name, bytes, MemoryKind::Device)?,
            upload: ctx.create_buffer(name, bytes, MemoryKind::Upload)?,
            staged: 0,
        })
    }

    /// Stages `bytes` for the next [`Staged::record_copy`].
    pub(crate) fn stage(&mut self, ctx: &Context, bytes: &[u8]) -> Result<()> {
        let size = bytes.len() as u64;
        if size > self.device.size() {
            self.device = ctx.create_buffer(self.name, size, MemoryKind::Device)?;
            self.upload = ctx.create_buffer(self.name, size, MemoryKind::Upload)?;
        }
        self.upload
            .mapped_mut()
            .ok_or_else(|| Error::Limit("upload memory is not host-mapped".into()))?[..bytes.len()]
            .copy_from_slice(bytes);
        self.staged = size;
        Ok(())
    }

    /// Records the copy of the staged bytes to the device buffer.
    pub(crate) fn record_copy(&self, rec: &mut Recorder<'_>) {
        rec.copy(&self.upload, 0, &self.device, 0, self.staged);
    }

    /// The device buffer (what the batch gather reads).
    pub(crate) fn buffer(&self) -> &Buffer {
        &self.device
    }
}

/// The schedule's rows of `iterations` (`objects` per iteration, iteration-major); with
/// `both_views`, each object's row is followed by its views swapped (the second view as an
/// input too).
fn schedule_rows(
    seed: u64,
    classes: &[(String, Range<u32>)],
    objects: u32,
    both_views: bool,
    iterations: std::ops::RangeInclusive<u32>,
) -> Vec<[u32; 4]> {
    iterations
        .flat_map(|it| (0..objects).map(move |s| (it, s)))
        .map(|(it, s)| schedule_entry(seed, it, s, classes))
        .flat_map(|[o, a, b, _]| {
            let swapped = both_views.then_some([o, b, a, 0]);
            std::iter::once([o, a, b, 0]).chain(swapped)
        })
        .collect()
}

/// The losses of the last iteration a submission ran.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainLog {
    /// The iteration (from 1).
    pub iteration: u32,
    /// The silhouette loss: the mean of the four IoU losses (SoftRas's recipe) or
    /// `L_iou(a) + L_iou(b)` (one view).
    pub silhouette: f32,
    /// Mean Laplacian loss over the batch's predicted meshes.
    pub laplacian: f32,
    /// Mean flatten loss over the batch's predicted meshes.
    pub flatten: f32,
    /// The colour loss (0 when its λ is 0).
    pub color: f32,
    /// The weighted total.
    pub total: f32,
}

/// The reconstruction's template: a 642-vertex icosphere of radius 0.5 turned off the axes
/// ([`crate::fit::mesh_fit::icosphere_template`]): the topology of SoftRas's
/// `sphere_642.obj`, whose coordinates that are exactly 0 would stay 0 forever under the
/// sigmoid parameterization (SoftRas's template then keeps them at the centroid).
pub fn template() -> Mesh {
    crate::fit::mesh_fit::icosphere_template()
}

/// Training on the GPU: the network, its optimizer, the decoder, the batch scene and the
/// losses ([`ReconTrainer::run`]).
pub struct ReconTraining<'c> {
    ctx: &'c Context,
    opts: TrainOptions,
    net: Sequential,
    trained: TrainedParams,
    decoder: MeshDecoder,
    d_outputs: Buffer,
    partials: Buffer,
    batches: Batches<'c>,
    /// Zeros standing for dL/d(colours) when the colour loss is off.
    zero_colors: Buffer,
    /// The colour generator's scratch: the inputs' pooled cells and palettes.
    pooled: Buffer,
    palette: Buffer,
    meshes: Buffer,
    d_meshes: Buffer,
    renderer: Renderer,
    scene: GpuScene,
    grads: GradBuffers,
    /// The guarded forward's bins, beside the scene.
    bins: GuardedBins,
    sil: SilhouetteLoss,
    mse: ImageMse,
    regs: Regularizers,
    capacity: u64,
    max_capacity: u64,
}

/// The reconstruction network's training, ready to run iterations ([`Fitter::run`]).
pub type ReconTrainer<'c> = Fitter<'c, ReconTraining<'c>>;

/// A trainer's batches on the GPU: the training images (borrowed, on the host), the schedule's
/// rows staged per submission, and each iteration's gathered input, targets, view rotations and
/// target images. Both trainers use it.
pub(crate) struct Batches<'d> {
    classes: Vec<(String, Range<u32>)>,
    seed: u64,
    /// Objects per batch.
    objects: u32,
    both_views: bool,
    shape: BatchShape,
    gather: BatchGather,
    /// The training images (the NMR layout, on the host, borrowed: the views a submission's
    /// rows name are staged for it, so the dataset may be larger than a storage buffer).
    images: &'d [u8],
    views: Staged,
    view_table: Buffer,
    schedule: Staged,
    pub(crate) input: Buffer,
    pub(crate) targets: Buffer,
    pub(crate) target_images: Buffer,
    pub(crate) rotations: Buffer,
}

impl<'d> Batches<'d> {
    /// `data` uploaded, for batches of `objects` objects drawn from `seed`, each seen from its
    /// view a or, with `both_views`, from a and from b (two inputs).
    pub(crate) fn new(
        ctx: &Context,
        data: &'d TrainImages,
        objects: u32,
        both_views: bool,
        seed: u64,
    ) -> Result<Self> {
        let batch = objects.saturating_mul(1 + u32::from(both_views));
        let b = u64::from(batch);
        let px = u64::from(data.size) * u64::from(data.size);
        let device = |name: &str, floats: u64| {
            ctx.create_buffer(name, 4 * floats.max(1), MemoryKind::Device)
        };
        let table: Vec<[f32; 2]> = (0..VIEWS).map(|v| view_rotation(view_azimuth(v))).collect();
        Ok(Self {
            classes: data.classes.clone(),
            seed,
            objects,
            both_views,
            shape: BatchShape {
                batch,
                pixels: data.size * data.size,
                views: VIEWS,
            },
            gather: BatchGather::new(ctx)?,
            images: &data.images,
            views: Staged::new(ctx, "recon staged views", 2 * 4 * b * px)?,
            view_table: ctx.upload_buffer("recon view rotations", &table)?,
            schedule: Staged::new(ctx, "recon schedule", 16 * b)?,
            input: device("recon input", 4 * b * px)?,
            targets: device("recon targets", u64::from(COPIES) * b * px)?,
            target_images: device("recon target images", 4 * u64::from(COPIES) * b * px)?,
            rotations: device("recon rotations", 2 * u64::from(COPIES) * b)?,
        })
    }

    /// Stages the rows of iterations `first ..= last` and returns them (one per input, in the
    /// iteration's batch order).
    /// The rows' two views each are staged beside them ([`super::batch::stage_views`]); a
    /// submission whose views exceed a storage buffer is [`Error::DeviceLimit`].
    pub(crate) fn stage(&mut self, ctx: &Context, first: u32, last: u32) -> Result<Vec<[u32; 4]>> {
        let mut entries = schedule_rows(
            self.seed,
            &self.classes,
            self.objects,
            self.both_views,
            first..=last,
        );
        let views = super::batch::stage_views(ctx, self.images, self.shape, &mut entries)?;
        self.views.stage(ctx, bytemuck::cast_slice(&views))?;
        self.schedule.stage(ctx, bytemuck::cast_slice(&entries))?;
        Ok(entries)
    }

    /// Records the gather of schedule row `row` (the staged rows copied in before row 0's).
    pub(crate) fn record(&self, rec: &mut Recorder<'_>, row: u32) -> Result<()> {
        if row == 0 {
            self.schedule.record_copy(rec);
            self.views.record_copy(rec);
        }
        rec.pass("recon batch", |rec| {
            self.gather.record(
                rec,
                self.shape,
                row,
                BatchBuffers {
                    views: self.views.buffer().whole(),
                    schedule: self.schedule.buffer().whole(),
                    view_rotations: self.view_table.whole(),
                    input: self.input.whole(),
                    targets: self.targets.whole(),
                    rotations: self.rotations.whole(),
                    target_images: self.target_images.whole(),
                },
            )
        })
    }
}

/// A trainer's parameters, their gradient and Adam over them, in buffers that may pad between
/// packed ranges (the conditioned field keeps its field's part at a bindable offset): the values
/// as a model file holds them are the ranges, one after another.
pub struct TrainedParams {
    pub(crate) params: Buffer,
    pub(crate) d_params: Buffer,
    pub(crate) adam: Adam,
    /// `(offset, count)` in floats of each packed range, in order.
    ranges: Vec<(u64, u64)>,
}

impl TrainedParams {
    /// `padded` (the buffers' layout) uploaded, the gradient zeroed, Adam's moments reset.
    pub(crate) fn new(
        ctx: &Context,
        name: &str,
        padded: &[f32],
        ranges: Vec<(u64, u64)>,
        adam: AdamOptions,
    ) -> Result<Self> {
        let n = padded.len() as u64;
        let trained = Self {
            params: ctx.upload_buffer(&format!("{name} params"), padded)?,
            d_params: ctx.create_buffer(
                &format!("{name} d_params"),
                4 * n.max(1),
                MemoryKind::Device,
            )?,
            adam: Adam::new(ctx, n, adam)?,
            ranges,
        };
        ctx.submit_and_wait(|rec| {
            rec.fill(trained.d_params.whole(), 0);
            trained.adam.record_reset(rec);
            Ok(())
        })?;
        Ok(trained)
    }

    /// Packed values in all.
    fn len(&self) -> usize {
        self.ranges.iter().map(|r| r.1 as usize).sum()
    }

    /// The packed values of one of the buffers.
    fn read(&self, ctx: &Context, buffer: &Buffer) -> Result<Vec<f32>> {
        let end = self.ranges.iter().map(|r| r.0 + r.1).max().unwrap_or(0);
        let all: Vec<f32> = ctx.read_buffer(buffer, 0, end as usize)?;
        Ok(self
            .ranges
            .iter()
            .flat_map(|&(at, n)| all[at as usize..(at + n) as usize].iter().copied())
            .collect())
    }

    /// Writes packed values into one of the buffers.
    fn write(&self, ctx: &Context, buffer: &Buffer, packed: &[f32]) -> Result<()> {
        if packed.len() != self.len() {
            return Err(Error::Input(format!(
                "{} values for a network of {}",
                packed.len(),
                self.len()
            )));
        }
        let mut from = 0;
        for &(at, n) in &self.ranges {
            ctx.write_buffer(buffer, 4 * at, &packed[from..from + n as usize])?;
            from += n as usize;
        }
        Ok(())
    }

    /// The parameters now (packed).
    pub fn read_params(&self, ctx: &Context) -> Result<Vec<f32>> {
        self.read(ctx, &self.params)
    }

    /// Replaces the parameters (packed, finite).
    pub fn write_params(&self, ctx: &Context, params: &[f32]) -> Result<()> {
        if let Some(i) = params.iter().position(|p| !p.is_finite()) {
            return Err(Error::Input(format!("parameter {i} is not finite")));
        }
        self.write(ctx, &self.params, params)
    }

    /// dL/d(params) of the last iteration run (packed).
    pub fn read_gradient(&self, ctx: &Context) -> Result<Vec<f32>> {
        self.read(ctx, &self.d_params)
    }

    /// Adam's moments now (first, second; packed).
    pub fn read_moments(&self, ctx: &Context) -> Result<(Vec<f32>, Vec<f32>)> {
        let (m, v) = self.adam.moments();
        Ok((self.read(ctx, m)?, self.read(ctx, v)?))
    }

    /// Sets Adam's moments (a resumed run; packed).
    pub fn write_moments(&self, ctx: &Context, m: &[f32], v: &[f32]) -> Result<()> {
        let (mb, vb) = self.adam.moments();
        self.write(ctx, mb, m)?;
        self.write(ctx, vb, v)
    }

    /// Records iteration `it`'s Adam step at learning rate `lr`.
    pub(crate) fn record_step(&self, rec: &mut Recorder<'_>, it: u32, lr: f64) -> Result<()> {
        rec.pass("adam", |rec| {
            self.adam
                .record_step_lr(rec, self.params.whole(), self.d_params.whole(), it, lr)
        })
    }
}

/// Copies of each object the renderer sees (views a and b).
const COPIES: u32 = 2;

impl<'c> Fitter<'c, ReconTraining<'c>> {
    /// Borrows the training images (each submission stages the views its batches name), builds
    /// the network with `params` (or an initialization from the seed), zeroes Adam's moments,
    /// and sizes the binning on the template.
    pub fn new(
        ctx: &'c Context,
        data: &'c TrainImages,
        opts: &TrainOptions,
        params: Option<&[f32]>,
    ) -> Result<Self> {
        data.validate()?;
        if data.size != opts.net.image {
            return Err(Error::Input(format!(
                "the data's images are {}² but the network takes {}²",
                data.size, opts.net.image
            )));
        }
        if opts.batch == 0 {
            return Err(Error::Input("a batch of 0 objects".into()));
        }
        if let Some(s) = opts.lr_step {
            if s.at == 0 || !(s.factor.is_finite() && s.factor >= 0.0) {
                return Err(Error::Input(format!(
                    "learning-rate step {s:?}: need an iteration from 1 and a factor >= 0"
                )));
            }
            if opts.recipe == Recipe::SoftRas && s.factor == 0.0 {
                return Err(Error::Input(
                    "a learning-rate step factor of 0 would step σ to 0 in SoftRas's recipe".into(),
                ));
            }
        }
        let t = template();
        let decoder = MeshDecoder::new(ctx, &t.positions, opts.net.image)?;
        let layers = opts.net.layers(decoder.outputs_per_object())?;
        // Per iteration: `inputs` images in, as many meshes, each rendered in COPIES views.
        let inputs = opts.inputs();
        let net = Sequential::new(ctx, &layers, inputs)?;
        let init;
        let params = match params {
            Some(p) => {
                if p.len() as u64 != net.param_count() {
                    return Err(Error::Input(format!(
                        "{} parameters for a network of {}",
                        p.len(),
                        net.param_count()
                    )));
                }
                p
            }
            None => {
                init = net.init(opts.seed);
                &init[..]
            }
        };
        let n = net.param_count();
        let b = u64::from(inputs);
        let v = u64::from(decoder.vertex_count());
        let device = |name: &str, floats: u64| {
            ctx.create_buffer(name, 4 * floats.max(1), MemoryKind::Device)
        };
        let trained = TrainedParams::new(ctx, "recon", params, vec![(0, n)], opts.adam)?;
        let renderer = Renderer::new(ctx)?;
        let copies = vec![t.clone(); (b * u64::from(COPIES)) as usize];
        let views: Vec<(usize, Camera)> = (0..copies.len()).map(|c| (c, view_camera(0))).collect();
        let settings = opts.raster_settings();
        let mut scene =
            renderer.prepare_batch(ctx, &copies, &views, &Lighting::unlit(), &settings)?;
        scene.set_silhouette_only(opts.color == 0.0);
        // The batch's meshes as one mesh of B disjoint templates, for the regularizers.
        let vc = t.vertex_count() as u32;
        let faces: Vec<[u32; 3]> = (0..inputs)
            .flat_map(|o| t.faces.iter().map(move |f| f.map(|i| i + o * vc)))
            .collect();
        let regs = Regularizers::new(ctx, &faces, (b * v) as usize)?;
        let max_capacity = crate::fit::max_entry_capacity(ctx, &renderer, &scene);
        let total = renderer.count_entries(ctx, &scene, opts.tile)?;
        // Predicted shapes wander from the sphere: room for 4× its entries to start with, or
        // as many as the device holds (the gate grows it as the shapes need).
        let capacity = crate::fit::with_headroom(
            ctx,
            "the reconstruction batch's binning",
            (4 * total).min(max_capacity.max(total)),
            max_capacity,
            HINT,
        )?;
        let alpha_only = opts.color == 0.0;
        let (bins, grads) =
            crate::fit::reserve_guarded(ctx, &renderer, &scene, opts.tile, capacity, alpha_only)?;
        let trainer = ReconTraining {
            ctx,
            opts: opts.clone(),
            batches: Batches::new(
                ctx,
                data,
                opts.batch,
                opts.recipe == Recipe::SoftRas,
                opts.seed,
            )?,
            trained,
            d_outputs: device("recon d_outputs", b * decoder.outputs_per_object())?,
            partials: decoder.create_partials(ctx, inputs)?,
            zero_colors: {
                let z = device("recon zero colour gradients", 3 * u64::from(COPIES) * b * v)?;
                ctx.submit_and_wait(|rec| {
                    rec.fill(z.whole(), 0);
                    Ok(())
                })?;
                z
            },
            pooled: device(
                "recon pooled cells",
                decoder.color_generator().pooled_floats(inputs),
            )?,
            palette: device(
                "recon palettes",
                decoder.color_generator().palette_floats(inputs),
            )?,
            meshes: device("recon meshes", 3 * b * v)?,
            d_meshes: device("recon d_meshes", 3 * b * v)?,
            sil: SilhouetteLoss::new(ctx, COPIES * inputs, opts.net.image, opts.net.image)?,
            mse: ImageMse::new(ctx, COPIES * inputs, opts.net.image, opts.net.image)?,
            regs,
            renderer,
            scene,
            grads,
            bins,
            decoder,
            net,
            capacity,
            max_capacity,
        };
        Fitter::from_fit(ctx, trainer)
    }
}

impl Fit for ReconTraining<'_> {
    const NAME: &'static str = "training";

    /// Stages the iterations' batches (their schedule rows).
    fn prepare(&mut self, ctx: &Context, first: u32, last: u32) -> Result<()> {
        self.batches.stage(ctx, first, last)?;
        Ok(())
    }

    /// Iteration `it` on the batch staged at row `row`: the network and the decoder, the
    /// guarded render of the batch's views, then gated on its count the silhouette (and
    /// colour) loss, the backward, the regularizers, the decoder's and the network's backward
    /// and the Adam step.
    fn record_iteration(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        row: u32,
    ) -> Result<()> {
        let sigma = self.opts.sigma_at(it);
        if sigma != self.scene.settings().sigma {
            let gamma = self.scene.settings().gamma;
            self.scene.set_blur(sigma, gamma)?;
        }
        self.batches.record(rec, row)?;
        let o = &self.opts;
        let inputs = o.inputs();
        rec.pass("recon network", |rec| {
            self.net.record_forward(
                rec,
                self.trained.params.whole(),
                self.batches.input.whole(),
                inputs,
            )
        })?;
        rec.pass("recon decoder", |rec| {
            self.decoder.record_forward(
                rec,
                inputs,
                COPIES,
                self.net.output().whole(),
                self.batches.rotations.whole(),
                self.meshes.whole(),
                self.scene.positions().whole(),
            )?;
            // Without a colour loss the colours are not rendered, but the generator's backward
            // (of zero gradients) still reads what its forward writes.
            self.decoder.record_colors(
                rec,
                inputs,
                COPIES,
                self.net.output().whole(),
                self.batches.input.whole(),
                self.pooled.whole(),
                self.palette.whole(),
                self.scene.colors().whole(),
            )
        })?;
        let scene = &self.scene;
        let g = &self.grads;
        self.renderer
            .record_forward_guarded(rec, scene, &self.bins, gate, it, |rec, binned| {
                let io = g.io();
                rec.pass("silhouette loss", |rec| {
                    self.sil.record(
                        rec,
                        scene.output().whole(),
                        self.batches.targets.whole(),
                        Some(GradOut::write(io.upstream).weighted(o.recipe.silhouette_weight())),
                    )?;
                    if o.color > 0.0 {
                        self.mse.record(
                            rec,
                            scene.output().whole(),
                            self.batches.target_images.whole(),
                            Some(GradOut::accumulate(io.upstream, o.color)),
                        )?;
                    }
                    Ok(())
                })?;
                self.renderer.grad_kernels().record(rec, &binned, g, &io)?;
                let per_object = 1.0 / inputs as f32;
                rec.pass("regularizers", |rec| {
                    self.regs.record_laplacian(
                        rec,
                        self.meshes.whole(),
                        Some(
                            GradOut::write(self.d_meshes.whole())
                                .weighted(o.laplacian * per_object),
                        ),
                    )?;
                    self.regs.record_flatten(
                        rec,
                        self.meshes.whole(),
                        Some(GradOut::accumulate(
                            self.d_meshes.whole(),
                            o.flatten * per_object,
                        )),
                    )
                })?;
                rec.pass("recon decoder backward", |rec| {
                    self.decoder.record_backward(
                        rec,
                        inputs,
                        COPIES,
                        self.net.output().whole(),
                        self.batches.rotations.whole(),
                        self.d_meshes.whole(),
                        io.positions,
                        self.d_outputs.whole(),
                        self.partials.whole(),
                    )?;
                    let d_colors = if o.color > 0.0 {
                        io.colors
                    } else {
                        self.zero_colors.whole()
                    };
                    self.decoder.record_colors_backward(
                        rec,
                        inputs,
                        COPIES,
                        self.net.output().whole(),
                        self.pooled.whole(),
                        self.palette.whole(),
                        d_colors,
                        self.d_outputs.whole(),
                    )
                })?;
                rec.pass("recon network backward", |rec| {
                    self.net.record_backward(
                        rec,
                        self.trained.params.whole(),
                        self.batches.input.whole(),
                        self.d_outputs.whole(),
                        self.trained.d_params.whole(),
                        None,
                        inputs,
                    )
                })?;
                self.trained.record_step(rec, it, o.lr_at(it))
            })
    }

    fn capacity(&self) -> u64 {
        self.capacity
    }

    fn grow(&mut self, ctx: &Context, total: u64) -> Result<()> {
        let capacity = crate::fit::with_headroom(
            ctx,
            "the reconstruction batch's binning",
            total,
            self.max_capacity,
            HINT,
        )?;
        (self.bins, self.grads) = crate::fit::reserve_guarded(
            ctx,
            &self.renderer,
            &self.scene,
            self.opts.tile,
            capacity,
            self.opts.color == 0.0,
        )?;
        self.capacity = capacity;
        Ok(())
    }
}

impl ReconTraining<'_> {
    /// The losses of the last iteration run (`iteration` names it in the log).
    pub fn read_log(&self, iteration: u32) -> Result<TrainLog> {
        let silhouette = self.opts.recipe.silhouette_weight() * self.sil.read_loss(self.ctx)?;
        let r = self.regs.read_losses(self.ctx)?;
        let per_object = 1.0 / self.opts.inputs() as f32;
        let (laplacian, flatten) = (r.laplacian * per_object, r.flatten * per_object);
        let color = if self.opts.color > 0.0 {
            self.mse.read_loss(self.ctx)?
        } else {
            0.0
        };
        Ok(TrainLog {
            iteration,
            silhouette,
            laplacian,
            flatten,
            color,
            total: silhouette
                + self.opts.color * color
                + self.opts.laplacian * laplacian
                + self.opts.flatten * flatten,
        })
    }

    /// The parameters, their gradient and Adam's moments.
    pub fn trained(&self) -> &TrainedParams {
        &self.trained
    }

    /// The options.
    pub fn options(&self) -> &TrainOptions {
        &self.opts
    }

    /// The network.
    pub fn net(&self) -> &Sequential {
        &self.net
    }

    /// Entries the binning holds now.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }
}

const HINT: &str = "use a smaller batch, larger tiles or a smaller σ";
