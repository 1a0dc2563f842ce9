//! Implicit-field fitting from silhouettes by sphere probing (SPEC §5): the glue between
//! [`crate::probe`] (sampling, probing, the losses and their dL/dφ), [`crate::field`] (φ and
//! dL/dparams) and [`Adam`].
//!
//! **One iteration**, recorded into one command buffer with no read-back, as [`crate::probe`]
//! spells out (the binning's entry count stays on the GPU: the prober's guarded mode):
//!
//! ```text
//! sample         sampler(iteration) → rays, anchors, candidates; geo points (49 per candidate)
//!                copy anchors → points[0 .. N_a), geo points → points[A .. A + M)
//! probe count    anchor items + binning count
//! gate           count ≤ capacity? (else this and the later iterations run nothing)
//! gated:         φ = field(points[0 .. A + M))                      one record_eval
//!                ψ, L_sil, dL_sil/dφ → d_φ[0 .. N_a)                (prober, over the capacity)
//!                L_geo, λ dL_geo/dφ → d_φ[A .. A + M)               (geometric regularizer)
//!                dL/dparams = field backward(points, d_φ)           one record_backward
//!                Adam step on the field's parameters
//! ```
//!
//! A fit records `log_every` iterations per submission and reads the losses after it (the
//! mesh fit's loop shape). The entry buffers are sized from iteration 1's count with the mesh
//! fit's headroom; an iteration whose count outgrows them is stopped by the gate with every
//! later one of its submission, the buffers grow, and they run again: the result is the one of
//! a fit that never stopped.
//!
//! `A` is `N_a` rounded up so that the geo block's φ and d_φ sub-ranges start at an offset the
//! device can bind; the points and d_φ between `N_a` and `A` are zero, so they add nothing to
//! the gradient. With λ = 0 the regularizer is skipped altogether (`M = 0`, L_geo logged as 0).
//!
//! Everything is deterministic: the sampler draws from (seed, iteration), every kernel sums in a
//! fixed order, so a fit repeated with the same options gives bit-identical parameters.
//!
//! [`FieldFitter`] runs any span of iterations in one submission (for tests and tools);
//! [`fit_field`] runs the whole fit and logs the losses every `log_every` iterations.

use std::time::Instant;

use glam::DVec3;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::field::{Cube, Field, FieldKind};
use crate::fit::checkpoint::{Fingerprint, FitKind, Reader, Writer, restore_adam, save_adam};
use crate::fit::driver::{Fit, Fitter};
use crate::fit::log::Columns;
use crate::fit::session::{LogRow, Session, Trainee, to_next_log};
use crate::fit::{Adam, AdamOptions};
use crate::gpu::GradOut;
use crate::gpu::gate::IterationGate;
use crate::gpu::{Buffer, Context, MemoryKind, Recorder};
use crate::probe::{GeoRegularizer, GpuTargets, ProbeSettings, Prober, Sampler, Targets};

/// Everything settable about a field fit. The cube and the seed live in [`ProbeSettings`]
/// (`cube_center`, `cube_half`, `seed`), so that sampling, probing and the field cannot disagree
/// about them; the MLP's initialization uses the same seed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldFitOptions {
    /// The field (grid or MLP; an analytic shape fits its few numbers).
    pub field: FieldKind,
    /// Every parameter of sampling, probing and the losses, in world units, with the cube.
    pub probe: ProbeSettings,
    /// Adam's hyper-parameters.
    pub adam: AdamOptions,
    /// Iterations, ≥ 1.
    pub iterations: u32,
    /// Read the losses back every this many iterations (and after the last), ≥ 1.
    pub log_every: u32,
    /// A constant added to the initial logit: every node of a grid, the output bias of an MLP
    /// (ignored for an analytic shape). Positive starts from "everything occupied", which the
    /// rays outside the silhouettes carve; 0 starts from φ ≈ 0.5.
    pub init_logit: f64,
}

