//! The buffers of one scene's backward ([`GradBuffers`]), sized once for the scene and kept
//! across its backward passes, and where a backward reads its upstream gradient and writes its
//! results ([`GradIo`]).

#[cfg(doc)]
use super::GradKernels;
use super::plan::band_rows;
use super::{GradSplit, face_grad_width, grad_stride};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{Buffer, BufferRange, Context, MemoryKind, TEXEL_BYTES};
use crate::raster::binned::{Binned, GuardedBins};
use crate::raster::fine::{FineModes, MAX_MASKED_TEXELS};
use crate::raster::loops::ColorWork;
use crate::raster::method::Method;
use crate::raster::reference_grad::VertexFaces;
use crate::raster::scene::GpuScene;
use crate::raster::settings::ColorMode;

/// The buffers of one scene's backward, reusable across backward passes of that scene.
pub struct GradBuffers {
    d_image: Buffer,
    pub(crate) partials: Buffer,
    pub(super) face_grads: Buffer,
    pub(super) corner_world: Buffer,
    pub(super) corner_cam: Buffer,
    pub(super) vertex_offsets: Buffer,
    pub(super) vertex_slots: Buffer,
    /// Each mesh's views, as `grad_gather.comp` reads them ([`mesh_view_lists`]).
    pub(super) mesh_views: Buffer,
    position_grads: Buffer,
    color_grads: Buffer,
    pub(super) method: Method,
    pub(crate) stride: u32,
    pub(super) width: u32,
    pub(super) split: GradSplit,
    /// Units one chunk of partials holds, and the most it may hold (the budget).
    pub(super) chunk_units: u64,
    budget_units: u64,
    /// Brute force: rows per band and bands per view.
    pub(super) band_rows: u32,
    pub(super) bands: u32,
    /// The upstream gradient has no RGB part ([`GradBuffers::set_alpha_only`]).
    alpha_only: bool,
    /// The sizes of the scene the buffers were made for ([`GradBuffers::fits`]).
    made_for: SceneSizes,
}

/// What of a scene sizes its backward's buffers: counts, image size, colour layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct SceneSizes {
    meshes: usize,
    vertices: u32,
    faces: u32,
    views: u32,
    texture_res: u32,
    color_mode: ColorMode,
    size: (u32, u32),
    rendered: (u32, u32),
}

impl SceneSizes {
    fn of(scene: &GpuScene) -> Self {
        SceneSizes {
            meshes: scene.meshes.len(),
            vertices: scene.vertex_count,
            faces: scene.face_count,
            views: scene.view_count,
            texture_res: scene.texture_res,
            color_mode: scene.settings.color_mode,
            size: (scene.settings.width, scene.settings.height),
            rendered: (scene.width, scene.height),
        }
    }
}

/// Where a backward reads its upstream gradient and writes its results ([`GradKernels::record`]):
/// buffer ranges that may belong to a host. [`GradBuffers::io`] gives the buffers' own.
#[derive(Clone, Copy)]
pub struct GradIo<'a> {
    /// dL/d(output RGBA): 4 floats per output pixel, view-major, row-major.
    pub upstream: BufferRange<'a>,
    /// dL/d(world positions), written: 3 floats per vertex, mesh after mesh.
    pub positions: BufferRange<'a>,
    /// dL/d(lit colours), written: 3 floats per texel slot (surface colours, face after face)
    /// or per vertex (vertex colours), mesh after mesh.
    pub colors: BufferRange<'a>,
}

