//! Mesh deformation from silhouettes, SoftRas's `demo_deform.py` on the GPU: a template's
//! vertices, parameterized by [`Deform`] (bounded displacement + centroid), are fitted to target
//! silhouettes seen from known cameras by Adam on `1 − IoU + λ_lap Laplacian + λ_flat flatten`.
//!
//! **A whole iteration runs on the GPU, and many iterations run per submission**, with no host
//! round trip: deform forward → face setup → binning count → [the gate] → scatter, sort and
//! ranges → tiled fine pass → IoU loss and dL/d(image) → tiled backward on the same bins →
//! Laplacian and flatten gradients accumulated → deform backward → Adam step. The host submits
//! the iterations up to the next logged one (`log_every` per submission), then reads the gate's
//! status and, at that logged iteration, the losses and per-view IoUs.
//!
//! The binning's entry count, which sizes its buffers and the backward's per-entry partials, is
//! only known on the GPU. The buffers are reserved with headroom ([`ENTRY_HEADROOM`]) over the
//! last count the host saw (the first from one counting submission before the loop), the sort
//! runs over the whole capacity with sentinel keys ([`crate::primitives::binning`]), and
//! [`crate::gpu::gate`] stops an iteration whose count does not fit before any stage after the count
//! runs — and every later iteration of the submission. The host then sees the stop, grows the
//! buffers to the count it recorded (with the headroom again) and re-runs from the stopped
//! iteration. A stopped iteration changes nothing (parameters and Adam's moments are untouched),
//! and the binned result does not depend on the capacity, so the fit is bit for bit the one that
//! never stopped.
//!
//! The silhouette loss has no colour gradient, so the lighting's share of the position gradient
//! (added on the host in [`crate::raster::backward::GradKernels::finish`]) is zero and the GPU's
//! position gradient is complete.

use glam::{DMat3, DVec3};

use super::checkpoint::{Fingerprint, FitKind, Reader, Writer, restore_adam, save_adam};
use super::driver::{Fit, Fitter};
use super::log::Columns;
use super::session::{LogRow, Session, Trainee, to_next_log};
use super::{Adam, AdamOptions, Deform, Regularizers, SilhouetteLoss, with_headroom};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::GradOut;
use crate::gpu::gate::IterationGate;
use crate::gpu::{Buffer, Context, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::backward::GradBuffers;
use crate::raster::gpu::{Binned, GpuScene, GuardedBins, Renderer};
use crate::raster::settings::{Alpha, RasterSettings, Rgb};

pub use super::driver::ENTRY_HEADROOM;

/// Everything settable about a mesh fit; the default is SoftRas's deformation demo.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshFitOptions {
    /// Iterations (SoftRas: 2000).
    pub iterations: u32,
    /// Adam (SoftRas: lr 0.01, betas 0.5, 0.99).
    pub adam: AdamOptions,
    /// Weight of the Laplacian regularizer (SoftRas: 0.03).
    pub laplacian: f32,
    /// Weight of the flatten regularizer (SoftRas: 0.0003).
    pub flatten: f32,
    /// Rasterization (SoftRas: 64², σ 1e-4, hard colour aggregation).
    pub settings: RasterSettings,
    /// Tile edge of the tiled passes.
    pub tile: u32,
    /// Read the losses back every this many iterations (and after the last); also the
    /// iterations per submission.
    pub log_every: u32,
    /// The (face, tile) entries reserved at the start; `None` (the default): the template's
    /// count, read back once, with [`ENTRY_HEADROOM`]. More spares the re-runs of a fit whose
    /// shape grows; less saves memory (the bins and the backward's partials scale with it). An
    /// iteration that does not fit grows the capacity and runs again either way, with the same
    /// result (as softvk-field's `FieldFit::reserve`).
    pub entry_capacity: Option<u64>,
}

impl Default for MeshFitOptions {
    fn default() -> Self {
        Self {
            iterations: 2000,
            adam: AdamOptions {
                lr: 0.01,
                betas: (0.5, 0.99),
                eps: 1e-8,
            },
            laplacian: 0.03,
            flatten: 0.0003,
            settings: RasterSettings {
                width: 64,
                height: 64,
                sigma: 1e-4,
                rgb: Rgb::Hard,
                alpha: Alpha::Prod,
                ..RasterSettings::default()
            },
            tile: crate::raster::gpu::DEFAULT_TILE,
            log_every: 20,
            entry_capacity: None,
        }
    }
}

