//! A scene on the GPU ([`GpuScene`]): the meshes, lit colours, views and every buffer of their
//! forward, kept so the scene renders again without re-uploading, with the bins of its exact
//! runs. [`crate::raster::gpu::Renderer`] makes and renders scenes; what a forward leaves for
//! its backward is in [`crate::raster::binned`].

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::primitives::binning::{BinJob, Bins, ItemLayout, TileGrid};
use crate::raster::fine::PixelAux;
use crate::raster::method::Method;
use crate::raster::reference::{FaceColors, MeshF64};
use crate::raster::settings::{ColorMode, RasterSettings};
use crate::raster::setup::{FACE_FINITE, GpuFaceSetup, VertexLayout};

/// Where the face setup's box and flags sit, for binning.
pub(crate) const SETUP_LAYOUT: ItemLayout = ItemLayout {
    stride_words: (std::mem::size_of::<GpuFaceSetup>() / 4) as u32,
    box_offset: (std::mem::offset_of!(GpuFaceSetup, bbox) / 4) as u32,
    flag_offset: (std::mem::offset_of!(GpuFaceSetup, flags) / 4) as u32,
    flag_mask: FACE_FINITE,
};

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

/// Views binned together: `first .. first + views`, with their (face, tile) entry count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ViewGroup {
    /// First view of the group.
    pub first: u32,
    /// Views in the group.
    pub views: u32,
    /// The group's window of tile rows ([`TileGrid::window`](crate::primitives::binning::TileGrid::window)): `(first row, rows)`, every row of
    /// the image unless one view held more entries than one binding and was binned window by
    /// window.
    pub tile_rows: (u32, u32),
    /// (face, tile) entries binned; for a guarded binning
    /// ([`Renderer::reserve_guarded`](crate::raster::gpu::Renderer::reserve_guarded), whose count
    /// stays on the GPU), the entry capacity, an upper bound.
    pub entries: u64,
    /// The most entries one tile holds, or an upper bound of it (the entry count) where that
    /// already satisfies the driver's loop cap ([`crate::gpu::DeviceInfo::shader_loop_limit`]).
    pub max_tile_entries: u64,
}

/// A scene on the GPU: mesh, lit colours, views, and every buffer of its forward pass, kept so
/// the scene can be rendered again without re-uploading (the bins grow, never shrink).
pub struct GpuScene {
    pub(crate) settings: RasterSettings,
    pub(crate) face_count: u32,
    pub(crate) vertex_count: u32,
    pub(crate) view_count: u32,
    pub(crate) texture_res: u32,
    /// Rendered size (2× the output with anti-aliasing).
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) positions: Buffer,
    /// Where the vertices sit in `positions` ([`GpuScene::bind_positions`]).
    pub(crate) position_layout: VertexLayout,
    pub(crate) faces: Buffer,
    pub(crate) colors: Buffer,
    pub(crate) views: Buffer,
    /// Every vertex of every view on screen: the face setup's scratch.
    pub(crate) screen: Buffer,
    pub(crate) setups: Buffer,
    pub(crate) image: Buffer,
    pub(crate) aux: Buffer,
    /// Every rendered pixel's running state between the passes of a face list too long for
    /// one (`CARRY` in `raster_fine.glsl`): sized where the scene's face count could need
    /// passes on this device, a placeholder elsewhere.
    pub(crate) carry: Buffer,
    pub(crate) small: Option<Buffer>,
    /// The bins of the exact runs ([`Renderer::run`]), one per view group or window of the last
    /// one. Kept for the next run and for the backward (no second binning); they grow, never
    /// shrink.
    ///
    /// [`Renderer::run`]: crate::raster::gpu::Renderer::run
    pub(crate) bins: Vec<Bins>,
    /// The method and view groups of the last exact run, while nothing has changed the scene
    /// since ([`GpuScene::last_run`]).
    pub(crate) last_run: Option<(Method, Vec<ViewGroup>)>,
    /// Render alpha only ([`GpuScene::set_silhouette_only`]).
    pub(crate) silhouette_only: bool,
    /// The batch's meshes in f64, the lighting and the views, for the backward's host share.
    pub(crate) meshes: Vec<MeshF64>,
    pub(crate) lighting: Lighting,
    pub(crate) views_host: Vec<(usize, Camera)>,
}