impl Default for FieldFitOptions {
    /// The defaults of `softvk fit-field`, for the cube [-1, 1]³ (lengths scale with the cube:
    /// [`scaled_to_cube`]), chosen by measurement on spot and on thin-parted objects
    /// (`RESULTS.md`, "Sphere probing" and "Thin structures"): a 48³ grid, 512 rays per view,
    /// 4096 anchors of radius τ = 0.045, tiles of 8 pixels, no geometric regularizer (λ = 0:
    /// every λ tried lowered the 3D IoU), Adam lr 0.05 with betas (0.9, 0.99), 1 000
    /// iterations; the other probe settings are [`ProbeSettings::default`]'s. (The grid was once
    /// 32³ and the fit 150 iterations: enough for spot, not for legs and wings.)
    fn default() -> Self {
        Self {
            field: FieldKind::Grid {
                res: DEFAULT_GRID_RES,
            },
            probe: ProbeSettings {
                rays_per_view: 512,
                anchors: 4096,
                tau: 0.045,
                tile_size: 8,
                geo_lambda: 0.0,
                ..ProbeSettings::default()
            },
            adam: AdamOptions {
                lr: DEFAULT_LR,
                betas: (0.9, 0.99),
                eps: 1e-8,
            },
            iterations: DEFAULT_ITERATIONS,
            log_every: 10,
            init_logit: DEFAULT_INIT_LOGIT,
        }
    }
}

/// Default grid resolution of `fit-field`.
pub const DEFAULT_GRID_RES: u32 = 48;
/// Default Adam learning rate of `fit-field`.
pub const DEFAULT_LR: f64 = 0.05;
/// Default iterations of `fit-field`.
pub const DEFAULT_ITERATIONS: u32 = 1000;
/// Default initial logit offset of `fit-field`.
pub const DEFAULT_INIT_LOGIT: f64 = 0.0;

impl FieldFitOptions {
    /// The field's cube (from the probe settings).
    pub fn cube(&self) -> Cube {
        Cube {
            center: self.probe.cube_center,
            half: self.probe.cube_half,
        }
    }

    /// [`Error::Input`] for an invalid field, probe settings, Adam options, zero iterations or
    /// log interval, or a non-finite initial logit.
    pub fn validate(&self) -> Result<()> {
        self.field.validate()?;
        self.probe.validate()?;
        self.adam.validate()?;
        if self.iterations == 0 || self.log_every == 0 {
            return Err(Error::Input(
                "field fit: iterations and log_every must be at least 1".into(),
            ));
        }
        if !self.init_logit.is_finite() {
            return Err(Error::Input(format!(
                "field fit: initial logit {} is not finite",
                self.init_logit
            )));
        }
        Ok(())
    }
}

/// `settings` with the cube set to `cube` and every length (τ, σ_a, δ, δ_n) multiplied by the
/// cube's half-edge: the lengths of `settings` are read in units of the half-edge (the defaults
/// of [`ProbeSettings`] are for the cube [-1, 1]³, whose half-edge is 1).
pub fn scaled_to_cube(settings: &ProbeSettings, cube: &Cube) -> ProbeSettings {
    let h = cube.half;
    ProbeSettings {
        cube_center: cube.center,
        cube_half: h,
        tau: settings.tau * h,
        tau_outside: settings.tau_outside.map(|t| t * h),
        anchor_sigma: settings.anchor_sigma * h,
        geo_delta: settings.geo_delta * h,
        geo_normal_delta: settings.geo_normal_delta * h,
        ..*settings
    }
}

/// The centre of projection of a camera, when it has one (perspective and matrix cameras; an
/// orthographic camera's eye is returned as well: anchors behind it are not probed either).
fn camera_centre(view: &crate::probe::ProbeView, camera: &Camera) -> DVec3 {
    let central = view.a2[..3].iter().any(|&c| c != 0.0);
    if central {
        DVec3::new(
            f64::from(view.o0[0]),
            f64::from(view.o0[1]),
            f64::from(view.o0[2]),
        )
    } else {
        camera.eye
    }
}

/// [`Error::Input`] when a camera's centre lies inside (or on) `cube`: anchors around it would
/// be behind it in that view, and the visual hull would be cut by the camera.
pub fn check_cameras_outside(targets: &Targets, cube: &Cube) -> Result<()> {
    for (k, (view, camera)) in targets.views.iter().zip(&targets.cameras).enumerate() {
        let c = camera_centre(view, camera);
        let inside = (0..3).all(|a| (c[a] - cube.center[a]).abs() <= cube.half);
        if inside {
            return Err(Error::Input(format!(
                "camera {k} at ({:.4}, {:.4}, {:.4}) is inside the field's cube (centre {:?}, \
                 half-edge {}): every camera must see the cube from outside; move the camera \
                 or shrink the cube (--cube)",
                c.x, c.y, c.z, cube.center, cube.half
            )));
        }
    }
    Ok(())
}

