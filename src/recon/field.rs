//! Single-view reconstruction as a *conditioned implicit field* (Liu et al.,
//! "Learning to Infer Implicit Surfaces without 3D Supervision", NeurIPS 2019): the image
//! encoder of [`super::train`] predicts a code per object, an occupancy MLP
//! ([`crate::field::mlp`]) shared by every object turns (point, code) into φ, and the pair is
//! trained through sphere probing ([`crate::probe`]) against each object's silhouettes alone.
//!
//! **Conditioning.** The code is the bias of every hidden layer of the MLP: object o's field is
//! the shared MLP with hidden layer l's bias replaced by `code_o[l]` (`W` floats per layer).
//! That is exactly a latent vector concatenated to the input of every hidden layer (its
//! product with the concatenated columns of the weights is a per-object bias), with the
//! encoder's last linear layer playing those columns. So object o's field *is* an ordinary
//! MLP field ([`crate::field::Field`]) whose parameters are the shared ones with the code
//! copied in, and dL/dcode_o is that field's bias gradient: the field's kernels, backward and
//! twin serve unchanged, and conditioning costs copies. (The shared parameters' own hidden
//! biases are never read; their gradient is zeroed so Adam leaves them where they are.)
//!
//! **One iteration**, recorded into one command buffer with nothing read back:
//!
//! ```text
//! schedule row ─[BatchGather]→ input (view a of B objects) ─[Sequential]→ codes (B × L·W)
//! per slot o (object j): sampler_j(iteration) → rays, anchors;  prober_o: items, count; gate
//! gated: per slot o
//!     shared params, code_o ─(copies)→ field params
//!     φ = field(anchors) ─[prober_o forward, backward; weight 1/B]→ dL/dφ
//!     field backward → d_field[o]  (P floats)
//!   d_shared = Σ_o d_field[o] (fixed order); d_code[o] = d_field[o]'s hidden biases (copies)
//!   encoder backward(d_codes) → d_encoder;  Adam on [encoder | shared field]
//! ```
//!
//! `L = mean_o L_sil(o)` with `L_sil` the prober's (probing every one of the object's 24
//! views with `rays_per_view` rays, anchors drawn around the visual hull of its own
//! silhouettes). Every sum has a fixed order and the samplers draw from (seed, iteration), so a
//! run is the same bits however its iterations are split into submissions.
//!
//! **Parameters** of a [`FieldNet`] are one vector: the encoder's ([`crate::nn::Sequential`]'s
//! layout), then the field's ([`crate::field::mlp`]'s layout). On the GPU the field's part
//! starts at the device's binding alignment; files and the host API hold it packed.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::field::mcubes::{Isosurface, MarchingCubes};

use crate::field::{Cube, Field, FieldKind, SumChunks};
use crate::fit::AdamOptions;
use crate::fit::driver::{Fit, Fitter};
use crate::fit::field_fit::scaled_to_cube;
use crate::gpu::GradOut;
use crate::gpu::gate::IterationGate;
use crate::gpu::{Buffer, Context, MemoryKind, Recorder};
use crate::nn::Sequential;
use crate::probe::{GpuTargets, ProbeSettings, Prober, Sampler, Targets};

use super::dataset::view_camera;
pub use super::model::FieldNet;
use super::model::ReconModel;
use super::train::{Batches, LrStep, TrainImages, TrainedParams, VIEWS, schedule_entry};

/// The cube the conditioned field lives in: the dataset's objects fill `[−0.5, 0.5]³`, its
/// voxel centres reach ±0.5 ([`super::dataset::voxel_cube`]); a margin keeps the uniform anchors
/// around them.
pub fn field_cube() -> Cube {
    Cube {
        center: [0.0; 3],
        half: 0.55,
    }
}

/// Most objects per batch: every slot records its own probing (about 14 dispatches, and one
/// more per hidden layer of the MLP: up to about 46) into the iteration's one gated region, which
/// holds [`crate::gpu::gate::GATE_SLOTS`] (2 048).
pub const MAX_BATCH: u32 = 32;