/// One logged iteration.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FitLog {
    /// Iteration (1-based) after which the values were read.
    pub iteration: u32,
    /// `1 − mean IoU` (soft).
    pub silhouette: f32,
    /// Laplacian regularizer (unweighted).
    pub laplacian: f32,
    /// Flatten regularizer (unweighted).
    pub flatten: f32,
    /// Weighted total.
    pub total: f32,
    /// (face, tile) entries the iteration binned.
    pub entries: u64,
    /// Seconds since the fit started.
    pub seconds: f64,
}

/// A finished fit.
#[derive(Clone, Debug)]
pub struct MeshFitResult {
    /// The fitted mesh (the template's faces, fitted positions).
    pub mesh: Mesh,
    /// The logged losses.
    pub log: Vec<FitLog>,
    /// The first iteration this call ran: 1, or resumed, the one after the state's.
    pub first_iteration: u32,
    /// Wall time of the iterations.
    pub seconds: f64,
    /// Submissions stopped because the entries outgrew their capacity (each grew it and re-ran
    /// from the stopped iteration).
    pub regrowths: u32,
    /// The entry capacity at the end.
    pub entry_capacity: u64,
    /// The fitted parameters: `3 V` displacements, then the centre ([`Deform`]'s layout).
    pub params: Vec<f32>,
}

/// SoftRas's deformation template, `sphere_1352.obj` (MIT; see `assets/README.md`), compiled in.
const SOFTRAS_SPHERE_OBJ: &str = include_str!("../../assets/sphere_1352.obj");

/// The template SoftRas's demo starts from: its 1 352-vertex sphere (2 700 faces) scaled by
/// 0.5, as `demo_deform.py` does. It has no coordinate exactly 0 (the parameterization keeps a
/// zero coordinate at zero forever).
pub fn default_template() -> Mesh {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _) = tobj::load_obj_buf(&mut SOFTRAS_SPHERE_OBJ.as_bytes(), &options, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .expect("the built-in sphere_1352.obj parses");
    let m = &models[0].mesh;
    let positions = m
        .positions
        .chunks_exact(3)
        .map(|p| [p[0] * 0.5, p[1] * 0.5, p[2] * 0.5])
        .collect();
    let faces = m
        .indices
        .chunks_exact(3)
        .map(|f| [f[0], f[1], f[2]])
        .collect();
    Mesh::new(positions, faces, 1).expect("the built-in sphere_1352.obj is a valid mesh")
}

/// The smaller template softvk used before (and `--template icosphere` selects): an icosphere
/// (3 subdivisions, 642 vertices, 1 280 faces) of radius 0.5, turned so that no coordinate is
/// exactly zero.
pub fn icosphere_template() -> Mesh {
    let mut mesh = Mesh::icosphere(3);
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.31, 0.47, 0.13);
    for p in &mut mesh.positions {
        let v = rot * DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])) * 0.5;
        *p = [v.x as f32, v.y as f32, v.z as f32];
    }
    mesh
}