/// Default margin of [`auto_cube`] (a fraction of the hull's half-edge).
pub const DEFAULT_CUBE_MARGIN: f64 = 0.1;

/// Lattice points per axis of the search for [`auto_cube`].
pub const AUTO_CUBE_RESOLUTION: u32 = 64;

/// A cube around the visual hull of `targets`, computed on a [`AUTO_CUBE_RESOLUTION`]³ lattice
/// over the largest origin-centred cube that keeps every camera outside (98 % of the smallest L∞
/// distance of a camera centre): the hull's bounding box, grown by one lattice step, made cubic
/// around its centre, and grown by `margin` (a fraction of the half-edge).
///
/// The hull is the usual one (inside every silhouette, and so within every frame) unless a
/// silhouette touches its image border ([`silhouettes_touch_the_border`]): the object is then
/// cut by some frames, and a point counts when at least half of the views see it and it is
/// inside the silhouette of every view that does, so the cube holds the object whole (half of
/// the views, not one, keeps out the regions near a camera that only it sees).
///
/// [`Error::Input`] when the hull is empty (the silhouettes do not agree with the cameras) or
/// `margin` is not finite and ≥ 0.
pub fn auto_cube(targets: &Targets, margin: f64) -> Result<Cube> {
    if !(margin.is_finite() && margin >= 0.0) {
        return Err(Error::Input(format!(
            "field fit: cube margin {margin}: need a finite number >= 0"
        )));
    }
    let nearest = targets
        .views
        .iter()
        .zip(&targets.cameras)
        .map(|(v, c)| camera_centre(v, c).abs().max_element())
        .fold(f64::INFINITY, f64::min);
    if !(nearest.is_finite() && nearest > 0.0) {
        return Err(Error::Input(
            "field fit: a camera sits at the origin; give the cube with --cube".into(),
        ));
    }
    let search = ProbeSettings {
        cube_center: [0.0; 3],
        cube_half: 0.98 * nearest,
        hull_resolution: AUTO_CUBE_RESOLUTION,
        ..ProbeSettings::default()
    };
    let views = targets.views.len();
    let min_seen = if silhouettes_touch_the_border(targets) {
        views.div_ceil(2)
    } else {
        views
    };
    let v = AUTO_CUBE_RESOLUTION as usize;
    let step = 2.0 * search.cube_half / v as f64;
    let lo = search.cube_min();
    let mut bmin = [f64::INFINITY; 3];
    let mut bmax = [f64::NEG_INFINITY; 3];
    for z in 0..v {
        for y in 0..v {
            for x in 0..v {
                let c = [x, y, z].map(|i| i as f64 + 0.5);
                let p = DVec3::new(
                    lo[0] + c[0] * step,
                    lo[1] + c[1] * step,
                    lo[2] + c[2] * step,
                );
                if frame_hull_contains(targets, p, min_seen) {
                    for a in 0..3 {
                        bmin[a] = bmin[a].min(p[a]);
                        bmax[a] = bmax[a].max(p[a]);
                    }
                }
            }
        }
    }
    if !bmin[0].is_finite() {
        return Err(Error::Input(format!(
            "field fit: the visual hull of the {} silhouettes is empty within {} of the origin: \
             the silhouettes and cameras do not agree (or give the cube with --cube)",
            targets.views.len(),
            search.cube_half
        )));
    }
    let center: [f64; 3] = std::array::from_fn(|a| 0.5 * (bmin[a] + bmax[a]));
    let half = (0..3)
        .map(|a| 0.5 * (bmax[a] - bmin[a]) + step)
        .fold(0.0f64, f64::max);
    Cube::new(center, half * (1.0 + margin))
}

