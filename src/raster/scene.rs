//! A scene on the GPU ([`GpuScene`]): the meshes, lit colours, views and every buffer of their
//! forward, kept so the scene renders again without re-uploading; what a forward leaves for its
//! backward ([`Binned`]); and how many (pixel, face) pairs its fine passes visit
//! ([`PairCounts`]). [`crate::raster::gpu::Renderer`] makes and renders scenes.

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::primitives::binning::{BinJob, Bins, ItemLayout, TileGrid};
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
    pub(crate) setups: Buffer,
    pub(crate) image: Buffer,
    pub(crate) aux: Buffer,
    /// Every rendered pixel's running state between the passes of a face list too long for
    /// one (`CARRY` in `raster_fine.glsl`): sized where the scene's face count could need
    /// passes on this device, a placeholder elsewhere.
    pub(crate) carry: Buffer,
    pub(crate) small: Option<Buffer>,
    /// Bins per view group: group `i` of the last tiled run used `bins[i]`. They are kept (the
    /// backward pass reuses them: no second binning) and grow, never shrink.
    pub(crate) bins: Vec<Bins>,
    /// The view groups of the last tiled render.
    pub(crate) groups: Vec<ViewGroup>,
    /// The tile size of the last tiled render.
    pub(crate) tile: Option<u32>,
    /// The bins were sized by
    /// [`Renderer::reserve_guarded`](crate::raster::gpu::Renderer::reserve_guarded) (one group of
    /// every view, a capacity), not by an exact run: what a guarded forward needs.
    pub(crate) guarded: bool,
    /// Render alpha only ([`GpuScene::set_silhouette_only`]).
    pub(crate) silhouette_only: bool,
    /// The batch's meshes in f64, the lighting and the views, for the backward's host share.
    pub(crate) meshes: Vec<MeshF64>,
    pub(crate) lighting: Lighting,
    pub(crate) views_host: Vec<(usize, Camera)>,
}

/// What a forward leaves for its backward: the scene it rendered and how (with tiles, the scene's
/// bins and view groups hold the binning). Every forward returns one; the backward takes it.
/// It borrows the scene, so the scene cannot be re-binned, re-sized or re-rendered while it
/// lives.
#[derive(Clone, Copy)]
pub struct Binned<'s> {
    pub(crate) scene: &'s GpuScene,
    pub(crate) method: Method,
}

impl std::fmt::Debug for Binned<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Binned")
            .field("method", &self.method)
            .field("groups", &self.scene.groups)
            .finish_non_exhaustive()
    }
}

impl<'s> Binned<'s> {
    /// The scene rendered.
    pub fn scene(&self) -> &'s GpuScene {
        self.scene
    }

    /// How faces met pixels.
    pub fn method(&self) -> Method {
        self.method
    }
}

/// Views binned together: `first .. first + views`, with their (face, tile) entry count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ViewGroup {
    /// First view of the group.
    pub first: u32,
    /// Views in the group.
    pub views: u32,
    /// The group's window of tile rows ([`TileGrid::window`]): `(first row, rows)`, every row of
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

/// The (pixel, face) pairs of one render's fine passes ([`GpuScene::pair_counts`]): what per
/// pair costs mean (ns per visited pair) independently of how fast the device is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PairCounts {
    /// Every pixel of a tile times the faces binned to it (tiled), or every pixel times every
    /// face (brute force).
    pub binned: u64,
    /// Pairs the forward's fine kernel shades: tiled, for each subgroup of a block's pixels,
    /// its lanes times the binned faces whose box touches the box of its pixel centres (the
    /// rest are skipped by the ballot); brute force, all.
    pub forward: u64,
    /// Pairs the backward's fine kernel evaluates where no upstream pixel is zero (zero ones
    /// are skipped too): tiled, for each batch of a subgroup's lanes' faces and each segment of
    /// as many of the tile's pixels, the lanes times the batch's faces that touch the segment;
    /// brute force, all.
    pub backward: u64,
    /// Pairs whose pixel centre lies in the face's grown box: the ones that can contribute.
    pub accepted: u64,
}

/// The pixel centres of a `width × height` image in f32, as the kernels compute them.
struct PixelCenters {
    x: Vec<f32>,
    y: Vec<f32>,
}

impl PixelCenters {
    fn new(width: u32, height: u32) -> Self {
        let (w, h) = (width as f32, height as f32);
        let s = w.min(h);
        Self {
            x: (0..width).map(|c| (2.0 * c as f32 + 1.0 - w) / s).collect(),
            y: (0..height)
                .map(|r| (2.0 * (h - 1.0 - r as f32) + 1.0 - h) / s)
                .collect(),
        }
    }

    /// Pixel centres inside `b` (`outside_bbox` false). `x` increases with the column and `y`
    /// decreases with the row.
    fn inside(&self, b: [f32; 4]) -> u64 {
        let cols = (self.x.partition_point(|&x| x <= b[2]))
            .saturating_sub(self.x.partition_point(|&x| x < b[0]));
        let rows = (self.y.partition_point(|&y| y >= b[1]))
            .saturating_sub(self.y.partition_point(|&y| y > b[3]));
        (cols * rows) as u64
    }

