//! Mesh deformation from silhouettes, SoftRas's `demo_deform.py` on the GPU: a template's
//! vertices, parameterized by [`Deform`] (bounded displacement + centroid), are fitted to target
//! silhouettes seen from known cameras by Adam on `1 − IoU + λ_lap Laplacian + λ_flat flatten`.
//!
//! One iteration is two submissions and one 4-byte read-back:
//! 1. deform forward → face setup → binning count;
//! 2. (the host reads the entry count, which sizes the bins exactly) sort → tiled fine pass →
//!    IoU loss and dL/d(image) → tiled backward on the same bins → Laplacian and flatten
//!    gradients accumulated → deform backward → Adam step.
//!
//! Losses and per-view IoUs are read back only every `log_every` iterations. The silhouette
//! loss has no colour gradient, so the lighting's share of the position gradient (added on the
//! host in [`crate::raster::backward::GradKernels::finish`]) is zero and the GPU's position
//! gradient is complete.

use std::time::Instant;

use glam::{DMat3, DVec3};

use super::{Adam, AdamOptions, Deform, GradOut, Regularizers, SilhouetteLoss};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::{Context, MemoryKind};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::backward::GradBuffers;
use crate::raster::gpu::{Method, Renderer};
use crate::raster::reference::{Alpha, RasterSettings, Rgb};

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
    /// Read the losses back every this many iterations (and after the last).
    pub log_every: u32,
    /// Also read back the predicted alpha images at every logged iteration (for progress
    /// pictures).
    pub snapshots: bool,
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
            snapshots: false,
        }
    }
}

/// One logged iteration.
#[derive(Clone, Debug, PartialEq)]
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
    /// Wall time of the iterations.
    pub seconds: f64,
}

/// The template SoftRas's demo starts from, generated in code: an icosphere (3 subdivisions,
/// 642 vertices) of radius 0.5, turned so that no coordinate is exactly zero (the
/// parameterization keeps a zero coordinate at zero forever).
pub fn default_template() -> Mesh {
    let mut mesh = Mesh::icosphere(3);
    let rot = DMat3::from_euler(glam::EulerRot::XYZ, 0.31, 0.47, 0.13);
    for p in &mut mesh.positions {
        let v = rot * DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])) * 0.5;
        *p = [v.x as f32, v.y as f32, v.z as f32];
    }
    mesh
}

/// Fits `template` to `targets` (one f32 mask per pixel, view-major, `W × H` per view, W and H
/// from the options) seen from `cameras`. `progress` is called after every logged iteration
/// with the log entry, the per-view (soft) IoUs and, with `snapshots`, the predicted alpha per
/// pixel (view-major) the iteration rendered; it may return `false` to stop early.
pub fn fit_mesh(
    ctx: &Context,
    template: &Mesh,
    cameras: &[Camera],
    targets: &[f32],
    opts: &MeshFitOptions,
    mut progress: impl FnMut(&FitLog, &[f32], Option<&[f32]>) -> bool,
) -> Result<MeshFitResult> {
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
    template.validate()?;
    let method = Method::Tiled { tile: opts.tile };
    let renderer = Renderer::new(ctx)?;
    let mut scene = renderer.prepare(ctx, template, cameras, &Lighting::unlit(), s)?;
    let deform = Deform::new(ctx, &template.positions)?;
    let regs = Regularizers::new(ctx, &template.faces, template.vertex_count())?;
    let sil = SilhouetteLoss::new(ctx, views as u32, s.width, s.height)?;
    let adam = Adam::new(ctx, deform.param_count(), opts.adam)?;
    let params = ctx.create_buffer("fit params", 4 * deform.param_count(), MemoryKind::Device)?;
    let d_params =
        ctx.create_buffer("fit d_params", 4 * deform.param_count(), MemoryKind::Device)?;
    let target_buf = ctx.upload_buffer("fit targets", targets)?;
    // Zero displacement and centre: the template itself.
    ctx.submit_and_wait(|rec| {
        rec.fill(params.whole(), 0);
        adam.record_reset(rec);
        Ok(())
    })?;

    // The first forward sizes the bins; the backward's buffers follow them.
    let start = Instant::now();
    let mut log = Vec::new();
    let mut gb: Option<GradBuffers> = None;
    let grads = renderer.grad_kernels();
    for it in 1..=opts.iterations {
        ctx.submit_and_wait(|rec| {
            deform.record_forward(rec, params.whole(), scene.positions.whole())?;
            renderer.record_setup_and_count(ctx, rec, &mut scene, opts.tile)
        })?;
        let entries = renderer.finish_count(ctx, &mut scene, opts.tile)?;
        let stale = gb.as_ref().is_none_or(|g| g.entry_capacity() < entries);
        if stale {
            gb = Some(GradBuffers::new(ctx, &scene, method)?);
        }
        let g = gb.as_ref().expect("made above");
        ctx.submit_and_wait(|rec| {
            renderer.record_rest(rec, &scene)?;
            sil.record(
                rec,
                scene.output().whole(),
                target_buf.whole(),
                Some(GradOut::write(g.d_image.whole())),
            )?;
            grads.record(rec, &scene, g)?;
            regs.record_laplacian(
                rec,
                scene.positions.whole(),
                Some(GradOut::accumulate(
                    g.position_grads.whole(),
                    opts.laplacian,
                )),
            )?;
            regs.record_flatten(
                rec,
                scene.positions.whole(),
                Some(GradOut::accumulate(g.position_grads.whole(), opts.flatten)),
            )?;
            deform.record_backward(
                rec,
                params.whole(),
                g.position_grads.whole(),
                d_params.whole(),
            )?;
            adam.record_step(rec, params.whole(), d_params.whole(), it)
        })?;
        if it % opts.log_every == 0 || it == opts.iterations {
            let silhouette = sil.read_loss(ctx)?;
            let r = regs.read_losses(ctx)?;
            let entry = FitLog {
                iteration: it,
                silhouette,
                laplacian: r.laplacian,
                flatten: r.flatten,
                total: silhouette + opts.laplacian * r.laplacian + opts.flatten * r.flatten,
                seconds: start.elapsed().as_secs_f64(),
            };
            let ious = sil.read_ious(ctx)?;
            let alphas: Option<Vec<f32>> = if opts.snapshots {
                let rgba: Vec<[f32; 4]> = ctx.read_buffer(scene.output(), 0, views * px)?;
                Some(rgba.iter().map(|p| p[3]).collect())
            } else {
                None
            };
            let go_on = progress(&entry, &ious, alphas.as_deref());
            log.push(entry);
            if !go_on {
                break;
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    // The positions the last Adam step produced.
    ctx.submit_and_wait(|rec| deform.record_forward(rec, params.whole(), scene.positions.whole()))?;
    let positions: Vec<[f32; 3]> = ctx.read_buffer(&scene.positions, 0, template.vertex_count())?;
    let mut mesh = template.clone();
    mesh.positions = positions;
    Ok(MeshFitResult { mesh, log, seconds })
}