impl GradIo<'_> {
    /// Bytes each range needs for the backward of `scene`.
    pub fn sizes(scene: &GpuScene) -> [u64; 3] {
        let s = &scene.settings;
        let batch = scene.meshes.len() as u64;
        let outputs = u64::from(s.width) * u64::from(s.height) * u64::from(scene.view_count);
        let vertices = u64::from(scene.vertex_count) * batch;
        let colors = match s.color_mode {
            ColorMode::Surface => {
                u64::from(scene.face_count) * u64::from(scene.texture_res).pow(2) * batch
            }
            ColorMode::Vertex => vertices,
        };
        [16 * outputs, 12 * vertices, 12 * colors]
    }

    /// [`Error::BufferTooSmall`] when a range is smaller than the backward of `scene` needs.
    pub(super) fn check(&self, scene: &GpuScene) -> Result<()> {
        let [upstream, positions, colors] = Self::sizes(scene);
        self.upstream
            .require(upstream, "the backward's upstream gradient")?;
        self.positions
            .require(positions, "the backward's position gradients")?;
        self.colors
            .require(colors, "the backward's colour gradients")
    }
}

/// The tiled partials an exact forward's backward sizes for: its largest group's entries, with
/// headroom so that a fit whose entries breathe does not reallocate every step.
fn most(binned: &Binned<'_>) -> u64 {
    let most = binned.groups().iter().map(|g| g.entries).max().unwrap_or(0);
    most + most / 4
}

fn checked(ctx: &Context, what: &str, bytes: u64) -> Result<u64> {
    let max = u64::from(ctx.info().limits.max_storage_buffer_range);
    if bytes > max {
        return Err(Error::Limit(format!(
            "the backward's {what} buffer would need {bytes} bytes, over this device's \
             maxStorageBufferRange ({max}); use fewer views or faces"
        )));
    }
    Ok(bytes.max(4))
}

impl GradBuffers {
    /// Buffers for the backward of the forward that left `binned` (the backward reuses its
    /// binning; tiled partials are sized for its largest group).
    pub fn new(ctx: &Context, binned: &Binned<'_>) -> Result<Self> {
        Self::build(
            ctx,
            binned.scene(),
            binned.method(),
            GradSplit::default(),
            most(binned),
        )
    }

    /// As [`GradBuffers::new`], splitting the work at most as `split` says (a test knob: the
    /// `test-knobs` feature).
    #[cfg(feature = "test-knobs")]
    pub fn with_split(ctx: &Context, binned: &Binned<'_>, split: GradSplit) -> Result<Self> {
        Self::build(ctx, binned.scene(), binned.method(), split, most(binned))
    }

    /// Buffers for the backward of every guarded forward of `scene` into `bins`
    /// ([`crate::raster::gpu::Renderer::reserve_guarded`]): tiled partials for their capacity
    /// (at most what one binding holds; more take several chunks).
    pub fn guarded(ctx: &Context, scene: &GpuScene, bins: &GuardedBins) -> Result<Self> {
        let binned = bins.binned(scene)?;
        Self::build(
            ctx,
            scene,
            binned.method(),
            GradSplit::default(),
            bins.capacity(),
        )
    }