    /// The box of the centres of `pixels` (col, row), if any.
    fn hull(&self, pixels: &[(u32, u32)]) -> Option<[f32; 4]> {
        let mut it = pixels
            .iter()
            .map(|&(c, r)| (self.x[c as usize], self.y[r as usize]));
        let (x, y) = it.next()?;
        Some(it.fold([x, y, x, y], |b, (x, y)| {
            [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)]
        }))
    }
}

/// `segment_shape` of `kernels/include/subgroup_face.glsl`: the block (width, height) of pixels
/// that `lanes` lanes cover together, as square as a power of two allows; `None` (rows) when
/// `lanes` is not a power of two up to 64.
fn segment_shape(lanes: u32) -> Option<(u32, u32)> {
    (lanes.is_power_of_two() && lanes <= 64).then(|| {
        let w = 1 << lanes.ilog2().div_ceil(2);
        (w, lanes / w)
    })
}

/// `segment_pixel`: where pixel `i` of a `size`-wide square lies (x, y) when its pixels go to
/// lanes `lanes` at a time, one [`segment_shape`] block per run.
fn segment_pixel(i: u32, size: u32, lanes: u32) -> (u32, u32) {
    let Some((w, h)) = segment_shape(lanes) else {
        return (i % size, i / size);
    };
    let (segment, lane) = (i / lanes, i % lanes);
    let per_row = size / w;
    (
        (segment % per_row) * w + lane % w,
        (segment / per_row) * h + lane / w,
    )
}