impl GpuScene {
    /// Views in the scene.
    pub fn view_count(&self) -> u32 {
        self.view_count
    }

    /// Faces per view.
    pub fn face_count(&self) -> u32 {
        self.face_count
    }

    /// Vertices per mesh of the batch.
    pub fn vertex_count(&self) -> u32 {
        self.vertex_count
    }

    /// Texels per face edge (surface colours).
    pub fn texture_res(&self) -> u32 {
        self.texture_res
    }

    /// Renders alpha only from now on (silhouettes, as fits from masks need): the fine passes
    /// leave out depth, colour and the softmax, the image's RGB is the background and the aux's
    /// colour fields keep their initial values, while alpha and its aux fields are the same
    /// bits as a full render's. The backward of such a scene differentiates alpha only (see
    /// [`crate::raster::backward::GradBuffers::set_alpha_only`]).
    pub fn set_silhouette_only(&mut self, silhouette_only: bool) {
        self.silhouette_only = silhouette_only;
        self.last_run = None;
    }

    /// Whether only alpha is rendered ([`GpuScene::set_silhouette_only`]).
    pub fn silhouette_only(&self) -> bool {
        self.silhouette_only
    }

    /// The output image buffer (RGBA per output pixel, view-major, row 0 at the top): the 2×2
    /// average with anti-aliasing, else the rendered image. What a loss recorded after the
    /// forward reads.
    pub fn output(&self) -> &Buffer {
        self.small.as_ref().unwrap_or(&self.image)
    }

    /// The world positions the face setup reads (3 floats per vertex, mesh after mesh): a
    /// deformation recorded before the forward writes them, a host may copy into them.
    pub fn positions(&self) -> &Buffer {
        &self.positions
    }

    /// Where the vertices sit in [`GpuScene::positions`].
    pub fn position_layout(&self) -> VertexLayout {
        self.position_layout
    }