/// Whether some silhouette has an inside pixel on its image border: the object is cut by that
/// view's frame.
pub fn silhouettes_touch_the_border(targets: &Targets) -> bool {
    let (w, h) = (i64::from(targets.width), i64::from(targets.height));
    (0..targets.views.len()).any(|k| {
        (0..w).any(|c| targets.inside(k, c, 0) || targets.inside(k, c, h - 1))
            || (0..h).any(|r| targets.inside(k, 0, r) || targets.inside(k, w - 1, r))
    })
}

/// Whether `p` is in the visual hull of `targets` with the image frames taken into account: in
/// front of every camera, seen (projected into the image) by at least `min_seen` views, and
/// inside the silhouette of every view that sees it. A view whose frame `p` falls outside says
/// nothing about it.
fn frame_hull_contains(targets: &Targets, p: DVec3, min_seen: usize) -> bool {
    let mut seen = 0;
    for (k, view) in targets.views.iter().enumerate() {
        let [sx, sy, depth] = view.project(p);
        if !(depth > 0.0 && view.denominator(p) > 0.0) {
            return false;
        }
        let (col, row) = targets.screen_to_pixel(sx, sy);
        let in_frame = (0..i64::from(targets.width)).contains(&col)
            && (0..i64::from(targets.height)).contains(&row);
        if in_frame {
            if !targets.inside(k, col, row) {
                return false;
            }
            seen += 1;
        }
    }
    seen >= min_seen
}

/// One logged iteration.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FieldFitLog {
    /// Iteration (1-based) after which the values were read.
    pub iteration: u32,
    /// L_sil of the iteration (before its Adam step).
    pub silhouette: f32,
    /// L_geo (unweighted; 0 when λ = 0 skips it).
    pub geo: f32,
    /// `L_sil + λ L_geo`.
    pub total: f32,
    /// Seconds since the iterations started.
    pub seconds: f64,
}

/// Where a fit's wall time went.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FieldFitTimings {
    /// Pipelines, buffers, the visual hull's boundary and the contour densities.
    pub setup_s: f64,
    /// Loss read-backs and the progress callback, summed.
    pub log_s: f64,
    /// All iterations, wall (their submissions, one per logged iteration, and the logging).
    pub iterations_s: f64,
    /// Submissions the gate stopped (each grew the entry capacity and ran again).
    pub regrowths: u32,
}

/// A finished fit.
pub struct FieldFitResult {
    /// The fitted field (on the GPU).
    pub field: Field,
    /// The logged losses.
    pub log: Vec<FieldFitLog>,
    /// Iterations run (fewer than asked when the progress callback stopped the fit).
    pub iterations: u32,
    /// The first iteration this run ran (after a resume, the checkpoint's + 1).
    pub first_iteration: u32,
    /// Wall times.
    pub timings: FieldFitTimings,
}

/// A field fit's state on the GPU; [`FieldFitter`] runs its iterations.
pub struct FieldFit {
    opts: FieldFitOptions,
    field: Field,
    gpu: GpuTargets,
    sampler: Sampler,
    prober: Prober,
    geo: Option<GeoRegularizer>,
    adam: Adam,
    /// Anchors, padding, geo points (`vec4` each).
    points: Buffer,
    phi: Buffer,
    d_phi: Buffer,
    d_params: Buffer,
    anchors: u32,
    geo_start: u32,
    geo_count: u32,
}

/// A field fit ready to run iterations ([`Fitter::run`]).
pub type FieldFitter<'c> = Fitter<'c, FieldFit>;

/// `n` rounded up to a multiple of `align`.
fn round_up(n: u64, align: u64) -> u64 {
    n.div_ceil(align) * align
}

