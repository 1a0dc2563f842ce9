//! The shared iteration loop (`fit::driver`) driving a fit written here, outside softvk, from
//! nothing but its recording and its parameters: a small mesh's vertex positions themselves (no
//! deformation parameterization) fitted to silhouettes by 1 − IoU and Adam. The driver brings
//! the submissions of `k` iterations, the gate's regrowths and the loop.

mod common;

use softvk::Result;
use softvk::camera::{Camera, Projection};
use softvk::fit::driver::{self, Fit, Fitter};
use softvk::fit::{Adam, AdamOptions, GradOut, SilhouetteLoss, max_entry_capacity};
use softvk::fit::{reserve_guarded, with_headroom};
use softvk::gpu::gate::IterationGate;
use softvk::gpu::{Buffer, Context, Recorder};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::backward::GradBuffers;
use softvk::raster::gpu::{GpuScene, GuardedBins, Method, Renderer};
use softvk::raster::settings::{Alpha, Dist, RasterSettings, Rgb};

const SIZE: u32 = 24;
const TILE: u32 = 8;

/// The fit: the scene's positions are its parameters.
struct VertexFit {
    renderer: Renderer,
    scene: GpuScene,
    bins: GuardedBins,
    sil: SilhouetteLoss,
    adam: Adam,
    targets: Buffer,
    grads: GradBuffers,
    capacity: u64,
    max_capacity: u64,
}

impl Fit for VertexFit {
    const NAME: &'static str = "vertex fit";

    fn record_iteration(
        &mut self,
        rec: &mut Recorder<'_>,
        gate: &mut IterationGate,
        it: u32,
        _row: u32,
    ) -> Result<()> {
        let Self {
            renderer,
            scene,
            sil,
            adam,
            targets,
            grads,
            bins,
            ..
        } = self;
        renderer.record_forward_guarded(rec, scene, bins, gate, it, |rec, binned| {
            let scene = binned.scene();
            let io = grads.io();
            sil.record(
                rec,
                scene.output().whole(),
                targets.whole(),
                Some(GradOut::write(io.upstream)),
            )?;
            renderer.grad_kernels().record(rec, &binned, grads, &io)?;
            adam.record_step(rec, scene.positions().whole(), io.positions, it)
        })
    }

    fn capacity(&self) -> u64 {
        self.capacity
    }

    fn grow(&mut self, ctx: &Context, total: u64) -> Result<()> {
        let capacity = with_headroom(ctx, "a vertex fit", total, self.max_capacity, "")?;
        (self.bins, self.grads) =
            reserve_guarded(ctx, &self.renderer, &self.scene, TILE, capacity, true)?;
        self.capacity = capacity;
        Ok(())
    }
}

fn cameras() -> Vec<Camera> {
    [0.0, 90.0, 200.0]
        .iter()
        .map(|&az| Camera {
            projection: Projection::Perspective {
                viewing_angle_deg: 15.0,
            },
            ..Camera::from_angles(2.732, 30.0, az)
        })
        .collect()
}

fn settings() -> RasterSettings {
    RasterSettings {
        width: SIZE,
        height: SIZE,
        sigma: 1e-3,
        rgb: Rgb::Hard,
        ..RasterSettings::default()
    }
}

/// An icosphere(1) of radius 0.4 fitted to a box's silhouettes, its bins reserved for
/// `capacity` entries at first.
fn vertex_fit(ctx: &Context, capacity: u64) -> Fitter<'_, VertexFit> {
    let hard = RasterSettings {
        dist: Dist::Hard,
        alpha: Alpha::Hard,
        ..settings()
    };
    let renderer = Renderer::new(ctx).unwrap();
    let targets = renderer
        .render_silhouettes(
            ctx,
            &Mesh::cuboid([0.35, 0.25, 0.3]),
            &cameras(),
            &hard,
            Method::default(),
        )
        .unwrap();
    let mut sphere = Mesh::icosphere(1);
    sphere
        .positions
        .iter_mut()
        .for_each(|p| p.iter_mut().for_each(|c| *c *= 0.4));
    let mut scene = renderer
        .prepare(ctx, &sphere, &cameras(), &Lighting::unlit(), &settings())
        .unwrap();
    scene.set_silhouette_only(true);
    let max_capacity = max_entry_capacity(ctx, &renderer, &scene);
    let (bins, grads) = reserve_guarded(ctx, &renderer, &scene, TILE, capacity, true).unwrap();
    let views = cameras().len() as u32;
    let adam = Adam::new(
        ctx,
        3 * sphere.vertex_count() as u64,
        AdamOptions {
            lr: 0.01,
            ..AdamOptions::default()
        },
    )
    .unwrap();
    ctx.submit_and_wait(|rec| {
        adam.record_reset(rec);
        Ok(())
    })
    .unwrap();
    let fit = VertexFit {
        sil: SilhouetteLoss::new(ctx, views, SIZE, SIZE).unwrap(),
        adam,
        targets: ctx.upload_buffer("targets", &targets).unwrap(),
        grads,
        capacity,
        max_capacity,
        renderer,
        scene,
        bins,
    };
    Fitter::from_fit(ctx, fit).unwrap()
}