/// What training a conditioned field needs besides the data.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldTrainOptions {
    /// The network.
    pub net: FieldNet,
    /// Objects per batch.
    pub batch: u32,
    /// Adam, on the encoder and the shared field alike.
    pub adam: AdamOptions,
    /// The learning rate's step, if any.
    pub lr_step: Option<LrStep>,
    /// Sphere probing, in world units of [`field_cube`] (its cube must be that cube); its seed
    /// is replaced by [`FieldTrainOptions::seed`].
    pub probe: ProbeSettings,
    /// Seeds the parameters, the schedule and the samplers.
    pub seed: u64,
}

impl Default for FieldTrainOptions {
    /// Batches of 16 (as `train-recon`'s), Adam at 1e-3, and per object and iteration 64 rays
    /// in each of the 24 views and 2 048 anchors of radius τ = 0.045 half-edges on 8-pixel
    /// tiles; no geometric regularizer.
    fn default() -> Self {
        Self {
            net: FieldNet::default(),
            batch: 16,
            adam: AdamOptions {
                lr: 1e-3,
                ..AdamOptions::default()
            },
            lr_step: None,
            probe: default_probe(),
            seed: 1,
        }
    }
}

/// The default probing of [`FieldTrainOptions`], scaled to [`field_cube`].
pub fn default_probe() -> ProbeSettings {
    scaled_to_cube(
        &ProbeSettings {
            rays_per_view: 64,
            anchors: 2048,
            tau: 0.045,
            tile_size: 8,
            hull_resolution: 32,
            geo_lambda: 0.0,
            ..ProbeSettings::default()
        },
        &field_cube(),
    )
}

impl FieldTrainOptions {
    /// The learning rate of iteration `it` (from 1).
    pub fn lr_at(&self, it: u32) -> f64 {
        match self.lr_step {
            Some(s) if it >= s.at => self.adam.lr * s.factor,
            _ => self.adam.lr,
        }
    }

    /// The probe settings the trainer uses (the options' seed in them).
    pub fn probe_settings(&self) -> ProbeSettings {
        ProbeSettings {
            seed: self.seed,
            ..self.probe
        }
    }

    /// [`Error::Input`] for a batch of 0 or over [`MAX_BATCH`], a bad step, Adam options, probe settings, a probe
    /// cube other than [`field_cube`] or a regularizer weight (not supported here).
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_BATCH).contains(&self.batch) {
            return Err(Error::Input(format!(
                "a conditioned field's batch of {} objects: 1 to {MAX_BATCH} (an iteration's \
                 gated dispatches must fit the gate)",
                self.batch
            )));
        }
        if let Some(s) = self.lr_step {
            if s.at == 0 || !(s.factor.is_finite() && s.factor >= 0.0) {
                return Err(Error::Input(format!(
                    "learning-rate step {s:?}: need an iteration from 1 and a factor >= 0"
                )));
            }
        }
        self.adam.validate()?;
        self.probe.validate()?;
        let cube = field_cube();
        if self.probe.cube_center != cube.center || self.probe.cube_half != cube.half {
            return Err(Error::Input(format!(
                "conditioned field: probing in the cube {:?} ± {}; the field lives in {:?} ± {}",
                self.probe.cube_center, self.probe.cube_half, cube.center, cube.half
            )));
        }
        if self.probe.geo_lambda != 0.0 {
            return Err(Error::Input(
                "conditioned field: the geometric regularizer is not supported (geo_lambda 0)"
                    .into(),
            ));
        }
        Ok(())
    }
}

/// Object `n`'s probing targets: its views' alpha at ≥ 128 as silhouettes, with the dataset's
/// cameras.
pub fn object_targets(data: &TrainImages, n: u32) -> Result<Targets> {
    let px = (data.size * data.size) as usize;
    let per = VIEWS as usize * 4 * px;
    let object = &data.images[n as usize * per..(n as usize + 1) * per];
    let masks = (0..VIEWS as usize)
        .flat_map(|v| object[(4 * v + 3) * px..(4 * v + 4) * px].iter())
        .map(|&a| if a >= 128 { 1.0 } else { 0.0 })
        .collect();
    let cameras: Vec<Camera> = (0..VIEWS as usize).map(view_camera).collect();
    Targets::new(&cameras, data.size, data.size, masks)
}

