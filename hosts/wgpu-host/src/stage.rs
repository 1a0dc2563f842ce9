//! softvk's part of a frame: the one place that decides what softvk records.
//!
//! softvk renders the silhouettes of the application's vertex buffer (x, y, z, 1 per vertex:
//! bound with a stride of 4 floats) with guarded binning — the count gates the rest on the GPU,
//! so nothing is read back — and differentiates them against the application's upstream
//! gradient, writing dL/d(vertex positions) into the application's buffer, then copies its
//! silhouettes into the application's image buffer. Every buffer of the application is
//! borrowed ([`Context::import_buffer`]); softvk's own are its scene's and its backward's.

use std::cell::RefCell;

use softvk::camera::Camera;
use softvk::gpu::gate::IterationGate;
use softvk::gpu::{Buffer, Context, Recorder};
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::backward::{GradBuffers, GradIo};
use softvk::raster::gpu::{GpuScene, GuardedBins, Renderer};
use softvk::raster::settings::RasterSettings;
use softvk::raster::setup::VertexLayout;

use crate::HostError;
use crate::scene::{Scene, raw_buffer};

/// Tile edge of the binning.
const TILE: u32 = 8;

/// softvk's pipelines, its scene and backward buffers, and the application's buffers it borrows.
pub struct SoftvkStage {
    renderer: Renderer,
    scene: GpuScene,
    /// The guarded forward's bins.
    bins: GuardedBins,
    grads: GradBuffers,
    /// Recording a frame resets and arms the gate.
    gate: RefCell<IterationGate>,
    /// `Scene::upstream`, imported: the backward reads it.
    upstream: Buffer,
    /// `Scene::d_positions`, imported: the backward writes it.
    d_positions: Buffer,
    /// `Scene::image`, imported: softvk copies its silhouettes into it.
    image: Buffer,
}

impl SoftvkStage {
    /// Builds softvk's pipelines and buffers on `ctx` for `mesh` (its faces; the positions come
    /// from the application's vertex buffer every frame) seen from `cameras`, and imports the
    /// scene's buffers without taking ownership. softvk's setup uploads (faces, views, the
    /// backward's adjacency) submit on the adopted queue here, from this thread, before any
    /// frame; the frames make no submission.
    ///
    /// # Safety
    /// `ctx` was adopted from the device `scene`'s buffers were made on, nothing else submits
    /// to its queue while this runs, and `scene` outlives the stage and every frame recorded
    /// with it.
    pub unsafe fn new(
        ctx: &Context,
        scene: &Scene,
        mesh: &Mesh,
        cameras: &[Camera],
        settings: &RasterSettings,
    ) -> Result<Self, HostError> {
        let renderer = Renderer::new(ctx)?;
        let mut gpu = renderer.prepare(ctx, mesh, cameras, &Lighting::unlit(), settings)?;
        gpu.set_silhouette_only(true);
        let [upstream_bytes, position_bytes, _] = GradIo::sizes(&gpu);
        // SAFETY: the wgpu buffers are storage buffers of `ctx`'s device with these sizes bound
        // (Scene::new: 16 bytes per vertex, per pixel; 12 per vertex), and they outlive the stage
        // (the caller's contract).
        let (vertices, upstream, d_positions, image) = unsafe {
            (
                ctx.import_buffer(
                    raw_buffer(&scene.vertices)?,
                    16 * u64::from(gpu.vertex_count()),
                    "vertices (wgpu)",
                ),
                ctx.import_buffer(
                    raw_buffer(&scene.upstream)?,
                    upstream_bytes,
                    "upstream (wgpu)",
                ),
                ctx.import_buffer(
                    raw_buffer(&scene.d_positions)?,
                    position_bytes,
                    "d_positions (wgpu)",
                ),
                ctx.import_buffer(raw_buffer(&scene.image)?, upstream_bytes, "image (wgpu)"),
            )
        };
        gpu.bind_positions(
            vertices,
            VertexLayout {
                offset: 0,
                stride: 4,
            },
        )?;
        // The capacity: every face in every tile of every view, so no deformation can outgrow
        // it (a small scene; a large one would size from `Renderer::count_entries` with
        // headroom and grow when the gate says so).
        let tiles = u64::from(settings.width.div_ceil(TILE) * settings.height.div_ceil(TILE));
        let capacity = u64::from(gpu.face_count()) * tiles * cameras.len() as u64;
        let bins = renderer.reserve_guarded(ctx, &gpu, TILE, capacity)?;
        let mut grads = GradBuffers::guarded(ctx, &gpu, &bins)?;
        grads.set_alpha_only(true);
        Ok(Self {
            gate: RefCell::new(IterationGate::new(ctx)?),
            renderer,
            scene: gpu,
            bins,
            grads,
            upstream,
            d_positions,
            image,
        })
    }

    /// Records softvk's work for frame `frame`: the guarded forward of the application's
    /// vertices, the backward into the application's gradient buffer, and the copy of the
    /// silhouettes into its image buffer. The caller brackets it with
    /// [`Recorder::full_barrier`] (see `App::encode_softvk`), so this orders nothing against
    /// wgpu's passes itself.
    pub fn record(&self, rec: &mut Recorder<'_>, frame: u32) -> Result<(), HostError> {
        let mut gate = self.gate.borrow_mut();
        gate.reset();
        let io = GradIo {
            upstream: self.upstream.whole(),
            positions: self.d_positions.whole(),
            colors: self.grads.io().colors,
        };
        let (renderer, grads) = (&self.renderer, &self.grads);
        renderer.record_forward_guarded(
            rec,
            &self.scene,
            &self.bins,
            &mut gate,
            frame,
            |rec, binned| renderer.grad_kernels().record(rec, &binned, grads, &io),
        )?;
        rec.copy(self.scene.output(), 0, &self.image, 0, self.image.size());
        Ok(())
    }

    /// Whether the last frames' entries fitted the capacity (a read-back: softvk's convenience,
    /// after the frames).
    pub fn capacity_held(&self, ctx: &Context) -> Result<bool, HostError> {
        Ok(self.gate.borrow().read(ctx)?.stopped.is_none())
    }
}