/// A template (`softvk fit-mesh --template T.obj`) scaled into (-0.5, 0.5)³ around its bounding box's centre, turned slightly if a
/// coordinate is exactly 0 (the deformation keeps a zero coordinate at zero).
pub fn normalize_template(mut mesh: Mesh) -> Mesh {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in &mesh.positions {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let centre: [f32; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let half = (0..3).map(|k| 0.5 * (hi[k] - lo[k])).fold(0.0f32, f32::max);
    let scale = 0.45 / half.max(1e-12);
    for p in &mut mesh.positions {
        for k in 0..3 {
            p[k] = (p[k] - centre[k]) * scale;
            if p[k] == 0.0 {
                p[k] = 1e-4;
            }
        }
    }
    mesh
}

/// The demo's target, generated in code: an icosphere pushed out into three lobes and a dent.
pub fn demo_target() -> Mesh {
    let mut mesh = Mesh::icosphere(3);
    for p in &mut mesh.positions {
        let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        let az = z.atan2(x);
        let r = 0.42 * (1.0 + 0.28 * (3.0 * az).cos() * (1.0 - y * y) + 0.15 * y);
        *p = [(x * r) as f32, (y * r * 0.9) as f32, (z * r) as f32];
    }
    mesh
}

/// Fits `template` to `targets` (one f32 mask per pixel, view-major, `W × H` per view, W and H
/// from the options) seen from `cameras`, in `session` (its hooks see the fit after every
/// logged iteration: [`MeshFit::read_ious`], [`MeshFit::read_alphas`]; its checkpoints carry
/// [`MeshFit::fingerprint`]).
pub fn fit_mesh<'c>(
    ctx: &'c Context,
    template: &Mesh,
    cameras: &[Camera],
    targets: &[f32],
    opts: &MeshFitOptions,
    session: Session<'_, MeshFit<'c>>,
) -> Result<MeshFitResult> {
    let mut fitter = MeshFitter::new(ctx, template, cameras, targets, opts)?;
    let end = session.run(
        &mut fitter,
        (opts.iterations, opts.log_every),
        to_next_log(opts.log_every),
    )?;
    Ok(MeshFitResult {
        mesh: fitter.mesh(template)?,
        log: end.log,
        first_iteration: end.first,
        seconds: end.seconds,
        regrowths: fitter.regrowths(),
        entry_capacity: fitter.capacity(),
        params: fitter.read_params()?,
    })
}

impl LogRow for FitLog {
    fn iteration(&self) -> u32 {
        self.iteration
    }
    fn loss(&self) -> f64 {
        f64::from(self.total)
    }
    fn columns(&mut self, c: &mut dyn Columns) {
        c.u32("iteration", &mut self.iteration);
        c.f32("total", &mut self.total);
        c.f32("silhouette", &mut self.silhouette);
        c.f32("laplacian", &mut self.laplacian);
        c.f32("flatten", &mut self.flatten);
        c.u64("entries", &mut self.entries);
        c.f64("seconds", &mut self.seconds);
    }
}

/// A mesh fit in a session: its row is the losses of the logged iteration, its state the
/// parameters (`3 V` displacements, then the centre) and Adam's moments (the deformation fit
/// has no other state: no sampler, no schedule).
impl Trainee for MeshFit<'_> {
    type Row = FitLog;
    const KIND: FitKind = FitKind::Mesh;

    fn rows(
        &mut self,
        ctx: &Context,
        _first: u32,
        last: u32,
        entries: u64,
        seconds: f64,
    ) -> Result<Vec<FitLog>> {
        let o = &self.opts;
        let silhouette = self.sil.read_loss(ctx)?;
        let r = self.regs.read_losses(ctx)?;
        Ok(vec![FitLog {
            iteration: last,
            silhouette,
            laplacian: r.laplacian,
            flatten: r.flatten,
            total: silhouette + o.laplacian * r.laplacian + o.flatten * r.flatten,
            entries,
            seconds,
        }])
    }

    fn save_state(&self, ctx: &Context, w: &mut Writer) -> Result<()> {
        let n = self.deform.param_count() as usize;
        save_adam(ctx, &self.params, &self.adam, n, w)
    }

    fn restore_state(&mut self, ctx: &Context, r: &mut Reader<'_>) -> Result<()> {
        let n = self.deform.param_count() as usize;
        restore_adam(ctx, &self.params, &self.adam, n, r, "the template")
    }
}

impl MeshFit<'_> {
    /// The fingerprint of a fit's inputs that a checkpoint of it must carry: the template, the
    /// targets, the cameras and every option but the iteration count, the logging and the entry
    /// capacity (which change no result: a fit may be resumed for more iterations).
    pub fn fingerprint(
        template: &Mesh,
        cameras: &[Camera],
        targets: &[f32],
        opts: &MeshFitOptions,
    ) -> u64 {
        let mut f = Fingerprint::default();
        f.add_pod(&template.positions).add_pod(&template.faces);
        f.add_pod(targets);
        f.add(format!("{cameras:?}").as_bytes());
        let o = MeshFitOptions {
            iterations: 0,
            log_every: 0,
            entry_capacity: None,
            ..opts.clone()
        };
        f.add(format!("{o:?}").as_bytes());
        f.value()
    }
}