impl FieldFit {
    /// The field (initialized as [`FieldFitOptions::init_logit`] says), the sampler (the visual
    /// hull's boundary and the contour densities, on the host), the prober, the regularizer and
    /// Adam, for `targets`, on the driver. (The fits of softvk-fit build theirs with
    /// `…Fitter::new`; an inherent `impl` on [`Fitter`] is that crate's alone, so this crate's
    /// fit is built by its own type.)
    ///
    /// [`Error::Input`] for invalid options or a camera inside the cube; [`Error::Limit`] for
    /// counts the device cannot hold or loop over.
    pub fn fitter<'c>(
        ctx: &'c Context,
        targets: &Targets,
        opts: &FieldFitOptions,
    ) -> Result<FieldFitter<'c>> {
        opts.validate()?;
        let cube = opts.cube();
        check_cameras_outside(targets, &cube)?;
        let s = &opts.probe;
        let field = Field::new(ctx, opts.field, cube, s.seed)?;
        if opts.init_logit != 0.0 {
            let mut params = opts.field.initial_params(s.seed);
            match opts.field {
                FieldKind::Grid { .. } => {
                    params.iter_mut().for_each(|p| *p += opts.init_logit as f32)
                }
                FieldKind::Mlp { .. } => {
                    if let Some(bias) = params.last_mut() {
                        *bias += opts.init_logit as f32;
                    }
                }
                FieldKind::Analytic { .. } => {}
            }
            field.set_params(ctx, &params)?;
        }
        let gpu = GpuTargets::new(ctx, targets)?;
        let sampler = Sampler::new(ctx, targets, &gpu, s)?;
        let prober = Prober::new(ctx, &gpu, s)?;
        let geo = if s.geo_lambda > 0.0 {
            Some(GeoRegularizer::new(ctx, s)?)
        } else {
            None
        };
        let mut prober = prober;
        // One counting submission (iteration 1's anchors) sizes the guarded entry buffers,
        // with headroom; an iteration that outgrows them grows them and runs again.
        ctx.submit_and_wait(|rec| {
            sampler.record(rec, &gpu, 1)?;
            prober.record_count(rec, &gpu, sampler.anchors().whole())
        })?;
        let counted = u64::from(ctx.read_buffer::<u32>(prober.total_buffer().buffer, 0, 1)?[0]);
        prober.reserve_guarded(ctx, field_capacity(ctx, counted)?)?;
        let anchors = s.anchors;
        // φ and d_φ of the geo block are bound at 4 · geo_start bytes: keep that aligned.
        let align_floats = (ctx.info().buffer_alignment() / 4).max(1);
        let geo_start = round_up(u64::from(anchors), align_floats);
        let geo_count = geo.as_ref().map_or(0, |g| g.point_count());
        let total = geo_start + geo_count;
        let total = u32::try_from(total).map_err(|_| {
            Error::Limit(format!(
                "field fit: {total} points per iteration (at most 2^32 − 1)"
            ))
        })?;
        crate::gpu::check_binding(ctx, "field fit: points", 16 * u64::from(total))?;
        let points = ctx.create_buffer(
            "field fit points",
            16 * u64::from(total),
            MemoryKind::Device,
        )?;
        let phi = ctx.create_buffer("field fit phi", 4 * u64::from(total), MemoryKind::Device)?;
        let d_phi =
            ctx.create_buffer("field fit d_phi", 4 * u64::from(total), MemoryKind::Device)?;
        let p = field.param_count() as u64;
        let d_params = ctx.create_buffer("field fit d_params", 4 * p.max(1), MemoryKind::Device)?;
        let adam = Adam::new(ctx, p, opts.adam)?;
        // The padding between the anchors and the geo block stays zero: points at the origin
        // with d_φ = 0.
        ctx.submit_and_wait(|rec| {
            rec.fill(points.whole(), 0);
            rec.fill(d_phi.whole(), 0);
            Ok(())
        })?;
        let fit = FieldFit {
            opts: *opts,
            field,
            gpu,
            sampler,
            prober,
            geo,
            adam,
            points,
            phi,
            d_phi,
            d_params,
            anchors,
            geo_start: geo_start as u32,
            geo_count: geo_count as u32,
        };
        Fitter::from_fit(ctx, fit)
    }

    /// The field, giving up the rest.
    pub fn into_field(self) -> Field {
        self.field
    }
}

impl Fit for FieldFit {
    const NAME: &'static str = "field fit";

