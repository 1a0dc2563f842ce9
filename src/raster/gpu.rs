//! The GPU forward as a script of stages, for the CLI, tests and benchmarks: light on the host
//! (f64, as SoftRas lights before projection) → upload → face setup → brute-force fine pass →
//! 2×2 average with anti-aliasing → read back. [`Renderer`] makes the pipelines once.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, MemoryKind};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::raster::brute::{BruteBindings, BruteRaster, PixelAux};
use crate::raster::reference::{ColorMode, FaceColors, RasterSettings};
use crate::raster::setup::{FaceSetupKernel, GpuFaceSetup, GpuView};

/// One GPU render's results, for every view.
#[derive(Clone, Debug, PartialEq)]
pub struct Frames {
    /// Output width in pixels.
    pub width: u32,
    /// Output height in pixels.
    pub height: u32,
    /// RGBA per output pixel, view-major, row-major, row 0 at the top.
    pub images: Vec<[f32; 4]>,
    /// Width of the rendered image the aux buffer describes (2× with anti-aliasing).
    pub rendered_width: u32,
    /// Height of the rendered image.
    pub rendered_height: u32,
    /// The forward state per *rendered* pixel (see [`PixelAux`]).
    pub aux: Vec<PixelAux>,
}

impl Frames {
    /// The image of view `v`.
    pub fn image(&self, v: usize) -> &[[f32; 4]] {
        let n = (self.width * self.height) as usize;
        &self.images[v * n..(v + 1) * n]
    }
}

/// The forward's pipelines, made once per context.
pub struct Renderer {
    setup: FaceSetupKernel,
    brute: BruteRaster,
}

/// A mesh and its lit colours, uploaded.
struct SceneBuffers {
    positions: Buffer,
    faces: Buffer,
    colors: Buffer,
}

/// Lights on the host in f64 and rounds to the packed f32 triples the kernels read.
fn lit_colors(mesh: &Mesh, lighting: &Lighting, mode: ColorMode) -> Vec<f32> {
    let colors = match FaceColors::new(mesh, lighting, mode) {
        FaceColors::Surface { texels, .. } => texels,
        FaceColors::Vertex { colors, .. } => colors,
    };
    colors.iter().flatten().map(|&c| c as f32).collect()
}

