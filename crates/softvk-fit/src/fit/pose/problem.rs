//! [`PoseProblem`]: the loss and gradient at any pose, the chain on the host in f64 (landscapes
//! and studies).

use glam::DVec3;

use super::{Pose, centroid, pose_gradient};
use crate::fit::posed::check_target;

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::fit::ImageMse;
use crate::gpu::GradOut;
use crate::gpu::{Buffer, Context, MemoryKind};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::backward::GradBuffers;
use crate::raster::gpu::{GpuScene, Method, Renderer};
use crate::raster::settings::{ColorMode, RasterSettings};

/// One evaluation of the loss and its gradient at a pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Evaluation {
    /// The image MSE (GPU, f32).
    pub loss: f64,
    /// dL/d(ω, t).
    pub gradient: [f64; 6],
}

/// One mesh, one camera and one target on the GPU, ready to evaluate the loss and its pose
/// gradient at any pose and σ/γ (see the [module docs](super) for the stages).
pub struct PoseProblem {
    renderer: Renderer,
    scene: GpuScene,
    mse: ImageMse,
    target: Buffer,
    /// Host-visible staging of the posed positions, then the lit colours (copied into the
    /// scene's buffers by the first submission of each evaluation).
    staging: Buffer,
    /// Bytes of positions at the start of `staging`, and of colours after them.
    position_bytes: u64,
    color_bytes: u64,
    grads: Option<GradBuffers>,
    rest: Vec<DVec3>,
    centre: DVec3,
    tile: u32,
}

impl PoseProblem {
    /// Uploads `mesh` (at rest), `camera`, `lighting` and `target` (RGBA per pixel, row 0 at
    /// the top, `settings.width × settings.height`).
    pub fn new(
        ctx: &Context,
        mesh: &Mesh,
        camera: &Camera,
        lighting: &Lighting,
        target: &[[f32; 4]],
        settings: &RasterSettings,
        tile: u32,
    ) -> Result<Self> {
        crate::raster::gpu::Method::check_tile(tile)?;
        mesh.validate()?;
        settings.validate()?;
        check_target(target, settings)?;
        let renderer = Renderer::new(ctx)?;
        let scene =
            renderer.prepare(ctx, mesh, std::slice::from_ref(camera), lighting, settings)?;
        let rest = scene.host_meshes()[0].positions.clone();
        let position_bytes = 12 * rest.len() as u64;
        // As `GpuScene::colors` holds them: 4 floats per colour.
        let color_bytes = 16
            * match settings.color_mode {
                ColorMode::Surface => mesh.textures.len() as u64,
                ColorMode::Vertex => rest.len() as u64,
            };
        let staging = ctx.create_buffer(
            "pose staging",
            position_bytes + color_bytes,
            MemoryKind::Upload,
        )?;
        Ok(Self {
            mse: ImageMse::new(ctx, 1, settings.width, settings.height)?,
            target: ctx.upload_buffer("pose target", target)?,
            staging,
            position_bytes,
            color_bytes,
            renderer,
            scene,
            grads: None,
            centre: centroid(&rest),
            rest,
            tile,
        })
    }

    /// Replaces the target (same size, finite).
    pub fn set_target(&mut self, ctx: &Context, target: &[[f32; 4]]) -> Result<()> {
        check_target(target, self.scene.settings())?;
        ctx.write_buffer(&self.target, 0, target)
    }

    /// The point rotations turn about (the rest mesh's vertex centroid).
    pub fn centre(&self) -> DVec3 {
        self.centre
    }

    /// Renders the mesh at `pose` with σ and γ, and returns the MSE against the target and
    /// dL/d(ω, t). The image stays on the GPU for [`PoseProblem::read_image`].
    pub fn evaluate(
        &mut self,
        ctx: &Context,
        pose: &Pose,
        sigma: f64,
        gamma: f64,
    ) -> Result<Evaluation> {
        if !pose.is_finite() {
            return Err(Error::Input(format!("the pose {pose:?} is not finite")));
        }
        self.set_pose(pose)?;
        let scene = &mut self.scene;
        scene.set_blur(sigma, gamma)?;
        let (renderer, tile) = (&self.renderer, self.tile);
        let (staging, split, colors) = (&self.staging, self.position_bytes, self.color_bytes);
        ctx.submit_and_wait(|rec| {
            rec.copy(staging, 0, scene.positions(), 0, split);
            rec.copy(staging, split, scene.colors(), 0, colors);
            Ok(())
        })?;
        // The exact-sized tiled forward (its count is read back: the host round trip of this
        // loop is the pose chain's anyway).
        let binned = renderer.run(ctx, scene, Method::Tiled { tile })?.binned();
        let scene = binned.scene();
        let entries = binned.entries();
        if self
            .grads
            .as_ref()
            .is_none_or(|g| g.entry_capacity() < entries)
        {
            // Drop the old buffers before making the larger ones.
            self.grads = None;
            self.grads = Some(GradBuffers::new(ctx, &binned)?);
        }
        let gb = self.grads.as_ref().expect("made above");
        let io = gb.io();
        let kernels = renderer.grad_kernels();
        ctx.submit_and_wait(|rec| {
            self.mse.record(
                rec,
                scene.output().whole(),
                self.target.whole(),
                Some(GradOut::write(io.upstream)),
            )?;
            kernels.record(rec, &binned, gb, &io)
        })?;
        let loss = f64::from(self.mse.read_loss(ctx)?);
        let g = kernels.finish(ctx, scene, gb, &io, false)?;
        Ok(Evaluation {
            loss,
            gradient: pose_gradient(&self.rest, self.centre, pose, &g.positions),
        })
    }

    /// The last evaluation's image: RGBA per pixel, row 0 at the top.
    pub fn read_image(&self, ctx: &Context) -> Result<Vec<[f32; 4]>> {
        let s = self.scene.settings();
        ctx.read_buffer(self.scene.output(), 0, (s.width * s.height) as usize)
    }

    /// Uploads the posed positions and the colours lit with the posed normals, and keeps the
    /// f64 mesh the backward's host share reads in step with what the GPU renders.
    fn set_pose(&mut self, pose: &Pose) -> Result<()> {
        let posed: Vec<[f32; 3]> = pose
            .apply(&self.rest, self.centre)
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect();
        let colors = self.scene.relight(0, &posed)?;
        let (split, color_bytes) = (self.position_bytes as usize, self.color_bytes as usize);
        let bytes = self
            .staging
            .mapped_mut()
            .ok_or_else(|| Error::Limit("upload memory is not host-mapped".into()))?;
        let (p, c) = (
            bytemuck::cast_slice::<_, u8>(&posed),
            bytemuck::cast_slice::<_, u8>(&colors),
        );
        if p.len() != split || c.len() != color_bytes {
            return Err(Error::Input(format!(
                "pose staging: {} position and {} colour bytes, expected {split} and \
                 {color_bytes}",
                p.len(),
                c.len(),
            )));
        }
        bytes[..split].copy_from_slice(p);
        bytes[split..split + c.len()].copy_from_slice(c);
        Ok(())
    }
}