    /// Sampling and the geo points (see the [module docs](self)), then the prober's guarded
    /// count and — gated on it — φ, probing, the losses, the backward and the Adam step.
    fn record_iteration(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        iteration: u32,
        _row: u32,
    ) -> Result<()> {
        let na = u64::from(self.anchors);
        let (gs, gc) = (u64::from(self.geo_start), u64::from(self.geo_count));
        let count = (gs + gc) as u32;
        let lambda = self.opts.probe.geo_lambda as f32;
        rec.pass("sample", |rec| {
            self.sampler.record(rec, &self.gpu, iteration)?;
            rec.copy(self.sampler.anchors(), 0, &self.points, 0, 16 * na);
            if let Some(geo) = &self.geo {
                geo.record_points(rec, self.sampler.candidates().whole())?;
                rec.copy(geo.points(), 0, &self.points, 16 * gs, 16 * gc);
            }
            Ok(())
        })?;
        let anchors = self.sampler.anchors().whole();
        self.prober
            .record_guarded(rec, gate, iteration, &self.gpu, anchors, |rec| {
                rec.pass("field eval", |rec| {
                    self.field
                        .record_eval(rec, self.points.whole(), count, self.phi.whole())
                })?;
                let rays = self.sampler.rays().whole();
                let phi_a = self.phi.range(0, 4 * na);
                rec.pass("probe forward", |rec| {
                    self.prober
                        .record_forward(rec, &self.gpu, anchors, phi_a, rays)
                })?;
                rec.pass("probe backward", |rec| {
                    self.prober.record_backward(
                        rec,
                        &self.gpu,
                        anchors,
                        phi_a,
                        rays,
                        GradOut::write(self.d_phi.range(0, 4 * na)),
                    )
                })?;
                rec.pass("geo loss", |rec| match &self.geo {
                    Some(geo) => geo.record_loss(
                        rec,
                        self.phi.range(4 * gs, 4 * gc),
                        Some(GradOut::write(self.d_phi.range(4 * gs, 4 * gc)).weighted(lambda)),
                    ),
                    None => Ok(()),
                })?;
                rec.pass("field backward", |rec| {
                    self.field.record_backward(
                        rec,
                        self.points.whole(),
                        count,
                        self.d_phi.whole(),
                        self.d_params.whole(),
                    )
                })?;
                let p = self.field.param_count() as u64;
                rec.pass("adam", |rec| {
                    self.adam.record_step(
                        rec,
                        self.field.params().range(0, 4 * p.max(1)),
                        self.d_params.whole(),
                        iteration,
                    )
                })
            })
    }

    fn capacity(&self) -> u64 {
        self.prober.entry_capacity()
    }

    fn grow(&mut self, ctx: &Context, total: u64) -> Result<()> {
        self.prober
            .reserve_guarded(ctx, field_capacity(ctx, total)?)
    }
}

impl FieldFit {
    /// Sizes the prober's entry buffers for `capacity` (anchor, tile) entries per iteration
    /// (at least 1). [`FieldFitter::new`] sizes them from the first iteration's count with
    /// headroom; more spares the re-runs of a fit whose counts grow, less saves memory, and
    /// an iteration that does not fit grows them and runs again either way.
    pub fn reserve(&mut self, ctx: &Context, capacity: u64) -> Result<()> {
        self.prober.reserve_guarded(ctx, capacity)
    }

    /// Entries the prober's buffers hold now.
    pub fn capacity(&self) -> u64 {
        self.prober.entry_capacity()
    }

    /// `(L_sil, L_geo)` of the last iteration (L_geo 0 when λ = 0).
    pub fn read_losses(&self, ctx: &Context) -> Result<(f32, f32)> {
        let sil = self.prober.read_loss(ctx)?;
        let geo = match &self.geo {
            Some(g) => g.read_loss(ctx)?,
            None => 0.0,
        };
        Ok((sil, geo))
    }

    /// The field.
    pub fn field(&self) -> &Field {
        &self.field
    }

    /// The sampler (its buffers hold the last iteration's rays, anchors and candidates).
    pub fn sampler(&self) -> &Sampler {
        &self.sampler
    }

    /// The points of the last iteration: anchors at `[0, N_a)`, zeros up to
    /// [`FieldFit::geo_start`], then the regularizer's points.
    pub fn points(&self) -> &Buffer {
        &self.points
    }

    /// dL/dφ per point of the last iteration (the layout of [`FieldFit::points`]).
    pub fn d_phi(&self) -> &Buffer {
        &self.d_phi
    }

    /// dL/dparams of the last iteration (the gradient Adam stepped with).
    pub fn d_params(&self) -> &Buffer {
        &self.d_params
    }