    /// The bytes of [`GpuScene::positions`] the kernels read (a host's vertex buffer may be
    /// larger than one storage binding; only the vertices' span is bound).
    pub(crate) fn position_range(&self) -> Result<BufferRange<'_>> {
        let vertices = u64::from(self.vertex_count) * self.meshes.len() as u64;
        let bytes = self.position_layout.bytes(vertices)?.max(4);
        Ok(self.positions.range(0, bytes.min(self.positions.size())))
    }

    /// Renders from `buffer`'s vertices from now on, laid out as `layout` says: a host's vertex
    /// buffer ([`Context::import_buffer`]), interleaved or not, written by the host's own passes
    /// before each forward. The scene's own position buffer is dropped. The vertex count (per mesh
    /// of the batch, meshes one after another) stays the scene's; the faces, colours and views too.
    /// The backward's host share (lighting, cameras) keeps reading the meshes given to
    /// [`Renderer::prepare`](crate::raster::gpu::Renderer::prepare): for lit scenes whose vertices
    /// move, use an unlit or silhouette render, relight on the host ([`GpuScene::relight`]), or
    /// record the lighting and its backward on the GPU ([`crate::raster::light::SceneLight`]).
    pub fn bind_positions(&mut self, buffer: Buffer, layout: VertexLayout) -> Result<()> {
        let vertices = u64::from(self.vertex_count) * self.meshes.len() as u64;
        let need = layout.bytes(vertices)?;
        buffer
            .whole()
            .require(need, "the scene's vertex positions")?;
        if need > 4 * u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "vertex positions reach byte {need}, past what 32-bit float indices address"
            )));
        }
        self.positions = buffer;
        self.position_layout = layout;
        self.last_run = None;
        Ok(())
    }

    /// The lit colours the fine passes read (per texel slot or per vertex, mesh after mesh: 4
    /// floats each, RGB and an unused fourth).
    pub fn colors(&self) -> &Buffer {
        &self.colors
    }

    /// The settings the scene renders with.
    pub fn settings(&self) -> &RasterSettings {
        &self.settings
    }

    /// Changes σ and γ (SoftRas's blur and the softmax's temperature) for the next forward; an
    /// error, with nothing changed, when the settings would not validate.
    pub fn set_blur(&mut self, sigma: f64, gamma: f64) -> Result<()> {
        let mut settings = self.settings;
        settings.sigma = sigma;
        settings.gamma = gamma;
        settings.validate()?;
        self.settings = settings;
        self.last_run = None;
        Ok(())
    }

    /// The batch's meshes in f64, which the backward's host share (lighting, cameras) reads.
    pub fn host_meshes(&self) -> &[MeshF64] {
        &self.meshes
    }

    /// Moves mesh `mesh`'s vertices to `positions` on the host side and returns its colours lit
    /// anew, packed as [`GpuScene::colors`] holds them: for callers that pose a mesh on the host
    /// and copy positions and colours into the scene's buffers themselves (the pose fit), so
    /// the backward's host share sees what the GPU renders.
    pub fn relight(&mut self, mesh: usize, positions: &[[f32; 3]]) -> Result<Vec<f32>> {
        let Some(m) = self.meshes.get_mut(mesh) else {
            return Err(Error::Input(format!(
                "mesh {mesh} of a batch of {}",
                self.meshes.len()
            )));
        };
        if positions.len() != m.positions.len() {
            return Err(Error::Input(format!(
                "{} positions for a mesh of {} vertices",
                positions.len(),
                m.positions.len()
            )));
        }
        for (dst, src) in m.positions.iter_mut().zip(positions) {
            *dst = glam::DVec3::from(src.map(f64::from));
        }
        self.last_run = None;
        Ok(
            match FaceColors::of(m, &self.lighting, self.settings.color_mode) {
                FaceColors::Surface { texels, .. } => rgb_padded(&texels),
                FaceColors::Vertex { colors, .. } => rgb_padded(&colors),
            },
        )
    }

    /// Replaces the batch's meshes by `meshes` of the same topology (faces, vertex count, texture
    /// resolution and colour source), for the next forward: their positions and colours, lit anew
    /// with the scene's lighting, are written into the scene's buffers, and the backward's host
    /// share reads them. What a loop that renders new vertices or textures every iteration through
    /// the same views calls instead of
    /// [`Renderer::prepare_batch`](crate::raster::gpu::Renderer::prepare_batch): no buffer is made
    /// again, and the bins keep their size. An error, with nothing changed, when a mesh does not
    /// fit.
    pub fn update_meshes(&mut self, ctx: &Context, meshes: &[Mesh]) -> Result<()> {
        if meshes.len() != self.meshes.len() {
            return Err(Error::Input(format!(
                "{} meshes for a scene of {}",
                meshes.len(),
                self.meshes.len()
            )));
        }
        if self.position_layout != VertexLayout::default() {
            return Err(Error::Misuse(
                "update_meshes writes the scene's own positions; this scene renders a host's positions \
                 (bind_positions)"
                    .into(),
            ));
        }
        for (i, (new, old)) in meshes.iter().zip(&self.meshes).enumerate() {
            new.validate()?;
            let same_colors = match self.settings.color_mode {
                ColorMode::Surface => true,
                ColorMode::Vertex => new.vertex_colors.is_some() == old.vertex_colors.is_some(),
            };
            if new.faces != old.faces
                || new.positions.len() != old.positions.len()
                || new.texture_res != old.texture_res
                || !same_colors
            {
                return Err(Error::Input(format!(
                    "mesh {i} does not share the scene's topology (faces, vertex count, texture \
                     resolution and colour source must be equal)"
                )));
            }
        }
        let positions: Vec<f32> = meshes
            .iter()
            .flat_map(|m| m.positions.iter().flatten().copied())
            .collect();
        let colors = lit_batch(meshes, &self.lighting, self.settings.color_mode);
        ctx.write_buffer(&self.positions, 0, &positions)?;
        ctx.write_buffer(&self.colors, 0, &colors)?;
        self.meshes = meshes.iter().map(MeshF64::from_mesh).collect();
        self.last_run = None;
        Ok(())
    }

    /// Reads back the face setups of the last forward: one per (view, face), view-major.
    pub fn read_setups(&self, ctx: &Context) -> Result<Vec<GpuFaceSetup>> {
        let n = self.face_count as usize * self.view_count as usize;
        ctx.read_buffer(&self.setups, 0, n)
    }

    /// Reads back the images and aux of the last forward.
    pub fn read_frames(&self, ctx: &Context) -> Result<Frames> {
        let s = &self.settings;
        let outputs = (s.width * s.height * self.view_count) as usize;
        let rendered = (self.width * self.height * self.view_count) as usize;
        Ok(Frames {
            width: s.width,
            height: s.height,
            images: ctx.read_buffer(self.output(), 0, outputs)?,
            rendered_width: self.width,
            rendered_height: self.height,
            aux: ctx.read_buffer(&self.aux, 0, rendered)?,
        })
    }

    /// The rendered (pre-downsampling) image size.
    pub fn rendered_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The tile grid of `tile`-pixel tiles over the rendered image.
    pub(crate) fn grid(&self, tile: u32) -> Result<TileGrid> {
        TileGrid::new(self.width, self.height, tile)
    }

    pub(crate) fn job(&self, grid: TileGrid, first_view: u32, views: u32) -> BinJob {
        BinJob {
            grid,
            layout: SETUP_LAYOUT,
            items_per_view: self.face_count,
            views,
            first_item: first_view * self.face_count,
        }
    }
}