fn positions(fitter: &Fitter<'_, VertexFit>) -> Vec<[f32; 3]> {
    let n = fitter.scene.vertex_count() as usize;
    fitter
        .ctx()
        .read_buffer(fitter.scene.positions(), 0, n)
        .unwrap()
}

/// 30 iterations, 4 per submission: the spans, the falling loss, and after a stop the rest.
fn drive(
    fitter: &mut Fitter<'_, VertexFit>,
    first: u32,
    stop_after: u32,
) -> (u32, Vec<[u32; 2]>, Vec<f32>) {
    let (mut spans, mut losses) = (Vec::new(), Vec::new());
    let ran = fitter
        .drive(
            first,
            30,
            |_, it| Ok(driver::to_next_log(it, 4)),
            |fitter, first, last| {
                spans.push([first, last]);
                losses.push(fitter.sil.read_loss(fitter.ctx())?);
                Ok(last < stop_after)
            },
        )
        .unwrap();
    (ran, spans, losses)
}

#[test]
fn a_fit_written_outside_runs_through_the_driver_with_its_recording_alone() {
    let Some(gpu) = common::gpu() else { return };
    // Ample capacity: no regrowth.
    let mut ample = vertex_fit(&gpu, 1 << 20);
    let (ran, spans, losses) = drive(&mut ample, 1, u32::MAX);
    assert_eq!(ran, 30);
    let expected: Vec<[u32; 2]> = (0..8).map(|k| [4 * k + 1, (4 * k + 4).min(30)]).collect();
    assert_eq!(spans, expected, "k = 4 per submission, the last one short");
    assert_eq!(ample.regrowths(), 0);
    assert!(
        losses[7] < 0.5 * losses[0],
        "1 − IoU fell from {} to only {}",
        losses[0],
        losses[7]
    );
    // One entry at first: the gate stops the first iteration, the fit grows and runs it again,
    // and the positions end bit for bit as the fit that never stopped.
    let mut tight = vertex_fit(&gpu, 1);
    let (ran, spans, tight_losses) = drive(&mut tight, 1, u32::MAX);
    assert_eq!((ran, spans.len()), (30, 8));
    assert!(
        tight.regrowths() >= 1,
        "the gate never stopped an iteration"
    );
    assert!(tight.capacity > 1);
    assert_eq!(positions(&tight), positions(&ample));
    assert_eq!(tight_losses, losses);
    // Stopped by the callback after iteration 12, then driven on from 13: the same end.
    let mut stopped = vertex_fit(&gpu, 1 << 20);
    let (ran, spans, _) = drive(&mut stopped, 1, 12);
    assert_eq!((ran, spans.last().copied()), (12, Some([9, 12])));
    let (ran, spans, _) = drive(&mut stopped, ran + 1, u32::MAX);
    assert_eq!((ran, spans[0]), (30, [13, 16]));
    assert_eq!(positions(&stopped), positions(&ample));
}

#[test]
fn the_driver_refuses_iterations_that_do_not_count_from_1() {
    let Some(gpu) = common::gpu() else { return };
    let mut fitter = vertex_fit(&gpu, 1 << 20);
    for (first, last) in [(0, 3), (4, 3)] {
        let err = fitter.run(first, last, None).unwrap_err();
        assert!(matches!(err, softvk::Error::Misuse(_)), "{err}");
    }
}