/// One training object's probing state: its silhouettes on the GPU and its sampler (visual hull
/// boundary, contour densities).
struct ObjectProbe {
    gpu: GpuTargets,
    sampler: Sampler,
}

/// The losses of the last iteration a submission ran.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldTrainLog {
    /// The iteration (from 1).
    pub iteration: u32,
    /// `mean_o L_sil(o)`.
    pub silhouette: f32,
}

/// Training a conditioned field on the GPU ([`FieldReconTrainer::run`]).
pub struct FieldReconTraining<'c> {
    ctx: &'c Context,
    opts: FieldTrainOptions,
    net: Sequential,
    field: Field,
    objects: Vec<ObjectProbe>,
    probers: Vec<Prober>,
    /// `[encoder | pad | field | pad]`: the field's part at `field_offset` floats.
    trained: TrainedParams,
    encoder_count: u64,
    field_count: u64,
    field_offset: u64,
    /// Floats per slot of `d_fields` (the field's count rounded to the alignment).
    field_stride: u64,
    d_fields: Buffer,
    d_codes: Buffer,
    phi: Buffer,
    d_phi: Buffer,
    losses: Buffer,
    sum: SumChunks,
    batches: Batches<'c>,
    /// The staged rows' objects (`batch` per row), for recording them.
    staged: Vec<u32>,
    capacity: u64,
}

/// The conditioned field's training, ready to run iterations ([`Fitter::run`]).
pub type FieldReconTrainer<'c> = Fitter<'c, FieldReconTraining<'c>>;

const HINT: &str = "use fewer anchors, larger tiles or a smaller τ";

