//! [`ReconTraining`], the [`Fit`] that trains the reconstruction network: its buffers and
//! kernels, built by [`ReconTrainer::new`], one iteration recorded, and the logs read back.

use super::{Batches, COPIES, Recipe, TrainImages, TrainOptions, TrainedParams};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::fit::driver::{Fit, Fitter};
use crate::fit::{ImageMse, Regularizers, SilhouetteLoss};
use crate::gpu::gate::IterationGate;
use crate::gpu::{Buffer, Context, GradOut, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::nn::Sequential;
use crate::raster::backward::GradBuffers;
use crate::raster::gpu::{GpuScene, GuardedBins, Renderer};
use crate::recon::dataset::view_camera;
use crate::recon::decode::MeshDecoder;

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

impl<'c> ReconTraining<'c> {
    /// Borrows the training images (each submission stages the views its batches name), builds
    /// the network with `params` (or an initialization from the seed), zeroes Adam's moments,
    /// and sizes the binning on the template; on the driver. (A fit of another crate than the
    /// driver's is built by its own type: an inherent `impl` on [`Fitter`] is softvk-fit's.)
    pub fn fitter(
        ctx: &'c Context,
        data: &'c TrainImages,
        opts: &TrainOptions,
        params: Option<&[f32]>,
    ) -> Result<ReconTrainer<'c>> {
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