/// A mesh fit's GPU state: the scene, the losses, the optimizer, the parameters and the guarded
/// bins; [`MeshFitter`] runs its iterations.
pub struct MeshFit<'c> {
    ctx: &'c Context,
    opts: MeshFitOptions,
    renderer: Renderer,
    scene: GpuScene,
    /// The guarded forward's bins, beside the scene.
    bins: GuardedBins,
    deform: Deform,
    regs: Regularizers,
    sil: SilhouetteLoss,
    adam: Adam,
    params: Buffer,
    d_params: Buffer,
    targets: Buffer,
    grads: GradBuffers,
    /// Entries the bins and the partials hold.
    capacity: u64,
    /// The most they may hold (one binding, the u32 count).
    max_capacity: u64,
}

/// A mesh fit ready to run iterations ([`Fitter::run`]); also what the fitting benchmark times.
pub type MeshFitter<'c> = Fitter<'c, MeshFit<'c>>;

impl<'c> Fitter<'c, MeshFit<'c>> {
    /// Checks the inputs, uploads everything, zeroes the parameters and Adam's moments, and
    /// reserves the entries (see [`MeshFitOptions::entry_capacity`]).
    pub fn new(
        ctx: &'c Context,
        template: &Mesh,
        cameras: &[Camera],
        targets: &[f32],
        opts: &MeshFitOptions,
    ) -> Result<Self> {
        let s = &opts.settings;
        let views = cameras.len();
        if views == 0 {
            return Err(Error::Input("no views to fit".into()));
        }
        let px = (s.width * s.height) as usize;
        if targets.len() != views * px {
            return Err(Error::Input(format!(
                "{} target pixels, but {views} views of {}x{} need {}",
                targets.len(),
                s.width,
                s.height,
                views * px
            )));
        }
        if opts.iterations == 0 || opts.log_every == 0 {
            return Err(Error::Input(
                "iterations and log_every must be at least 1".into(),
            ));
        }
        if opts.entry_capacity == Some(0) {
            return Err(Error::Input("the entry capacity must be at least 1".into()));
        }
        template.validate()?;
        let renderer = Renderer::new(ctx)?;
        let mut scene = renderer.prepare(ctx, template, cameras, &Lighting::unlit(), s)?;
        // Silhouettes: alpha is all the loss reads.
        scene.set_silhouette_only(true);
        let deform = Deform::new(ctx, &template.positions)?;
        let regs = Regularizers::new(ctx, &template.faces, template.vertex_count())?;
        let sil = SilhouetteLoss::new(ctx, views as u32, s.width, s.height)?;
        let adam = Adam::new(ctx, deform.param_count(), opts.adam)?;
        let params =
            ctx.create_buffer("fit params", 4 * deform.param_count(), MemoryKind::Device)?;
        let d_params =
            ctx.create_buffer("fit d_params", 4 * deform.param_count(), MemoryKind::Device)?;
        let target_buf = ctx.upload_buffer("fit targets", targets)?;
        // Zero displacement and centre: the template itself.
        ctx.submit_and_wait(|rec| {
            rec.fill(params.whole(), 0);
            adam.record_reset(rec);
            Ok(())
        })?;
        let max_capacity = super::max_entry_capacity(ctx, &renderer, &scene);
        let capacity = match opts.entry_capacity {
            Some(c) => c.min(max_capacity),
            None => {
                // One counting submission on the template.
                ctx.submit_and_wait(|rec| {
                    deform.record_forward(rec, params.whole(), scene.positions().whole())
                })?;
                let total = renderer.count_entries(ctx, &scene, opts.tile)?;
                with_headroom(ctx, &mesh_entries(views), total, max_capacity, MESH_HINT)?
            }
        };
        // The silhouette loss differentiates alpha only (as the scene renders it).
        let (bins, grads) =
            super::reserve_guarded(ctx, &renderer, &scene, opts.tile, capacity, true)?;
        let fit = MeshFit {
            ctx,
            opts: opts.clone(),
            renderer,
            scene,
            bins,
            deform,
            regs,
            sil,
            adam,
            params,
            d_params,
            targets: target_buf,
            grads,
            capacity,
            max_capacity,
        };
        Fitter::from_fit(ctx, fit)
    }
}