    fn build(
        ctx: &Context,
        scene: &GpuScene,
        method: Method,
        split: GradSplit,
        entries: u64,
    ) -> Result<Self> {
        let mode = scene.settings.color_mode;
        let stride = grad_stride(mode, scene.texture_res);
        let width = face_grad_width(mode);
        let items = u64::from(scene.face_count) * u64::from(scene.view_count);
        let outputs = u64::from(scene.settings.width)
            * u64::from(scene.settings.height)
            * u64::from(scene.view_count);
        let batch = scene.meshes.len() as u64;
        let vertices = u64::from(scene.vertex_count) * batch;
        let color_values = match mode {
            ColorMode::Surface => {
                u64::from(scene.face_count) * u64::from(scene.texture_res).pow(2) * batch
            }
            ColorMode::Vertex => vertices,
        };
        let adjacency = VertexFaces::new(&scene.meshes[0].faces, scene.vertex_count as usize);
        let limit = ctx.info().shader_loop_limit();
        // The partials are bound as a storage buffer (the fine kernels) and as texels (the
        // texel reduction): a chunk fits both limits.
        let limits = &ctx.info().limits;
        let max_range = u64::from(limits.max_storage_buffer_range)
            .min(u64::from(limits.max_texel_buffer_elements) * TEXEL_BYTES);
        let mut budget_units = max_range / (4 * u64::from(stride));
        if let Some(cap) = split.chunk_units {
            budget_units = budget_units.min(cap);
        }
        if budget_units == 0 {
            return Err(Error::DeviceLimit {
                kind: LimitKind::StorageBinding,
                what: format!("one partial gradient of {stride} floats"),
                need: 4 * u64::from(stride),
                max: max_range,
                device: ctx.info().name.clone(),
                hint: "use a smaller texture resolution",
            });
        }
        let (band_rows, bands, units) = match method {
            Method::Brute => {
                let rows = band_rows(
                    scene.width,
                    scene.height,
                    limit,
                    split.band_rows,
                    &ctx.info().name,
                )?;
                let bands = scene.height.div_ceil(rows);
                (rows, bands, items * u64::from(bands))
            }
            Method::Tiled { .. } => (0, 0, entries),
        };
        if units > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "the backward would split into {units} units of work, over 2^32; use fewer \
                 views or the tiled method"
            )));
        }
        let chunk_units = units.clamp(1, budget_units);
        let device = |name: &str, bytes: u64| -> Result<Buffer> {
            ctx.create_buffer(name, checked(ctx, name, bytes)?, MemoryKind::Device)
        };
        Ok(Self {
            d_image: device("d_image", 16 * outputs)?,
            partials: device("grad partials", chunk_units * u64::from(stride) * 4)?,
            face_grads: device("face grads", items * u64::from(width) * 4)?,
            corner_world: device("corner world grads", items * 36)?,
            corner_cam: device("corner camera grads", items * 36)?,
            vertex_offsets: ctx.upload_buffer("vertex offsets", &adjacency.offsets)?,
            vertex_slots: ctx.upload_buffer("vertex slots", &adjacency.slots)?,
            mesh_views: ctx.upload_buffer("mesh views", &mesh_view_lists(scene))?,
            position_grads: device("position grads", vertices * 12)?,
            color_grads: device("colour grads", color_values * 12)?,
            method,
            stride,
            width,
            split,
            chunk_units,
            budget_units,
            band_rows,
            bands,
            alpha_only: false,
            made_for: SceneSizes::of(scene),
        })
    }

    /// Whether these buffers serve the backward of the forward that left `binned` as well as new ones
    /// would: made for a scene of its sizes and method, with room for its (face, tile) entries
    /// in as few chunks. For a scene with the same meshes' topology and views as the one they
    /// were made for (the vertex adjacency and each mesh's views are uploaded once): a loop
    /// that writes new vertices into its scene ([`GpuScene::update_meshes`]) keeps one set.
    /// Keeping them is faster than making them again: on a CPU device fresh device memory
    /// costs a page fault per page at its first write (about 40 ms of a 200 ms backward on the
    /// deformation demo's 120 views on llvmpipe).
    pub fn fits(&self, binned: &Binned<'_>) -> bool {
        if self.method != binned.method() || self.made_for != SceneSizes::of(binned.scene()) {
            return false;
        }
        let most = binned.groups().iter().map(|g| g.entries).max().unwrap_or(0);
        self.chunk_units >= most || self.chunk_units >= self.budget_units
    }

    /// The buffers' own upstream gradient (written by [`GradBuffers::set_d_image`], or by a
    /// loss recorded before the backward) and results, as the backward's ranges.
    pub fn io(&self) -> GradIo<'_> {
        GradIo {
            upstream: self.d_image.whole(),
            positions: self.position_grads.whole(),
            colors: self.color_grads.whole(),
        }
    }

    /// Declares whether the upstream gradient's RGB part is zero everywhere (silhouette losses:
    /// only alpha has a gradient). Then the backward is recorded without its colour terms, which
    /// would only add exact zeros: the gradients are the same bits, for less work. Off by
    /// default; with a non-zero RGB upstream it would drop the colour's share.
    pub fn set_alpha_only(&mut self, alpha_only: bool) {
        self.alpha_only = alpha_only;
    }

    /// Whether the backward of `scene` differentiates alpha only: declared, or a silhouette
    /// render (which has no colour to differentiate).
    fn alpha_only(&self, scene: &GpuScene) -> bool {
        self.alpha_only || scene.silhouette_only
    }

    /// The fine kernels' modes for this backward of `scene`.
    pub(super) fn modes(&self, scene: &GpuScene) -> FineModes {
        FineModes::new(&scene.settings, true)
            .alpha_only_if(self.alpha_only(scene))
            .texel_masks_if(self.texel_masks(scene))
    }

    /// Whether the partials of `scene`'s backward carry masks of the texel slots they wrote
    /// (then no fill zeroes the slots first): surface colours, with colour terms, and few
    /// enough texels a face for one 32-bit mask.
    pub(super) fn texel_masks(&self, scene: &GpuScene) -> bool {
        self.color_work(scene) == ColorWork::Texels
            && scene.texture_res * scene.texture_res <= MAX_MASKED_TEXELS
    }

    /// What the tiled kernel does per face besides the screen sums.
    pub(crate) fn color_work(&self, scene: &GpuScene) -> ColorWork {
        match scene.settings.color_mode {
            _ if self.alpha_only(scene) => ColorWork::None,
            ColorMode::Vertex => ColorWork::Vertex,
            ColorMode::Surface => ColorWork::Texels,
        }
    }

    /// The (face, tile) entries one chunk of the tiled partials holds, or `u64::MAX` once the
    /// partials are as large as they may be (more entries then take more chunks, and new
    /// buffers would not help); 0 for brute force.
    pub fn entry_capacity(&self) -> u64 {
        match self.method {
            Method::Brute => 0,
            Method::Tiled { .. } if self.chunk_units >= self.budget_units => u64::MAX,
            Method::Tiled { .. } => self.chunk_units,
        }
    }

    /// Units of work (tiled: (face, tile) entries; brute: (view, face, band)) one chunk of
    /// partials holds.
    pub fn chunk_units(&self) -> u64 {
        self.chunk_units
    }

    /// Brute force: bands of rows per view (0 for tiled).
    pub fn bands(&self) -> u32 {
        self.bands
    }

    /// Uploads dL/d(image): RGBA per output pixel, view-major, row-major.
    pub fn set_d_image(&self, ctx: &Context, scene: &GpuScene, d_image: &[[f32; 4]]) -> Result<()> {
        let s = &scene.settings;
        let want = (s.width * s.height * scene.view_count) as usize;
        if d_image.len() != want {
            return Err(Error::Input(format!(
                "the image gradient has {} pixels; {} views of {}x{} need {want}",
                d_image.len(),
                scene.view_count,
                s.width,
                s.height
            )));
        }
        if let Some(i) = d_image
            .iter()
            .position(|g| !g.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Input(format!(
                "the image gradient is not finite at pixel {} of view {}",
                i % (s.width * s.height) as usize,
                i / (s.width * s.height) as usize
            )));
        }
        ctx.write_buffer(&self.d_image, 0, d_image)
    }
}

/// Each mesh's views in ascending order, as CSR in one list: `meshes + 1` offsets, then the
/// view indices (what `grad_gather.comp` visits per vertex, in the order the twin sums them).
fn mesh_view_lists(scene: &GpuScene) -> Vec<u32> {
    let meshes = scene.meshes.len();
    let mut lists: Vec<Vec<u32>> = vec![Vec::new(); meshes];
    for (v, (m, _)) in scene.views_host.iter().enumerate() {
        lists[*m].push(v as u32);
    }
    let mut out = Vec::with_capacity(meshes + 1 + scene.views_host.len());
    let mut offset = 0;
    out.push(0);
    for list in &lists {
        offset += list.len() as u32;
        out.push(offset);
    }
    out.extend(lists.into_iter().flatten());
    out
}