/// Whether face box `f` can hold a pixel centre of box `p` (the kernels' ballot test).
fn boxes_touch(f: [f32; 4], p: [f32; 4]) -> bool {
    !(p[2] < f[0] || p[3] < f[1] || p[0] > f[2] || p[1] > f[3])
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
    }

    /// Whether only alpha is rendered ([`GpuScene::set_silhouette_only`]).
    pub fn silhouette_only(&self) -> bool {
        self.silhouette_only
    }

    /// The (face, tile) entries of the last tiled render, over all view groups.
    pub fn binned_entries(&self) -> u64 {
        self.groups.iter().map(|g| g.entries).sum()
    }

    /// How many (pixel, face) pairs the last run's fine passes bin, visit and accept
    /// ([`PairCounts`]), counted on the host from the setups and bins read back, by the
    /// kernels' own rules for this device's subgroup size. Tiled needs the last run to have
    /// been tiled with this tile size (in any view groups and windows).
    pub fn pair_counts(&self, ctx: &Context, method: Method) -> Result<PairCounts> {
        let (w, h) = (self.width, self.height);
        let faces = self.face_count as usize;
        let views = self.view_count as usize;
        let setups: Vec<GpuFaceSetup> = ctx.read_buffer(&self.setups, 0, faces * views)?;
        let centers = PixelCenters::new(w, h);
        // Pairs whose pixel lies in the face's box: the box test's (`outside_bbox`) passes.
        let accepted = setups
            .iter()
            .filter(|f| f.flags & FACE_FINITE != 0)
            .map(|f| centers.inside(f.bbox))
            .sum();
        let pixels = u64::from(w) * u64::from(h) * views as u64;
        let Method::Tiled { tile } = method else {
            let all = pixels * faces as u64;
            return Ok(PairCounts {
                binned: all,
                forward: all,
                backward: all,
                accepted,
            });
        };
        if self.tile != Some(tile) || self.groups.is_empty() {
            return Err(Error::Misuse(
                "pair_counts needs a previous tiled run with this tile size".into(),
            ));
        }
        let lanes = ctx.info().subgroup_size.clamp(1, 64);
        let mut counts = PairCounts {
            accepted,
            ..PairCounts::default()
        };
        // Every group of views, or window of one view's tile rows, with its own bins.
        for (group, bins) in self.groups.iter().zip(&self.bins) {
            let (first_row, rows) = group.tile_rows;
            let grid = self.grid(tile)?.window(first_row, rows)?;
            let per_view = grid.tiles_per_view() as usize;
            let tiles = per_view * group.views as usize;
            let ranges: Vec<[u32; 2]> = ctx.read_buffer(bins.ranges(), 0, tiles)?;
            let total = ranges.iter().map(|r| r[1]).max().unwrap_or(0) as usize;
            let entries: Vec<u32> = ctx.read_buffer(bins.entries(), 0, total)?;
            let items: Vec<u32> = ctx.read_buffer(bins.entry_items(), 0, total)?;
            for (t, r) in ranges.iter().enumerate() {
                let view = group.first as usize + t / per_view;
                let in_view = (t % per_view) as u32;
                let (x0, y0) = (
                    (in_view % grid.tiles_x) * tile,
                    (grid.first_row + in_view / grid.tiles_x) * tile,
                );
                let run: Vec<&GpuFaceSetup> = (r[0] as usize..r[1] as usize)
                    .map(|k| &setups[view * faces + items[entries[k] as usize] as usize])
                    .collect();
                let tile_w = (w - x0).min(tile);
                let tile_h = (h - y0).min(tile);
                counts.binned += run.len() as u64 * u64::from(tile_w * tile_h);
                let touching = |faces: &[&GpuFaceSetup], pixels: &[(u32, u32)]| -> u64 {
                    let Some(b) = centers.hull(pixels) else {
                        return 0;
                    };
                    faces
                        .iter()
                        .filter(|f| f.flags & FACE_FINITE != 0 && boxes_touch(f.bbox, b))
                        .count() as u64
                };
                // Forward: per 8×8 block of the tile, per subgroup of its 64 pixels (one
                // `segment_pixel` block each, edge pixels clamped into the image), the faces whose
                // box touches the subgroup's.
                for by in (y0..y0 + tile).step_by(8).filter(|&y| y < h) {
                    for bx in (x0..x0 + tile).step_by(8).filter(|&x| x < w) {
                        for first in (0..64).step_by(lanes as usize) {
                            let group: Vec<(u32, u32)> = (first..first + lanes.min(64))
                                .map(|i| {
                                    let (x, y) = segment_pixel(i, 8, lanes);
                                    ((bx + x).min(w - 1), (by + y).min(h - 1))
                                })
                                .collect();
                            counts.forward += u64::from(lanes) * touching(&run, &group);
                        }
                    }
                }
                // Backward: per batch of `lanes` faces, per segment of `lanes` pixels of the tile
                // (`segment_pixel` blocks, those in the image), the batch's faces whose box
                // touches the segment.
                let tile_pixels: Vec<(u32, u32)> = (0..tile * tile)
                    .map(|i| {
                        let (x, y) = segment_pixel(i, tile, lanes);
                        (x0 + x, y0 + y)
                    })
                    .collect();
                for batch in run.chunks(lanes as usize) {
                    for segment in tile_pixels.chunks(lanes as usize) {
                        let inside: Vec<(u32, u32)> = segment
                            .iter()
                            .copied()
                            .filter(|&(c, r)| c < w && r < h)
                            .collect();
                        counts.backward += u64::from(lanes) * touching(batch, &inside);
                    }
                }
            }
        }
        Ok(counts)
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
        Ok(())
    }

    /// The [`Binned`] the scene's last forward by `method` left, for a backward recorded apart
    /// from its forward (a benchmark timing the backward alone over one render). Tiled:
    /// [`Error::Misuse`] unless the last tiled forward used these tiles. The forward's own
    /// return value says the same without asking; prefer it.
    pub fn binned(&self, method: Method) -> Result<Binned<'_>> {
        if let Method::Tiled { tile } = method {
            if self.tile != Some(tile) || self.groups.is_empty() {
                return Err(Error::Misuse(format!(
                    "the scene was not last binned with {tile}-pixel tiles (it was with {:?})",
                    self.tile
                )));
            }
        }
        Ok(Binned {
            scene: self,
            method,
        })
    }

    /// The view groups of the last tiled run.
    pub fn groups(&self) -> &[ViewGroup] {
        &self.groups
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

/// Positions and faces as the packed triples the kernels read.
pub(crate) fn upload_geometry(ctx: &Context, mesh: &Mesh) -> Result<(Buffer, Buffer)> {
    let positions: Vec<f32> = mesh.positions.iter().flatten().copied().collect();
    let faces: Vec<u32> = mesh.faces.iter().flatten().copied().collect();
    Ok((
        ctx.upload_buffer("mesh positions", &positions)?,
        ctx.upload_buffer("mesh faces", &faces)?,
    ))
}

#[cfg(test)]
mod tests {
    use super::{segment_pixel, segment_shape};

    /// Every pixel of a tile goes to exactly one lane of one segment, and a segment's pixels
    /// fill one `segment_shape` block, for every subgroup size a device may have.
    #[test]
    fn segments_cover_each_pixel_once_in_square_blocks() {
        for lanes in [1u32, 2, 4, 8, 16, 32, 64, 3, 48] {
            for size in [8u32, 16, 32] {
                let mut seen = vec![false; (size * size) as usize];
                for i in 0..size * size {
                    let (x, y) = segment_pixel(i, size, lanes);
                    assert!(x < size && y < size, "lanes {lanes}, size {size}, i {i}");
                    assert!(!std::mem::replace(&mut seen[(y * size + x) as usize], true));
                }
                let Some((w, h)) = segment_shape(lanes) else {
                    assert!(!lanes.is_power_of_two());
                    continue;
                };
                assert_eq!(w * h, lanes);
                assert!(w == h || w == 2 * h, "lanes {lanes}: {w} × {h}");
                for first in (0..size * size).step_by(lanes as usize) {
                    let (x0, y0) = segment_pixel(first, size, lanes);
                    for i in first..first + lanes {
                        let (x, y) = segment_pixel(i, size, lanes);
                        assert!((x0..x0 + w).contains(&x) && (y0..y0 + h).contains(&y));
                    }
                }
            }
        }
    }
}