impl<'c> FieldReconTraining<'c> {
    /// Uploads the training images, prepares every object's probing (its visual hull's
    /// boundary and contour densities, on the host), builds the network with `params`
    /// (packed, [`FieldNet::param_count`]) or the seeded init, and sizes the probers' entries
    /// from iteration 1's counts; on the driver (built by its own type, as
    /// [`ReconTraining::fitter`](crate::recon::train::ReconTraining::fitter) says why).
    pub fn fitter(
        ctx: &'c Context,
        data: &'c TrainImages,
        opts: &FieldTrainOptions,
        params: Option<&[f32]>,
    ) -> Result<FieldReconTrainer<'c>> {
        data.validate()?;
        opts.validate()?;
        if data.size != opts.net.net.image {
            return Err(Error::Input(format!(
                "the data's images are {}² but the network takes {}²",
                data.size, opts.net.net.image
            )));
        }
        let probe = opts.probe_settings();
        let net = Sequential::new(ctx, &opts.net.encoder_layers()?, opts.batch)?;
        let field = Field::new(
            ctx,
            FieldKind::Mlp {
                hidden_layers: opts.net.mlp.hidden_layers,
                width: opts.net.mlp.width,
                frequencies: opts.net.mlp.frequencies,
            },
            field_cube(),
            opts.seed,
        )?;
        let encoder_count = net.param_count();
        let field_count = field.param_count() as u64;
        let total = encoder_count + field_count;
        let init;
        let packed = match params {
            Some(p) if p.len() as u64 == total => p,
            Some(p) => {
                return Err(Error::Input(format!(
                    "{} parameters for a network of {total}",
                    p.len()
                )));
            }
            None => {
                init = opts.net.init(opts.seed)?;
                &init[..]
            }
        };
        let align = (ctx.info().buffer_alignment() / 4).max(1);
        let field_offset = encoder_count.next_multiple_of(align);
        let field_stride = field_count.next_multiple_of(align);
        let n = field_offset + field_stride;
        let b = u64::from(opts.batch);
        let device = |name: &str, floats: u64| {
            ctx.create_buffer(name, 4 * floats.max(1), MemoryKind::Device)
        };
        let mut objects = Vec::with_capacity(data.objects() as usize);
        for o in 0..data.objects() {
            let targets = object_targets(data, o)?;
            let gpu = GpuTargets::new(ctx, &targets)?;
            let sampler = Sampler::new(ctx, &targets, &gpu, &probe)?;
            objects.push(ObjectProbe { gpu, sampler });
        }
        let mut probers = (0..opts.batch)
            .map(|_| Prober::new(ctx, &objects[0].gpu, &probe))
            .collect::<Result<Vec<_>>>()?;
        // Iteration 1's counts size the entry buffers (all slots alike), with headroom.
        let first: Vec<u32> = (0..opts.batch)
            .map(|s| schedule_entry(opts.seed, 1, s, &data.classes)[0])
            .collect();
        ctx.submit_and_wait(|rec| {
            for (prober, &j) in probers.iter().zip(&first) {
                let o = &objects[j as usize];
                o.sampler.record(rec, &o.gpu, 1)?;
                prober.record_count(rec, &o.gpu, o.sampler.anchors().whole())?;
            }
            Ok(())
        })?;
        let mut counted = 0u64;
        for prober in &probers {
            let total = ctx.read_buffer::<u32>(prober.total_buffer().buffer, 0, 1)?[0];
            counted = counted.max(u64::from(total));
        }
        let capacity = capacity_for(ctx, counted)?;
        for p in &mut probers {
            p.reserve_guarded(ctx, capacity)?;
        }
        let anchors = u64::from(probe.anchors);
        let mut padded = vec![0f32; n as usize];
        padded[..encoder_count as usize].copy_from_slice(&packed[..encoder_count as usize]);
        padded[field_offset as usize..(field_offset + field_count) as usize]
            .copy_from_slice(&packed[encoder_count as usize..]);
        let trainer = FieldReconTraining {
            ctx,
            opts: opts.clone(),
            trained: TrainedParams::new(
                ctx,
                "recon field",
                &padded,
                vec![(0, encoder_count), (field_offset, field_count)],
                opts.adam,
            )?,
            encoder_count,
            field_count,
            field_offset,
            field_stride,
            d_fields: device("recon field per-object gradients", b * field_stride)?,
            d_codes: device("recon field d_codes", b * opts.net.code_len())?,
            phi: device("recon field phi", anchors)?,
            d_phi: device("recon field d_phi", anchors)?,
            losses: device("recon field losses", b)?,
            sum: SumChunks::new(ctx)?,
            batches: Batches::new(ctx, data, opts.batch, false, opts.seed)?,
            staged: Vec::new(),
            capacity,
            net,
            field,
            objects,
            probers,
        };
        ctx.submit_and_wait(|rec| {
            // The padding of the per-object gradients stays zero (the parameters' gradient is
            // zeroed with it by TrainedParams).
            rec.fill(trainer.d_fields.whole(), 0);
            Ok(())
        })?;
        Fitter::from_fit(ctx, trainer)
    }
}