impl Renderer {
    /// Builds every pipeline of the forward.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            setup: FaceSetupKernel::new(ctx)?,
            brute: BruteRaster::new(ctx)?,
        })
    }

    /// Positions and faces as the packed triples the kernels read.
    fn upload_geometry(ctx: &Context, mesh: &Mesh) -> Result<(Buffer, Buffer)> {
        let positions: Vec<f32> = mesh.positions.iter().flatten().copied().collect();
        let faces: Vec<u32> = mesh.faces.iter().flatten().copied().collect();
        Ok((
            ctx.upload_buffer("mesh positions", &positions)?,
            ctx.upload_buffer("mesh faces", &faces)?,
        ))
    }

    fn upload(
        ctx: &Context,
        mesh: &Mesh,
        lighting: &Lighting,
        settings: &RasterSettings,
    ) -> Result<SceneBuffers> {
        let (positions, faces) = Self::upload_geometry(ctx, mesh)?;
        Ok(SceneBuffers {
            positions,
            faces,
            colors: ctx.upload_buffer(
                "lit colours",
                &lit_colors(mesh, lighting, settings.color_mode),
            )?,
        })
    }

    /// Renders `mesh` from every camera with the brute-force kernel and reads back images and aux.
    /// Inputs are validated as the CPU twin validates them.
    pub fn render_brute_views(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
    ) -> Result<Frames> {
        self.render_brute_views_with_cull(ctx, mesh, cameras, lighting, settings, true)
    }

    /// As [`Renderer::render_brute_views`], choosing whether the fine pass culls by the grown
    /// boxes (it must make no difference; tests check that it makes none, bit for bit).
    pub fn render_brute_views_with_cull(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
        cull: bool,
    ) -> Result<Frames> {
        let views = checked_views(mesh, cameras, settings)?;
        let face_count = u32::try_from(mesh.face_count())
            .map_err(|_| Error::Limit(format!("{} faces exceed 2^32", mesh.face_count())))?;
        let view_count = views.len() as u32;
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
            ("colour", 12 * texels),
            ("position", 12 * mesh.vertex_count() as u64),
        ] {
            if bytes > max_range {
                return Err(Error::Limit(format!(
                    "the {what} buffer would need {bytes} bytes, over this device's \
                     maxStorageBufferRange ({max_range})"
                )));
            }
        }

        let scene = Self::upload(ctx, mesh, lighting, settings)?;
        let view_buf = ctx.upload_buffer("views", &views)?;
        let setups = ctx.create_buffer(
            "face setups",
            pairs * std::mem::size_of::<GpuFaceSetup>() as u64,
            MemoryKind::Device,
        )?;
        let image = ctx.create_buffer("image", 16 * rendered, MemoryKind::Device)?;
        let aux = ctx.create_buffer("pixel aux", 16 * rendered, MemoryKind::Device)?;
        let small = if settings.antialias {
            Some(ctx.create_buffer("image (anti-aliased)", 16 * outputs, MemoryKind::Device)?)
        } else {
            None
        };
        ctx.submit_and_wait(|rec| {
            rec.pass("face setup", |rec| {
                self.setup.record(
                    rec,
                    scene.positions.whole(),
                    scene.faces.whole(),
                    view_buf.whole(),
                    setups.whole(),
                    face_count,
                    view_count,
                    settings.dist,
                    settings.sigma,
                )
            })?;
            rec.pass("raster brute", |rec| {
                self.brute.record(
                    rec,
                    &BruteBindings {
                        setups: setups.whole(),
                        colors: scene.colors.whole(),
                        faces: scene.faces.whole(),
                        image: image.whole(),
                        aux: aux.whole(),
                    },
                    settings,
                    w,
                    h,
                    face_count,
                    view_count,
                    mesh.texture_res,
                    cull,
                )
            })?;
            if let Some(small) = &small {
                rec.pass("downsample 2x2", |rec| {
                    self.brute.record_downsample(
                        rec,
                        image.whole(),
                        small.whole(),
                        settings.width,
                        settings.height,
                        view_count,
                    )
                })?;
            }
            Ok(())
        })?;
        let out = small.as_ref().unwrap_or(&image);
        Ok(Frames {
            width: settings.width,
            height: settings.height,
            images: ctx.read_buffer(out, 0, outputs as usize)?,
            rendered_width: w,
            rendered_height: h,
            aux: ctx.read_buffer(&aux, 0, rendered as usize)?,
        })
    }

    /// Renders one view with the brute-force kernel: RGBA per pixel, row 0 at the top.
    pub fn render_brute(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        camera: &Camera,
        lighting: &Lighting,
        settings: &RasterSettings,
    ) -> Result<Vec<[f32; 4]>> {
        Ok(self
            .render_brute_views(ctx, mesh, std::slice::from_ref(camera), lighting, settings)?
            .images)
    }

    /// Runs only the face setup and reads it back (`cameras.len() * F` entries, view-major).
    pub fn face_setups(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        settings: &RasterSettings,
    ) -> Result<Vec<GpuFaceSetup>> {
        let views = checked_views(mesh, cameras, settings)?;
        let (positions, faces) = Self::upload_geometry(ctx, mesh)?;
        let view_buf = ctx.upload_buffer("views", &views)?;
        let n = mesh.face_count() * views.len();
        let setups = ctx.create_buffer(
            "face setups",
            (n * std::mem::size_of::<GpuFaceSetup>()) as u64,
            MemoryKind::Device,
        )?;
        ctx.submit_and_wait(|rec| {
            self.setup.record(
                rec,
                positions.whole(),
                faces.whole(),
                view_buf.whole(),
                setups.whole(),
                mesh.face_count() as u32,
                views.len() as u32,
                settings.dist,
                settings.sigma,
            )
        })?;
        ctx.read_buffer(&setups, 0, n)
    }
}

/// Convenience: builds a [`Renderer`] and renders one view with the brute-force kernel.
pub fn render_brute(
    ctx: &Context,
    mesh: &Mesh,
    camera: &Camera,
    lighting: &Lighting,
    settings: &RasterSettings,
) -> Result<Vec<[f32; 4]>> {
    Renderer::new(ctx)?.render_brute(ctx, mesh, camera, lighting, settings)
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