/// The lit colours of a batch, mesh after mesh ([`lit_colors`]). A mesh equal to the one before
/// it (SoftRas renders many views of one mesh as a batch of copies) takes its colours: the same
/// bits, lit once.
pub(crate) fn lit_batch(meshes: &[Mesh], lighting: &Lighting, mode: ColorMode) -> Vec<f32> {
    let mut colors: Vec<f32> = Vec::new();
    let mut last: Option<(&Mesh, std::ops::Range<usize>)> = None;
    for mesh in meshes {
        let start = colors.len();
        match &last {
            Some((prev, range))
                if prev.positions == mesh.positions
                    && prev.textures == mesh.textures
                    && prev.vertex_colors == mesh.vertex_colors =>
            {
                colors.extend_from_within(range.clone());
            }
            _ => colors.extend(lit_colors(mesh, lighting, mode)),
        }
        last = Some((mesh, start..colors.len()));
    }
    colors
}

/// Lights on the host in f64 and rounds to the f32 colours the kernels read ([`rgb_padded`]).
fn lit_colors(mesh: &Mesh, lighting: &Lighting, mode: ColorMode) -> Vec<f32> {
    match FaceColors::new(mesh, lighting, mode) {
        FaceColors::Surface { texels, .. } => rgb_padded(&texels),
        FaceColors::Vertex { colors, .. } => rgb_padded(&colors),
    }
}

/// Colours as [`GpuScene::colors`] holds them: RGB in f32 and an unused fourth float each (a
/// kernel then reads a colour with one vec4 load: on llvmpipe every load of a lane's own
/// address is a scalar loop over the lanes, one per load whatever its width).
fn rgb_padded(colors: &[[f64; 3]]) -> Vec<f32> {
    colors
        .iter()
        .flat_map(|c| [c[0] as f32, c[1] as f32, c[2] as f32, 0.0])
        .collect()
}