impl Fit for FieldReconTraining<'_> {
    const NAME: &'static str = "training";

    /// Stages the iterations' batches (their schedule rows) and keeps each row's objects.
    fn prepare(&mut self, ctx: &Context, first: u32, last: u32) -> Result<()> {
        let entries = self.batches.stage(ctx, first, last)?;
        self.staged = entries.iter().map(|e| e[0]).collect();
        Ok(())
    }

    /// Iteration `it` on the batch staged at row `row`: the encoder's codes; per object its
    /// anchors sampled and probed, the count gated; then the conditioned field's loss and
    /// gradient per object, the encoder's backward and the Adam step.
    fn record_iteration(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        row: u32,
    ) -> Result<()> {
        let b = self.opts.batch as usize;
        let objects = &self.staged[row as usize * b..(row as usize + 1) * b];
        let o = &self.opts;
        let b = o.batch;
        let f4 = |floats: u64| 4 * floats;
        let encoder = self.trained.params.range(0, f4(self.encoder_count));
        let d_encoder = self.trained.d_params.range(0, f4(self.encoder_count));
        self.batches.record(rec, row)?;
        rec.pass("recon encoder", |rec| {
            self.net
                .record_forward(rec, encoder, self.batches.input.whole(), b)
        })?;
        for (prober, &j) in self.probers.iter().zip(objects) {
            let obj = &self.objects[j as usize];
            rec.pass("sample", |rec| obj.sampler.record(rec, &obj.gpu, it))?;
            rec.pass("probe count", |rec| {
                prober.record_count(rec, &obj.gpu, obj.sampler.anchors().whole())
            })?;
            gate.record_check(rec, prober.total_buffer(), it, self.capacity)?;
        }
        let na = self.opts.probe.anchors;
        let codes = self.opts.net.code_len();
        let width = u64::from(self.opts.net.mlp.width);
        let ranges = self.opts.net.code_ranges();
        gate.record_gated(rec, |rec| {
            for (s, (prober, &j)) in self.probers.iter().zip(objects).enumerate() {
                let s = s as u64;
                let obj = &self.objects[j as usize];
                let anchors = obj.sampler.anchors().whole();
                let rays = obj.sampler.rays().whole();
                rec.copy(
                    &self.trained.params,
                    f4(self.field_offset),
                    self.field.params(),
                    0,
                    f4(self.field_count),
                );
                for (l, r) in ranges.iter().enumerate() {
                    rec.copy(
                        self.net.output(),
                        f4(s * codes + l as u64 * width),
                        self.field.params(),
                        f4(r.start as u64),
                        f4(width),
                    );
                }
                rec.pass("field eval", |rec| {
                    self.field.record_eval(rec, anchors, na, self.phi.whole())
                })?;
                rec.pass("probe forward", |rec| {
                    prober.record_forward(rec, &obj.gpu, anchors, self.phi.whole(), rays)
                })?;
                rec.pass("probe backward", |rec| {
                    prober.record_backward(
                        rec,
                        &obj.gpu,
                        anchors,
                        self.phi.whole(),
                        rays,
                        GradOut::write(self.d_phi.whole()).weighted(1.0 / b as f32),
                    )
                })?;
                let d_field = self
                    .d_fields
                    .range(f4(s * self.field_stride), f4(self.field_count));
                rec.pass("field backward", |rec| {
                    self.field
                        .record_backward(rec, anchors, na, self.d_phi.whole(), d_field)
                })?;
                rec.copy(prober.loss_buffer(), 0, &self.losses, f4(s), 4);
                for (l, r) in ranges.iter().enumerate() {
                    rec.copy(
                        &self.d_fields,
                        f4(s * self.field_stride + r.start as u64),
                        &self.d_codes,
                        f4(s * codes + l as u64 * width),
                        f4(width),
                    );
                }
            }
            let d_shared = self
                .trained
                .d_params
                .range(f4(self.field_offset), f4(self.field_stride));
            rec.pass("field gradient sum", |rec| {
                self.sum.record(
                    rec,
                    self.d_fields.range(0, f4(u64::from(b) * self.field_stride)),
                    d_shared,
                    self.field_stride as u32,
                    b,
                    false,
                )
            })?;
            // The shared hidden biases are never read (the codes replace them).
            for r in &ranges {
                rec.fill(
                    self.trained
                        .d_params
                        .range(f4(self.field_offset + r.start as u64), f4(r.len() as u64)),
                    0,
                );
            }
            rec.pass("recon encoder backward", |rec| {
                self.net.record_backward(
                    rec,
                    encoder,
                    self.batches.input.whole(),
                    self.d_codes.whole(),
                    d_encoder,
                    None,
                    b,
                )
            })?;
            self.trained.record_step(rec, it, o.lr_at(it))
        })
    }

    fn capacity(&self) -> u64 {
        self.capacity
    }

    fn grow(&mut self, ctx: &Context, total: u64) -> Result<()> {
        let capacity = capacity_for(ctx, total)?;
        for p in &mut self.probers {
            p.reserve_guarded(ctx, capacity)?;
        }
        self.capacity = capacity;
        Ok(())
    }
}

