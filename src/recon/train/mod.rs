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
//! cheaper, and the generator is not trained). [`SilhouetteLoss`](crate::fit::SilhouetteLoss)
//! averages over all renders (SoftRas's mean; the one-view recipe takes it with weight 2); the
//! regularizers sum over the batch's meshes (one block-diagonal mesh of templates), so theirs are
//! taken with weight `λ / meshes`.
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

mod params;
mod schedule;
mod trainer;

pub use params::TrainedParams;
pub(crate) use schedule::Batches;
pub use schedule::schedule_entry;
pub use trainer::{ReconTrainer, ReconTraining, TrainLog, template};

use std::ops::Range;

use crate::error::{Error, Result};
use crate::fit::AdamOptions;
use crate::nn::{Activation, Conv2d, Layer, Linear};
use crate::raster::settings::{ColorMode, RasterSettings};

use super::dataset::{self, Dataset};

/// Views per object in the NMR data.
pub const VIEWS: u32 = super::dataset::VIEWS as u32;

/// View `v`'s azimuth in degrees: SoftRas's loader passes `-v · 15` to
/// `get_points_from_angles` ([`view_camera`](super::dataset::view_camera)).
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
/// generator's ([`MeshDecoder::outputs_per_object`](super::decode::MeshDecoder::outputs_per_object)
/// without a device).
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

    /// The silhouette loss's weight on [`SilhouetteLoss`](crate::fit::SilhouetteLoss)'s mean over
    /// all renders: SoftRas averages its four IoU losses (1); the one-view recipe sums its two.
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

/// Copies of each object the renderer sees (views a and b).
const COPIES: u32 = 2;
