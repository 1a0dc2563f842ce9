//! Conveniences that render and read back: [`Renderer::render_views`],
//! [`Renderer::render_silhouettes`], in as few scenes as the device's storage bindings allow.

use super::{Renderer, views_per_scene};
use crate::camera::Camera;
use crate::error::Result;
use crate::gpu::Context;
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::method::Method;
use crate::raster::scene::Frames;
use crate::raster::settings::RasterSettings;

impl Renderer {
    /// Renders `mesh` from every camera by `method` and reads back images and aux: in one
    /// batch, or in as many as the device's storage bindings ask for (a batch's face setups,
    /// images and aux are one binding each).
    pub fn render_views(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
        method: Method,
    ) -> Result<Frames> {
        self.render_in_scenes(ctx, mesh, cameras, lighting, settings, method, false, true)
    }

    /// Renders `cameras` in as few scenes as the device's storage bindings allow (a scene
    /// holds every view's face setups, image and aux in one binding each), and joins their
    /// frames in camera order.
    #[allow(clippy::too_many_arguments)]
    fn render_in_scenes(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
        method: Method,
        silhouette_only: bool,
        cull: bool,
    ) -> Result<Frames> {
        let per_scene = views_per_scene(ctx, mesh.face_count() as u64, settings);
        let mut frames: Option<Frames> = None;
        // (No cameras: the scene's own error.)
        let parts: Vec<&[Camera]> = match cameras.len() {
            0 => vec![cameras],
            _ => cameras.chunks(per_scene).collect(),
        };
        for part in parts {
            let mut scene = self.prepare(ctx, mesh, part, lighting, settings)?;
            scene.set_silhouette_only(silhouette_only);
            self.run_with_cull(ctx, &mut scene, method, cull)?;
            let more = scene.read_frames(ctx)?;
            match &mut frames {
                None => frames = Some(more),
                Some(f) => {
                    f.images.extend(more.images);
                    f.aux.extend(more.aux);
                }
            }
        }
        Ok(frames.expect("at least one part"))
    }

    /// The silhouettes of `mesh` from every camera: the alpha of every output pixel, view-major,
    /// rendered as a silhouette ([`GpuScene::set_silhouette_only`](super::GpuScene::set_silhouette_only): no depth or colour work,
    /// the alpha of a full render bit for bit), unlit, by `method`.
    pub fn render_silhouettes(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        settings: &RasterSettings,
        method: Method,
    ) -> Result<Vec<f32>> {
        let frames = self.render_in_scenes(
            ctx,
            mesh,
            cameras,
            &Lighting::unlit(),
            settings,
            method,
            true,
            true,
        )?;
        Ok(frames.images.iter().map(|p| p[3]).collect())
    }

    /// As [`Renderer::render_views`] by brute force, choosing whether the fine pass culls by the
    /// grown boxes (it must make no difference; tests check that it makes none, bit for bit).
    #[cfg(feature = "test-knobs")]
    pub fn render_brute_views_with_cull(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
        cull: bool,
    ) -> Result<Frames> {
        self.render_in_scenes(
            ctx,
            mesh,
            cameras,
            lighting,
            settings,
            Method::Brute,
            false,
            cull,
        )
    }
}