impl FieldReconTraining<'_> {
    /// The losses of the last iteration run (`iteration` names it in the log).
    pub fn read_log(&self, iteration: u32) -> Result<FieldTrainLog> {
        let l: Vec<f32> = self
            .ctx
            .read_buffer(&self.losses, 0, self.opts.batch as usize)?;
        Ok(FieldTrainLog {
            iteration,
            silhouette: l.iter().sum::<f32>() / l.len() as f32,
        })
    }

    /// The parameters (packed `[encoder | field]`), their gradient and Adam's moments.
    pub fn trained(&self) -> &TrainedParams {
        &self.trained
    }

    /// Entries each prober holds now.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// The options.
    pub fn options(&self) -> &FieldTrainOptions {
        &self.opts
    }
}

/// A prober's entry capacity for a count of `total`.
fn capacity_for(ctx: &Context, total: u64) -> Result<u64> {
    crate::fit::with_headroom(
        ctx,
        "the conditioned field's sphere probing",
        total,
        crate::primitives::binning::max_entries(ctx),
        HINT,
    )
}

/// Reconstruction with a conditioned-field model on the GPU: the encoder's forward for a batch
/// of images gives their codes; each image's field is then the shared MLP with its code.
pub struct FieldReconstructor {
    shape: FieldNet,
    net: Sequential,
    encoder: Buffer,
    input: Buffer,
    shared: Vec<f32>,
    field: Field,
    capacity: u32,
}

impl FieldReconstructor {
    /// Uploads a conditioned-field `model` ([`ReconModel::field`] is `Some`) for batches of up
    /// to `capacity` images.
    pub fn new(ctx: &Context, model: &ReconModel, capacity: u32) -> Result<Self> {
        let Some(mlp) = model.field else {
            return Err(Error::Input(
                "a mesh model, not a conditioned field: reconstruct with recon::Reconstructor"
                    .into(),
            ));
        };
        if capacity == 0 {
            return Err(Error::Input("a reconstruction batch of 0 images".into()));
        }
        let shape = FieldNet {
            net: model.net,
            mlp,
        };
        let net = Sequential::new(ctx, &shape.encoder_layers()?, capacity)?;
        if model.params.len() as u64 != shape.param_count()? {
            return Err(Error::Input(format!(
                "{} parameters for a network of {}",
                model.params.len(),
                shape.param_count()?
            )));
        }
        let e = net.param_count() as usize;
        let field = Field::new(
            ctx,
            FieldKind::Mlp {
                hidden_layers: mlp.hidden_layers,
                width: mlp.width,
                frequencies: mlp.frequencies,
            },
            field_cube(),
            0,
        )?;
        let px = u64::from(model.net.image).pow(2);
        Ok(Self {
            shape,
            encoder: ctx.upload_buffer("recon field encoder params", &model.params[..e])?,
            input: ctx.create_buffer(
                "recon field input",
                16 * u64::from(capacity) * px,
                MemoryKind::Device,
            )?,
            shared: model.params[e..].to_vec(),
            net,
            field,
            capacity,
        })
    }

    /// The codes of `images` (uint8 RGBA planes, `4 × H × W` bytes each, at most the
    /// capacity): [`FieldNet::code_len`] floats per image.
    pub fn codes(&self, ctx: &Context, images: &[u8]) -> Result<Vec<Vec<f32>>> {
        let (n, input) = super::model::input_floats(images, self.shape.net.image, self.capacity)?;
        ctx.write_buffer(&self.input, 0, &input)?;
        ctx.submit_and_wait(|rec| {
            self.net
                .record_forward(rec, self.encoder.whole(), self.input.whole(), n as u32)
        })?;
        let c = self.shape.code_len() as usize;
        let flat: Vec<f32> = ctx.read_buffer(self.net.output(), 0, n * c)?;
        Ok(flat.chunks(c).map(<[f32]>::to_vec).collect())
    }

