//! [`Renderer::prepare`] and [`Renderer::prepare_batch`]: the inputs validated and checked
//! against the device's limits, lit on the host and uploaded as a [`GpuScene`].

use super::{Renderer, may_need_passes};
use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::{Context, MemoryKind};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::fine::{CARRY_BYTES, PixelAux};
use crate::raster::reference::MeshF64;
use crate::raster::scene::{GpuScene, lit_batch};
use crate::raster::settings::{ColorMode, RasterSettings};
use crate::raster::setup::{FaceSetupKernel, GpuFaceSetup, GpuView, VertexLayout};

impl Renderer {
    /// Validates the inputs (as the CPU twin does), checks them against the device's limits, and
    /// uploads the scene: `mesh` seen from every camera.
    pub fn prepare(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
    ) -> Result<GpuScene> {
        let views: Vec<(usize, Camera)> = cameras.iter().map(|c| (0, *c)).collect();
        self.prepare_batch(ctx, std::slice::from_ref(mesh), &views, lighting, settings)
    }

    /// A batch of meshes of equal topology (the same faces, vertex count and texture
    /// resolution; positions and colours may differ), each seen from any number of views:
    /// `views` pairs a mesh index with a camera. Everything renders in one submission per view
    /// group; the frames come back in `views` order.
    pub fn prepare_batch(
        &self,
        ctx: &Context,
        meshes: &[Mesh],
        views: &[(usize, Camera)],
        lighting: &Lighting,
        settings: &RasterSettings,
    ) -> Result<GpuScene> {
        let Some(mesh) = meshes.first() else {
            return Err(Error::Input("no mesh to render".into()));
        };
        let cameras: Vec<Camera> = views.iter().map(|v| v.1).collect();
        let mut gpu_views = checked_views(mesh, &cameras, settings)?;
        for (i, m) in meshes.iter().enumerate().skip(1) {
            m.validate()?;
            if m.faces != mesh.faces
                || m.vertex_count() != mesh.vertex_count()
                || m.texture_res != mesh.texture_res
            {
                return Err(Error::Input(format!(
                    "mesh {i} of the batch does not share mesh 0's topology (faces, vertex \
                     count and texture resolution must be equal)"
                )));
            }
        }
        for (gv, (m, _)) in gpu_views.iter_mut().zip(views) {
            if *m >= meshes.len() {
                return Err(Error::Input(format!(
                    "a view shows mesh {m} of a batch of {}",
                    meshes.len()
                )));
            }
            gv.mesh = *m as u32;
        }
        let face_count = u32::try_from(mesh.face_count())
            .map_err(|_| Error::Limit(format!("{} faces exceed 2^32", mesh.face_count())))?;
        let vertex_count = u32::try_from(mesh.vertex_count())
            .map_err(|_| Error::Limit(format!("{} vertices exceed 2^32", mesh.vertex_count())))?;
        let view_count = u32::try_from(views.len())
            .map_err(|_| Error::Limit(format!("{} views exceed 2^32", views.len())))?;
        let batch = meshes.len() as u64;
        let scale = if settings.antialias { 2 } else { 1 };
        let (w, h) = (settings.width * scale, settings.height * scale);
        let rendered = u64::from(w) * u64::from(h) * u64::from(view_count);
        let outputs =
            u64::from(settings.width) * u64::from(settings.height) * u64::from(view_count);
        let pairs = u64::from(face_count) * u64::from(view_count);
        let max_range = u64::from(ctx.info().limits.max_storage_buffer_range);
        let texels = match settings.color_mode {
            ColorMode::Surface => mesh.textures.len() as u64,
            ColorMode::Vertex => mesh.vertex_count() as u64,
        };
        for (what, bytes) in [
            ("image", 16 * rendered),
            (
                "face setup",
                pairs * std::mem::size_of::<GpuFaceSetup>() as u64,
            ),
            ("colour", 12 * texels * batch),
            ("position", 12 * mesh.vertex_count() as u64 * batch),
            (
                "screen vertex",
                16 * mesh.vertex_count() as u64 * u64::from(view_count),
            ),
        ] {
            if bytes > max_range {
                return Err(Error::Limit(format!(
                    "the {what} buffer would need {bytes} bytes, over this device's \
                     maxStorageBufferRange ({max_range})"
                )));
            }
        }
        if rendered > u64::from(u32::MAX) || u64::from(vertex_count) * batch > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "{rendered} rendered pixels or {} batched vertices exceed 2^32",
                u64::from(vertex_count) * batch
            )));
        }

        let positions: Vec<f32> = meshes
            .iter()
            .flat_map(|m| m.positions.iter().flatten().copied())
            .collect();
        let faces: Vec<u32> = mesh.faces.iter().flatten().copied().collect();
        let colors = lit_batch(meshes, lighting, settings.color_mode);
        Ok(GpuScene {
            settings: *settings,
            face_count,
            vertex_count,
            view_count,
            texture_res: mesh.texture_res,
            width: w,
            height: h,
            positions: ctx.upload_buffer("mesh positions", &positions)?,
            position_layout: VertexLayout::default(),
            faces: ctx.upload_buffer("mesh faces", &faces)?,
            colors: ctx.upload_buffer("lit colours", &colors)?,
            views: ctx.upload_buffer("views", &gpu_views)?,
            screen: ctx.create_buffer(
                "screen vertices",
                FaceSetupKernel::screen_bytes(vertex_count, view_count).max(16),
                MemoryKind::Device,
            )?,
            setups: ctx.create_buffer(
                "face setups",
                pairs * std::mem::size_of::<GpuFaceSetup>() as u64,
                MemoryKind::Device,
            )?,
            image: ctx.create_buffer("image", 16 * rendered, MemoryKind::Device)?,
            aux: ctx.create_buffer(
                "pixel aux",
                std::mem::size_of::<PixelAux>() as u64 * rendered,
                MemoryKind::Device,
            )?,
            carry: ctx.create_buffer(
                "pixel carry",
                if may_need_passes(ctx, face_count) {
                    CARRY_BYTES * rendered
                } else {
                    CARRY_BYTES
                },
                MemoryKind::Device,
            )?,
            small: if settings.antialias {
                Some(ctx.create_buffer("image (anti-aliased)", 16 * outputs, MemoryKind::Device)?)
            } else {
                None
            },
            bins: Vec::new(),
            last_run: None,
            silhouette_only: false,
            meshes: meshes.iter().map(MeshF64::from_mesh).collect(),
            lighting: lighting.clone(),
            views_host: views.to_vec(),
        })
    }
}
/// Validates a render's inputs (mesh, settings, at least one camera) and builds the GPU views.
fn checked_views(
    mesh: &Mesh,
    cameras: &[Camera],
    settings: &RasterSettings,
) -> Result<Vec<GpuView>> {
    mesh.validate()?;
    settings.validate()?;
    if cameras.is_empty() {
        return Err(Error::Input("no camera to render from".into()));
    }
    cameras.iter().map(GpuView::new).collect()
}