    /// Index of the first regularizer point.
    pub fn geo_start(&self) -> u32 {
        self.geo_start
    }

    /// Regularizer points per iteration (`49 ×` candidates; 0 when λ = 0).
    pub fn geo_count(&self) -> u32 {
        self.geo_count
    }

    /// The options.
    pub fn options(&self) -> &FieldFitOptions {
        &self.opts
    }
}

/// Fits a field to `targets` (silhouettes and their cameras) in `session` (its checkpoints
/// carry [`FieldFit::fingerprint`]).
pub fn fit_field(
    ctx: &Context,
    targets: &Targets,
    opts: &FieldFitOptions,
    session: Session<'_, FieldFit>,
) -> Result<FieldFitResult> {
    let setup = Instant::now();
    let mut fitter = FieldFit::fitter(ctx, targets, opts)?;
    let setup_s = setup.elapsed().as_secs_f64();
    let end = session.run(
        &mut fitter,
        (opts.iterations, opts.log_every),
        to_next_log(opts.log_every),
    )?;
    Ok(FieldFitResult {
        timings: FieldFitTimings {
            setup_s,
            log_s: end.logging_seconds,
            iterations_s: end.seconds,
            regrowths: fitter.regrowths(),
        },
        field: fitter.into_fit().into_field(),
        log: end.log,
        iterations: end.last,
        first_iteration: end.first,
    })
}

impl LogRow for FieldFitLog {
    fn iteration(&self) -> u32 {
        self.iteration
    }
    fn loss(&self) -> f64 {
        f64::from(self.total)
    }
    fn columns(&mut self, c: &mut dyn Columns) {
        c.u32("iteration", &mut self.iteration);
        c.f32("l_sil", &mut self.silhouette);
        c.f32("l_geo", &mut self.geo);
        c.f32("total", &mut self.total);
        c.f64("seconds", &mut self.seconds);
    }
}

/// A field fit in a session: its row is the losses of the logged iteration, its state the
/// field's parameters and Adam's moments (the samplers need nothing else: their random numbers
/// are keyed by (seed, iteration)).
impl Trainee for FieldFit {
    type Row = FieldFitLog;
    const KIND: FitKind = FitKind::Field;

    fn rows(
        &mut self,
        ctx: &Context,
        _first: u32,
        last: u32,
        _entries: u64,
        seconds: f64,
    ) -> Result<Vec<FieldFitLog>> {
        let (silhouette, geo) = self.read_losses(ctx)?;
        Ok(vec![FieldFitLog {
            iteration: last,
            silhouette,
            geo,
            total: self
                .opts
                .probe
                .total_loss(f64::from(silhouette), f64::from(geo)) as f32,
            seconds,
        }])
    }

    fn save_state(&self, ctx: &Context, w: &mut Writer) -> Result<()> {
        save_adam(
            ctx,
            self.field.params(),
            &self.adam,
            self.field.param_count(),
            w,
        )
    }

    fn restore_state(&mut self, ctx: &Context, r: &mut Reader<'_>) -> Result<()> {
        let n = self.field.param_count();
        restore_adam(ctx, self.field.params(), &self.adam, n, r, "the field")
    }
}

impl FieldFit {
    /// The fingerprint of a fit's inputs that a checkpoint of it must carry: the silhouettes,
    /// the cameras and every option (the field type among them) but the iteration count and
    /// the logging.
    pub fn fingerprint(targets: &Targets, opts: &FieldFitOptions) -> u64 {
        let mut f = Fingerprint::default();
        f.add_pod(&[targets.width, targets.height]);
        f.add_pod(&targets.masks);
        f.add(format!("{:?}", targets.cameras).as_bytes());
        let o = FieldFitOptions {
            iterations: 0,
            log_every: 0,
            ..*opts
        };
        f.add(format!("{o:?}").as_bytes());
        f.value()
    }
}

/// The prober's entry capacity for a count of `total` ([`crate::fit::with_headroom`]).
fn field_capacity(ctx: &Context, total: u64) -> Result<u64> {
    crate::fit::with_headroom(
        ctx,
        "a field fit's sphere probing",
        total,
        crate::primitives::binning::max_entries(ctx),
        "use fewer anchors or views, larger tiles or a smaller τ",
    )
}