    /// The field of `code` (uploaded: the reconstructor holds one field at a time).
    pub fn field_of(&self, ctx: &Context, code: &[f32]) -> Result<&Field> {
        self.field
            .set_params(ctx, &self.shape.object_field(&self.shared, code)?)?;
        Ok(&self.field)
    }

    /// The 32³ occupancy of each image's field in the dataset's voxel order: φ > 0.5 at the
    /// voxel centres ([`super::dataset::voxel_center`]), the ground truth's convention. (That is
    /// the marching-cubes mesh of φ on the lattice of the voxel centres voxelized by centres,
    /// as mesh predictions are: its inside nodes are those with φ > 0.5.)
    pub fn occupancy(&self, ctx: &Context, images: &[u8]) -> Result<Vec<Vec<bool>>> {
        use super::dataset::{VOXEL_RES, voxel_center};
        let r = VOXEL_RES;
        let points: Vec<[f32; 4]> = (0..r * r * r)
            .map(|i| {
                let c = voxel_center(i / (r * r), (i / r) % r, i % r);
                [c[0] as f32, c[1] as f32, c[2] as f32, 1.0]
            })
            .collect();
        self.codes(ctx, images)?
            .iter()
            .map(|code| {
                let phi = self.field_of(ctx, code)?.eval(ctx, &points)?;
                Ok(phi.iter().map(|&p| p > 0.5).collect())
            })
            .collect()
    }

    /// The mesh of φ = 0.5 of one image's field, by marching cubes on a `res³` lattice over
    /// [`field_cube`].
    pub fn isosurface(&self, ctx: &Context, image: &[u8], res: u32) -> Result<Isosurface> {
        let code = self.codes(ctx, image)?;
        if code.len() != 1 {
            return Err(Error::Input(format!("{} images; one expected", code.len())));
        }
        let field = self.field_of(ctx, &code[0])?;
        MarchingCubes::new(ctx)?.extract(ctx, field, res)
    }

    /// The network's shape.
    pub fn shape(&self) -> &FieldNet {
        &self.shape
    }

    /// Images per batch at most.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::MlpLayout;
    use crate::recon::NetShape;

    #[test]
    fn codes_replace_exactly_the_hidden_biases() {
        let net = FieldNet {
            net: NetShape {
                image: 16,
                channels: [2, 3, 4],
                latent: 8,
                hidden: 8,
            },
            mlp: MlpLayout {
                hidden_layers: 2,
                width: 8,
                frequencies: 1,
            },
        };
        // E = 9: layer 0 is 8 × 9 weights then 8 biases; layer 1 is 8 × 8 then 8; the output
        // 8 + 1.
        assert_eq!(net.code_ranges(), vec![72..80, 144..152]);
        assert_eq!(net.code_len(), 16);
        let shared: Vec<f32> = (0..net.mlp.param_count()).map(|i| i as f32).collect();
        let code: Vec<f32> = (0..16).map(|i| -1.0 - i as f32).collect();
        let p = net.object_field(&shared, &code).unwrap();
        for (i, (&a, &b)) in p.iter().zip(&shared).enumerate() {
            match i {
                72..80 => assert_eq!(a, code[i - 72]),
                144..152 => assert_eq!(a, code[8 + i - 144]),
                _ => assert_eq!(a, b),
            }
        }
        assert!(net.object_field(&shared, &code[1..]).is_err());
        let e = net.encoder_param_count().unwrap();
        assert_eq!(net.param_count().unwrap(), e + net.mlp.param_count() as u64);
        assert_eq!(
            net.init(5).unwrap().len() as u64,
            net.param_count().unwrap()
        );
        // The encoder's head gives the codes.
        let layers = net.encoder_layers().unwrap();
        assert_eq!(layers.last().unwrap().output_len(), 16);
    }
}