impl Fit for MeshFit<'_> {
    const NAME: &'static str = "fit";

    /// The deformation, then the guarded forward with the rest of the iteration (loss,
    /// backward, regularizers, deformation backward, Adam) gated on the count.
    fn record_iteration(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        _row: u32,
    ) -> Result<()> {
        let Self {
            opts: o,
            renderer,
            scene,
            deform,
            regs,
            sil,
            adam,
            params,
            d_params,
            targets,
            grads: g,
            bins,
            ..
        } = self;
        rec.pass("deform", |rec| {
            deform.record_forward(rec, params.whole(), scene.positions().whole())
        })?;
        renderer.record_forward_guarded(rec, scene, bins, gate, it, |rec, binned| {
            let io = g.io();
            rec.pass("silhouette loss", |rec| {
                sil.record(
                    rec,
                    scene.output().whole(),
                    targets.whole(),
                    Some(GradOut::write(io.upstream)),
                )
            })?;
            renderer.grad_kernels().record(rec, &binned, g, &io)?;
            rec.pass("regularizers", |rec| {
                regs.record_laplacian(
                    rec,
                    scene.positions().whole(),
                    Some(GradOut::accumulate(io.positions, o.laplacian)),
                )?;
                regs.record_flatten(
                    rec,
                    scene.positions().whole(),
                    Some(GradOut::accumulate(io.positions, o.flatten)),
                )
            })?;
            rec.pass("deform backward", |rec| {
                deform.record_backward(rec, params.whole(), io.positions, d_params.whole())
            })?;
            rec.pass("adam", |rec| {
                adam.record_step(rec, params.whole(), d_params.whole(), it)
            })
        })
    }

    fn capacity(&self) -> u64 {
        self.capacity
    }

    /// Grows the bins and the partials to `total` entries with the headroom.
    fn grow(&mut self, ctx: &Context, total: u64) -> Result<()> {
        let views = self.scene.view_count() as usize;
        let capacity = with_headroom(
            ctx,
            &mesh_entries(views),
            total,
            self.max_capacity,
            MESH_HINT,
        )?;
        (self.bins, self.grads) = super::reserve_guarded(
            ctx,
            &self.renderer,
            &self.scene,
            self.opts.tile,
            capacity,
            true,
        )?;
        self.capacity = capacity;
        Ok(())
    }
}

impl MeshFit<'_> {
    /// The per-view soft IoUs of the last iteration that ran.
    pub fn read_ious(&self) -> Result<Vec<f32>> {
        self.sil.read_ious(self.ctx)
    }

    /// The predicted alpha per pixel (view-major) of the last iteration that ran.
    pub fn read_alphas(&self) -> Result<Vec<f32>> {
        let s = &self.opts.settings;
        let n = (s.width * s.height * self.scene.view_count()) as usize;
        let rgba: Vec<[f32; 4]> = self.ctx.read_buffer(self.scene.output(), 0, n)?;
        Ok(rgba.iter().map(|p| p[3]).collect())
    }

    /// The template with the positions the parameters give now.
    pub fn mesh(&self, template: &Mesh) -> Result<Mesh> {
        self.ctx.submit_and_wait(|rec| {
            self.deform
                .record_forward(rec, self.params.whole(), self.scene.positions().whole())
        })?;
        let mut mesh = template.clone();
        mesh.positions =
            self.ctx
                .read_buffer(self.scene.positions(), 0, template.vertex_count())?;
        Ok(mesh)
    }

    /// The scene the fit renders.
    pub fn scene(&self) -> &GpuScene {
        &self.scene
    }

    /// The binning of the last iteration's forward (for [`Binned::pair_counts`]).
    pub fn binned(&self) -> Result<Binned<'_>> {
        self.bins.binned(&self.scene)
    }

    /// Entries the bins and the backward's partials hold now.
    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    /// The parameters (`3 V` displacements, then the centre).
    pub fn read_params(&self) -> Result<Vec<f32>> {
        self.ctx
            .read_buffer(&self.params, 0, self.deform.param_count() as usize)
    }
}

/// What a mesh fit's binning is, for [`Error::DeviceLimit`].
fn mesh_entries(views: usize) -> String {
    format!("a mesh fit's binning of {views} views (with the backward's partials)")
}

const MESH_HINT: &str = "use fewer views, larger tiles or a smaller σ";
