//! The GPU backward pass (SPEC §3, §4): from dL/d(image) to dL/d(world vertex positions), dL/d(raw
//! texels or vertex colours) and dL/d(camera), the exact derivative of the forward in f32.
//!
//! The stages mirror the f64 twin [`crate::raster::reference_grad`] step for step:
//!
//! 1. **Per (pixel, face)** (`kernels/include/raster_grad.glsl`, the twin's `pixel_face_grad`):
//!    from the pixel's upstream gradient and the forward's [`PixelAux`](super::fine::PixelAux),
//!    one face's contribution, independently of the other faces.
//! 2. **Per unit of work**, a partial gradient (vec4 records: the 3 screen corners, then the
//!    colour slots, 3 vertex colours or R² texels, RGB each; [`grad_stride`]), either
//!    - tiled (`grad_tiled.comp`): a unit is a (face, tile) entry of the forward's binning (no
//!      second binning), summed over the tile's pixels; a tile crowded past the driver's loop
//!      cap is split over several workgroups; or
//!    - brute force (`grad_brute.comp`, the baseline): a unit is a (view, face, band of rows),
//!      summed over the band's pixels; bands keep each invocation under the loop cap.
//!
//!    An item's (view, face) units are contiguous (item-major). The partials are written one
//!    **chunk** of units at a time into one buffer of at most one storage binding (or a smaller
//!    `GradSplit::chunk_units`, a test knob), so memory stays bounded whatever the texture
//!    resolution.
//! 3. **Per face**, after each chunk: `grad_reduce.comp` adds each item's partials to its screen
//!    (and vertex-colour) gradient, and `grad_reduce_texels.comp` adds the texel slots to the
//!    face's dL/d(lit texel) of the view's mesh. Both keep running sums in unit order, so the
//!    result is bit for bit the same however the units are chunked.
//! 4. **Per (view, face)** (`grad_world.comp`, the twin's `face_screen_to_world_grad`): screen →
//!    camera → world, through perspective, orthographic or the matrix projection.
//! 5. **Per vertex** (`grad_gather.comp`, the twin's `VertexFaces::gather`): summed over views
//!    and incident corners in a fixed order.
//! 6. **On the host, in f64**, where the forward lights: the lighting's backward (raw colours,
//!    and normals → positions) with the twin's own functions, and the camera gradient (look-at).
//!
//! Each value has one writer and a fixed summation order: no float atomics, and repeated runs
//! are bit-identical. On a driver that caps shader loops
//! ([`crate::gpu::DeviceInfo::shader_loop_limit`]) every dispatch's loop count is bounded on the
//! host from the real iteration counts (`raster::loops`); work is split (bands,
//! tile parts, reduction windows and view ranges) rather than refused.

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use super::fine::{FineModes, MAX_MASKED_TEXELS, RasterPush, tiled_backward_workgroup};
use super::loops::{
    ColorWork, brute_backward_iterations, reduce_iterations, texel_reduce_iterations,
    tiled_backward_iterations,
};
use super::method::Method;
use super::reference_grad::{
    self, Gradients, VertexFaces, camera_grad, lighting_grad_surface, lighting_grad_vertex,
};
use super::scene::{Binned, GpuScene};
use super::settings::ColorMode;
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{
    Buffer, BufferRange, Context, Kernel, KernelVariants, MemoryKind, Recorder, TEXEL_BYTES, specs,
};

/// Push constants of `grad_tiled.comp` and `grad_brute.comp`: the fine pass's, then the chunk.
/// Twin of `Push` in `raster_fine.glsl` with `FINE_BACKWARD`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GradPush {
    fine: RasterPush,
    chunk_begin: u32,
    chunk_end: u32,
    split: u32,
    parts: u32,
}

/// Push constants of `grad_reduce.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ReducePush {
    item_count: u32,
    first_item: u32,
    stride: u32,
    width: u32,
    unit_total: u32,
    chunk_begin: u32,
    window_begin: u32,
    window_end: u32,
    parts: u32,
    pad: [u32; 3],
}

/// Push constants of `grad_reduce_texels.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct TexelReducePush {
    face_count: u32,
    texels: u32,
    texel_begin: u32,
    texel_end: u32,
    texel_group: u32,
    stride: u32,
    unit_total: u32,
    chunk_begin: u32,
    window_begin: u32,
    window_end: u32,
    parts: u32,
    first_view: u32,
    group_views: u32,
    view_begin: u32,
    view_end: u32,
    masked: u32,
}

/// Push constants of `grad_world.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct WorldPush {
    face_count: u32,
    view_count: u32,
    vertex_count: u32,
    stride: u32,
    position_offset: u32,
    position_stride: u32,
}

/// Push constants of `grad_gather.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GatherPush {
    vertex_count: u32,
    mesh_count: u32,
    face_count: u32,
    view_count: u32,
    stride: u32,
    vertex_colors: u32,
    pad: [u32; 2],
}

/// The backward's pipelines, made once per context.
pub struct GradKernels {
    tiled: KernelVariants,
    brute: KernelVariants,
    reduce: Kernel,
    reduce_texels: Kernel,
    world: Kernel,
    gather: Kernel,
}

impl GradKernels {
    /// Builds the pipelines.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            tiled: KernelVariants::new(&specs::GRAD_TILED),
            brute: KernelVariants::new(&specs::GRAD_BRUTE),
            reduce: Kernel::new(ctx, &specs::GRAD_REDUCE)?,
            reduce_texels: Kernel::new(ctx, &specs::GRAD_REDUCE_TEXELS)?,
            world: Kernel::new(ctx, &specs::GRAD_WORLD)?,
            gather: Kernel::new(ctx, &specs::GRAD_GATHER)?,
        })
    }
}

/// Floats per partial gradient: a vec4 per screen corner (x_s, y_s, z), then one per colour
/// slot (R² texels or 3 corners) RGB, each with an unused fourth float (whole vec4s keep a
/// kernel's read-modify-write of a slot one load and one store; see `raster_grad.glsl`).
pub fn grad_stride(mode: ColorMode, texture_res: u32) -> u32 {
    4 * (3 + reference_grad::color_slots(mode, texture_res) as u32)
}

/// Floats per (view, face) gradient after the reduction: 9 screen coordinates, and with vertex
/// colours the 3 corners' RGB (texel gradients go straight to the per-texel sums).
pub fn face_grad_width(mode: ColorMode) -> u32 {
    match mode {
        ColorMode::Surface => 9,
        ColorMode::Vertex => 18,
    }
}

// `GradSplit` is public only with the `test-knobs` feature (softvk's own tests turn it on
// through their dev-dependency on the crate): one definition, two visibilities.
macro_rules! grad_split {
    ($vis:vis) => {
        /// How the backward may split its work. The default (all `None`) splits only where it
        /// must: the partials take at most one storage binding, and on a driver that caps shader
        /// loops, bands, tile parts and reduction windows are as large as the cap allows.
        /// Smaller values give the same gradients (bit for bit for `chunk_units` and
        /// `tile_faces`; brute force's bands regroup its sums) and exist to exercise the split
        /// paths on small scenes: a test knob (the `test-knobs` feature).
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
        $vis struct GradSplit {
            /// At most this many units (tiled: (face, tile) entries; brute: (view, face, band))
            /// per chunk of partials.
            pub chunk_units: Option<u64>,
            /// Brute force: at most this many rows per band.
            pub band_rows: Option<u32>,
            /// Tiled: at most this many of a tile's faces per workgroup (rounded up to a
            /// multiple of 64).
            pub tile_faces: Option<u32>,
        }
    };
}
#[cfg(feature = "test-knobs")]
grad_split!(pub);
#[cfg(not(feature = "test-knobs"))]
grad_split!(pub(crate));

/// The buffers of one scene's backward, reusable across backward passes of that scene.
pub struct GradBuffers {
    d_image: Buffer,
    partials: Buffer,
    face_grads: Buffer,
    corner_world: Buffer,
    corner_cam: Buffer,
    vertex_offsets: Buffer,
    vertex_slots: Buffer,
    /// Each mesh's views, as `grad_gather.comp` reads them ([`mesh_view_lists`]).
    mesh_views: Buffer,
    position_grads: Buffer,
    color_grads: Buffer,
    method: Method,
    stride: u32,
    width: u32,
    split: GradSplit,
    /// Units one chunk of partials holds, and the most it may hold (the budget).
    chunk_units: u64,
    budget_units: u64,
    /// Brute force: rows per band and bands per view.
    band_rows: u32,
    bands: u32,
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
    fn check(&self, scene: &GpuScene) -> Result<()> {
        let [upstream, positions, colors] = Self::sizes(scene);
        self.upstream
            .require(upstream, "the backward's upstream gradient")?;
        self.positions
            .require(positions, "the backward's position gradients")?;
        self.colors
            .require(colors, "the backward's colour gradients")
    }
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

/// Rows per band of the brute-force backward over a `width × height` image: the whole image, or
/// fewer rows where `cap` or the driver's loop `limit` asks.
fn band_rows(
    width: u32,
    height: u32,
    limit: Option<u64>,
    cap: Option<u32>,
    device: &str,
) -> Result<u32> {
    let mut rows = u64::from(height);
    if let Some(cap) = cap {
        rows = rows.min(u64::from(cap.max(1)));
    }
    if let Some(limit) = limit {
        let fit =
            limit.saturating_sub(brute_backward_iterations(0, width)) / (u64::from(width) + 1);
        if fit == 0 {
            return Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                what: format!("the brute-force backward of one row of {width} pixels"),
                need: brute_backward_iterations(1, width),
                max: limit,
                device: device.to_string(),
                hint: "use the tiled method",
            });
        }
        rows = rows.min(fit);
    }
    debug_assert!(limit.is_none_or(|l| brute_backward_iterations(rows, width) <= l));
    Ok(rows as u32)
}

/// Faces of one tile per workgroup of `grad_tiled.comp` (a multiple of its `workgroup`
/// invocations), for tiles of at most `run` entries: all of them, or fewer where `cap` or the
/// driver's loop `limit` asks.
fn tile_faces(
    run: u64,
    tile: u32,
    work: (u32, u32, ColorWork),
    limit: Option<u64>,
    cap: Option<u32>,
    device: &str,
) -> Result<u64> {
    let wg = u64::from(work.1.max(1));
    let mut faces = run.max(1).div_ceil(wg) * wg;
    if let Some(cap) = cap {
        faces = faces.min(u64::from(cap.max(1)).div_ceil(wg) * wg);
    }
    if let Some(limit) = limit {
        let iterations = |faces| tiled_backward_iterations(run, tile, faces, work);
        let fixed = iterations(0);
        let per_batch = tiled_backward_iterations(run.max(wg), tile, wg, work)
            - tiled_backward_iterations(run.max(wg), tile, 0, work);
        let batches = limit.saturating_sub(fixed) / per_batch;
        if batches == 0 {
            return Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                what: format!(
                    "the tiled backward of one batch of {wg} faces over a {tile}x{tile} tile"
                ),
                need: iterations(wg),
                max: limit,
                device: device.to_string(),
                hint: "use smaller tiles",
            });
        }
        faces = faces.min(wg * batches);
        debug_assert!(iterations(faces) <= limit);
    }
    Ok(faces)
}

/// Texels per invocation of `grad_reduce_texels.comp` for a dispatch over `texels` texels: all
/// of them on a CPU device ([`Context::cpu_workgroups`]), whose driver pays a set-up per
/// subgroup of invocations (llvmpipe: per (face, texel), the reduction took twice as long on
/// spot-256; BENCHMARKS.md); one on a GPU, which wants the threads.
fn texel_reduce_group(ctx: &Context, texels: u32) -> u32 {
    if ctx.cpu_workgroups() {
        texels.max(1)
    } else {
        1
    }
}

/// How one chunk's partials are added up: units per `grad_reduce.comp` dispatch (its window),
/// and views, units and texels per `grad_reduce_texels.comp` dispatch, for a chunk of `chunk`
/// units where an item holds at most `per_item` units, the group has `views` views and a face
/// `texels` texels. Under a loop cap of at least 8 iterations, every step is at least 1.
fn reduce_plan(
    chunk: u64,
    per_item: u64,
    views: u64,
    texels: u64,
    limit: Option<u64>,
) -> ReducePlan {
    let texels = texels.max(1);
    let Some(limit) = limit else {
        return ReducePlan {
            window: chunk,
            view_step: views,
            texel_window: chunk,
            texel_step: texels,
        };
    };
    let budget = limit - 2;
    let window = if reduce_iterations(per_item) <= limit {
        chunk
    } else {
        budget
    };
    let fits = |views: u64, units: u64, texels: u64| {
        texel_reduce_iterations(views, units, texels) <= limit
    };
    let (view_step, texel_window, texel_step) =
        if fits(views, (views * per_item).min(chunk), texels) {
            (views, chunk, texels)
        } else {
            // Views per dispatch with every texel and whole items; else one view, fewer texels
            // and a window of units.
            let per_view = 2 + texels + (texels + 1) * per_item;
            let step = (budget / per_view).min(views);
            if step >= 1 {
                (step, chunk, texels)
            } else {
                let texel_step = texels.min((budget - 3) / 2);
                let units = (budget - 2 - texel_step) / (texel_step + 1);
                (1, units, texel_step)
            }
        };
    debug_assert!(reduce_iterations(per_item.min(window)) <= limit);
    debug_assert!(fits(
        view_step,
        (view_step * per_item).min(texel_window),
        texel_step
    ));
    ReducePlan {
        window: window.max(1),
        view_step: view_step.max(1),
        texel_window: texel_window.max(1),
        texel_step: texel_step.max(1),
    }
}

/// [`reduce_plan`]'s answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct ReducePlan {
    /// Units per `grad_reduce.comp` dispatch.
    window: u64,
    /// Views per `grad_reduce_texels.comp` dispatch.
    view_step: u64,
    /// Units per `grad_reduce_texels.comp` dispatch.
    texel_window: u64,
    /// Texels per `grad_reduce_texels.comp` dispatch.
    texel_step: u64,
}

/// Workgroups of `size` invocations for `n` invocations, as the u32 a dispatch takes.
fn groups(n: u64, size: u64) -> Result<u32> {
    u32::try_from(n.div_ceil(size)).map_err(|_| {
        Error::Limit(format!(
            "the backward would dispatch {n} invocations at once"
        ))
    })
}

/// One view group's units, for the reductions.
struct UnitGroup<'a> {
    first_view: u32,
    views: u32,
    units: u64,
    /// Brute force: units per item (bands); 0: tiled, from `offsets`.
    parts: u32,
    offsets: BufferRange<'a>,
    /// The most units one item holds.
    per_item: u64,
}

impl GradBuffers {
    /// Buffers for the backward of `scene` by `method`. Tiled needs the scene's last forward run
    /// to have been tiled with the same tile size (the backward reuses its binning).
    pub fn new(ctx: &Context, scene: &GpuScene, method: Method) -> Result<Self> {
        Self::build(ctx, scene, method, GradSplit::default(), None)
    }

    /// As [`GradBuffers::new`], splitting the work at most as `split` says (a test knob: the
    /// `test-knobs` feature).
    #[cfg(feature = "test-knobs")]
    pub fn with_split(
        ctx: &Context,
        scene: &GpuScene,
        method: Method,
        split: GradSplit,
    ) -> Result<Self> {
        Self::build(ctx, scene, method, split, None)
    }

    /// As [`GradBuffers::new`], with tiled partials for `entries` (face, tile) entries (at least
    /// the scene's largest group; at most what one binding holds, more take several chunks): a
    /// guarded fitting loop sizes them as its bins.
    pub fn with_entry_capacity(
        ctx: &Context,
        scene: &GpuScene,
        method: Method,
        entries: u64,
    ) -> Result<Self> {
        Self::build(ctx, scene, method, GradSplit::default(), Some(entries))
    }

    fn build(
        ctx: &Context,
        scene: &GpuScene,
        method: Method,
        split: GradSplit,
        entries: Option<u64>,
    ) -> Result<Self> {
        if let Method::Tiled { tile } = method {
            if scene.tile != Some(tile) || scene.groups.is_empty() {
                return Err(Error::Input(format!(
                    "the tiled backward (tile {tile}) needs a forward run with the same tiles \
                     first (the scene was last binned with {:?})",
                    scene.tile
                )));
            }
        }
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
            Method::Tiled { .. } => {
                let most = scene.groups.iter().map(|g| g.entries).max().unwrap_or(0);
                // Headroom, so that a fit whose entries breathe does not reallocate every step.
                (0, 0, entries.map_or(most + most / 4, |e| e.max(most)))
            }
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

    /// Whether these buffers serve the backward of `scene`'s last forward as well as new ones
    /// would: made for a scene of its sizes and method, with room for its (face, tile) entries
    /// in as few chunks. For a scene with the same meshes' topology and views as the one they
    /// were made for (the vertex adjacency and each mesh's views are uploaded once): a loop
    /// that writes new vertices into its scene ([`GpuScene::update_meshes`]) keeps one set.
    /// Keeping them is faster than making them again: on a CPU device fresh device memory
    /// costs a page fault per page at its first write (about 40 ms of a 200 ms backward on the
    /// deformation demo's 120 views on llvmpipe).
    pub fn fits(&self, scene: &GpuScene, method: Method) -> bool {
        if self.method != method || self.made_for != SceneSizes::of(scene) {
            return false;
        }
        match method {
            Method::Brute => true,
            Method::Tiled { tile } => {
                let most = scene.groups.iter().map(|g| g.entries).max().unwrap_or(0);
                scene.tile == Some(tile)
                    && (self.chunk_units >= most || self.chunk_units >= self.budget_units)
            }
        }
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
    fn modes(&self, scene: &GpuScene) -> FineModes {
        FineModes::new(&scene.settings, true)
            .alpha_only_if(self.alpha_only(scene))
            .texel_masks_if(self.texel_masks(scene))
    }

    /// Whether the partials of `scene`'s backward carry masks of the texel slots they wrote
    /// (then no fill zeroes the slots first): surface colours, with colour terms, and few
    /// enough texels a face for one 32-bit mask.
    fn texel_masks(&self, scene: &GpuScene) -> bool {
        self.color_work(scene) == ColorWork::Texels
            && scene.texture_res * scene.texture_res <= MAX_MASKED_TEXELS
    }

    /// What the tiled kernel does per face besides the screen sums.
    fn color_work(&self, scene: &GpuScene) -> ColorWork {
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

impl GradKernels {
    fn fine_push(scene: &GpuScene, stride: u32) -> RasterPush {
        let s = &scene.settings;
        let mut push = RasterPush::new(
            s,
            scene.width,
            scene.height,
            scene.face_count,
            scene.view_count,
            scene.vertex_count,
            scene.texture_res,
        );
        push.out_width = s.width;
        push.out_height = s.height;
        push.grad_stride = stride;
        push
    }

    /// Records the backward of the forward that left `binned`: dL/d(output RGBA) is read from
    /// `io.upstream` (view-major, as [`GradBuffers::set_d_image`] lays it out), dL/d(positions)
    /// and dL/d(lit colours) are written to `io.positions` and `io.colors` (xyz / RGB triples,
    /// mesh after mesh); `gb` holds the intermediate sums. Per-face gradients by `gb`'s method
    /// (partials chunk by chunk, each chunk reduced into the running per-face and per-texel
    /// sums), then the world chain and the vertex sums. Any of the ranges may be a host's
    /// ([`Context::import_buffer`]). [`GradKernels::finish`] reads the results back and adds the
    /// host's share.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        binned: &Binned<'_>,
        gb: &GradBuffers,
        io: &GradIo<'_>,
    ) -> Result<()> {
        let scene = binned.scene();
        if binned.method() != gb.method {
            return Err(Error::Misuse(format!(
                "the backward buffers were made for {:?}, the forward ran {:?}",
                gb.method,
                binned.method()
            )));
        }
        io.check(scene)?;
        let items = scene.face_count * scene.view_count;
        let name = match gb.method {
            Method::Brute => "grad brute",
            Method::Tiled { .. } => "grad tiled",
        };
        rec.pass(name, |rec| {
            rec.fill(gb.face_grads.whole(), 0);
            if scene.settings.color_mode == ColorMode::Surface {
                rec.fill(io.colors, 0);
            }
            match gb.method {
                Method::Brute => self.record_brute(rec, scene, gb, io),
                Method::Tiled { tile } => self.record_tiled(rec, scene, gb, io, tile),
            }
        })?;
        let world = WorldPush {
            face_count: scene.face_count,
            view_count: scene.view_count,
            vertex_count: scene.vertex_count,
            stride: gb.width,
            position_offset: scene.position_layout.offset,
            position_stride: scene.position_layout.stride,
        };
        rec.pass("grad world", |rec| {
            rec.dispatch(
                &self.world,
                &specs::GradWorldBindings {
                    positions: scene.position_range()?,
                    faces: scene.faces.whole(),
                    views: scene.views.whole(),
                    face_grads: gb.face_grads.whole(),
                    corner_world: gb.corner_world.whole(),
                    corner_cam: gb.corner_cam.whole(),
                }
                .for_kernel(&self.world)?,
                &world,
                items.div_ceil(64),
            )
        })?;
        let meshes = scene.meshes.len() as u32;
        let vertex_colors = scene.settings.color_mode == ColorMode::Vertex;
        let gather = GatherPush {
            vertex_count: scene.vertex_count,
            mesh_count: meshes,
            face_count: scene.face_count,
            view_count: scene.view_count,
            stride: gb.width,
            vertex_colors: u32::from(vertex_colors),
            pad: [0; 2],
        };
        rec.pass("grad gather", |rec| {
            rec.dispatch(
                &self.gather,
                &specs::GradGatherBindings {
                    offsets: gb.vertex_offsets.whole(),
                    slots: gb.vertex_slots.whole(),
                    views: gb.mesh_views.whole(),
                    corner_world: gb.corner_world.whole(),
                    face_grads: gb.face_grads.whole(),
                    position_grads: io.positions,
                    color_grads: io.colors,
                }
                .for_kernel(&self.gather)?,
                &gather,
                (scene.vertex_count * meshes).div_ceil(64),
            )
        })
    }

    /// Brute force: (view, face, band) units, chunk by chunk.
    fn record_brute(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        gb: &GradBuffers,
        io: &GradIo<'_>,
    ) -> Result<()> {
        let limit = rec.context().info().shader_loop_limit();
        if let Some(limit) = limit {
            let n = brute_backward_iterations(u64::from(gb.band_rows), scene.width);
            if n > limit {
                return Err(Error::DeviceLimit {
                    kind: LimitKind::LoopIterations,
                    what: format!(
                        "the brute-force backward over bands of {} rows of {} pixels",
                        gb.band_rows, scene.width
                    ),
                    need: n,
                    max: limit,
                    device: rec.context().info().name.clone(),
                    hint: "make the GradBuffers on this device",
                });
            }
        }
        let items = u64::from(scene.face_count) * u64::from(scene.view_count);
        let units = items * u64::from(gb.bands);
        let group = UnitGroup {
            first_view: 0,
            views: scene.view_count,
            units,
            parts: gb.bands,
            // Unused with `parts`; any buffer binds.
            offsets: gb.vertex_offsets.whole(),
            per_item: u64::from(gb.bands),
        };
        let kernel = self
            .brute
            .get(rec.context(), &gb.modes(scene).constants(rec.context(), 64))?;
        let mut begin = 0;
        while begin < units {
            let end = units.min(begin + gb.chunk_units);
            self.clear_texel_partials(rec, scene, gb, end - begin);
            let push = GradPush {
                fine: Self::fine_push(scene, gb.stride),
                chunk_begin: begin as u32,
                chunk_end: end as u32,
                split: gb.band_rows,
                parts: gb.bands,
            };
            rec.dispatch(
                &kernel,
                &specs::GradBruteBindings {
                    setups: scene.setups.whole(),
                    colors: scene.colors.whole(),
                    faces: scene.faces.whole(),
                    image: scene.image.whole(),
                    aux: scene.aux.whole(),
                    d_image: io.upstream,
                    partials: gb.partials.whole(),
                }
                .for_kernel(&kernel)?,
                &push,
                groups(end - begin, 64)?,
            )?;
            self.record_reduce(rec, scene, gb, io, &group, begin, end, limit)?;
            begin = end;
        }
        Ok(())
    }

    /// Tiled: per view group, its (face, tile) entries chunk by chunk.
    fn record_tiled(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        gb: &GradBuffers,
        io: &GradIo<'_>,
        tile: u32,
    ) -> Result<()> {
        let grid = scene.grid(tile)?;
        if scene.tile != Some(tile) {
            return Err(Error::Misuse(format!(
                "the tiled backward (tile {tile}) needs the scene binned with those tiles"
            )));
        }
        let limit = rec.context().info().shader_loop_limit();
        // The modes, then the tile size (constant 6 of `grad_tiled.comp`).
        let modes = gb
            .modes(scene)
            .constants(rec.context(), tiled_backward_workgroup(rec.context()));
        let mut constants = modes.to_vec();
        constants.push(tile);
        let kernel = self.tiled.get(rec.context(), &constants)?;
        for (group, bins) in scene.groups.iter().zip(&scene.bins) {
            let grid = grid.window(group.tile_rows.0, group.tile_rows.1)?;
            if group.entries == 0 {
                // No face touches these views: their gradients stay zero.
                continue;
            }
            let run = group.max_tile_entries;
            let work = (
                rec.context().info().subgroup_size,
                tiled_backward_workgroup(rec.context()),
                gb.color_work(scene),
            );
            let device = &rec.context().info().name;
            let faces = tile_faces(run, tile, work, limit, gb.split.tile_faces, device)?;
            let tiles = grid.tiles_per_view() * u64::from(group.views);
            let units = UnitGroup {
                first_view: group.first,
                views: group.views,
                units: group.entries,
                parts: 0,
                offsets: bins.offsets().whole(),
                // A face enters each tile of its view at most once.
                per_item: grid.tiles_per_view().min(group.entries),
            };
            let mut begin = 0;
            while begin < group.entries {
                let end = group.entries.min(begin + gb.chunk_units);
                self.clear_texel_partials(rec, scene, gb, end - begin);
                let mut fine = Self::fine_push(scene, gb.stride);
                fine.first_view = group.first;
                fine.view_count = group.views;
                fine.tile_size = tile;
                fine.tiles_x = grid.tiles_x;
                fine.tiles_y = grid.tiles_y;
                fine.first_row = grid.first_row;
                fine.entry_total = group.entries as u32;
                let parts = run.min(end - begin).div_ceil(faces).max(1);
                let push = GradPush {
                    fine,
                    chunk_begin: begin as u32,
                    chunk_end: end as u32,
                    split: faces as u32,
                    parts: parts as u32,
                };
                let bindings = specs::GradTiledBindings {
                    setups: scene.setups.whole(),
                    colors: scene.colors.whole(),
                    faces: scene.faces.whole(),
                    image: scene.image.whole(),
                    aux: scene.aux.whole(),
                    d_image: io.upstream,
                    partials: gb.partials.whole(),
                    pairs: bins.entries().whole(),
                    pair_items: bins.entry_items().whole(),
                    ranges: bins.ranges().whole(),
                };
                rec.dispatch(
                    &kernel,
                    &bindings.for_kernel(&kernel)?,
                    &push,
                    groups(tiles * parts, 1)?,
                )?;
                self.record_reduce(rec, scene, gb, io, &units, begin, end, limit)?;
                begin = end;
            }
        }
        Ok(())
    }

    /// Surface colours: zeroes the texel slots the next chunk of `units` units sums into.
    fn clear_texel_partials(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        gb: &GradBuffers,
        units: u64,
    ) {
        if scene.settings.color_mode == ColorMode::Surface && !gb.texel_masks(scene) {
            rec.fill(gb.partials.range(0, 4 * units * u64::from(gb.stride)), 0);
        }
    }

    /// Adds the partials of units `begin .. end` (the chunk in `gb.partials`) of `group` to the
    /// running per-face sums and, with surface colours, per-texel sums, in unit order.
    #[allow(clippy::too_many_arguments)]
    fn record_reduce(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        gb: &GradBuffers,
        io: &GradIo<'_>,
        group: &UnitGroup<'_>,
        begin: u64,
        end: u64,
        limit: Option<u64>,
    ) -> Result<()> {
        let item_count = group.views * scene.face_count;
        let texels = scene.texture_res * scene.texture_res;
        let ReducePlan {
            window,
            view_step,
            texel_window,
            texel_step,
        } = reduce_plan(
            end - begin,
            group.per_item,
            u64::from(group.views),
            u64::from(texels),
            limit,
        );
        let mut w = begin;
        while w < end {
            let w_end = end.min(w + window);
            let push = ReducePush {
                item_count,
                first_item: group.first_view * scene.face_count,
                stride: gb.stride,
                width: gb.width,
                unit_total: group.units as u32,
                chunk_begin: begin as u32,
                window_begin: w as u32,
                window_end: w_end as u32,
                parts: group.parts,
                pad: [0; 3],
            };
            rec.dispatch(
                &self.reduce,
                &specs::GradReduceBindings {
                    offsets: group.offsets,
                    partials: gb.partials.whole(),
                    face_grads: gb.face_grads.whole(),
                }
                .for_kernel(&self.reduce)?,
                &push,
                groups(u64::from(item_count), 64)?,
            )?;
            w = w_end;
        }
        if scene.settings.color_mode != ColorMode::Surface {
            return Ok(());
        }
        // Texel ranges are independent; within one, windows and views go in unit order.
        let mut t = 0;
        while t < texels {
            let t_end = texels.min(t + texel_step as u32);
            let group_texels = texel_reduce_group(rec.context(), t_end - t);
            let invocations =
                u64::from(scene.face_count) * u64::from((t_end - t).div_ceil(group_texels));
            let mut w = begin;
            while w < end {
                let w_end = end.min(w + texel_window);
                let mut v = 0;
                while v < group.views {
                    let v_end = group.views.min(v + view_step as u32);
                    let push = TexelReducePush {
                        face_count: scene.face_count,
                        texels,
                        texel_begin: t,
                        texel_end: t_end,
                        texel_group: group_texels,
                        stride: gb.stride,
                        unit_total: group.units as u32,
                        chunk_begin: begin as u32,
                        window_begin: w as u32,
                        window_end: w_end as u32,
                        parts: group.parts,
                        first_view: group.first_view,
                        group_views: group.views,
                        view_begin: v,
                        view_end: v_end,
                        masked: u32::from(gb.texel_masks(scene)),
                    };
                    rec.dispatch(
                        &self.reduce_texels,
                        &specs::GradReduceTexelsBindings {
                            views: scene.views.whole(),
                            offsets: group.offsets,
                            partials: gb.partials.whole(),
                            texel_grads: io.colors,
                        }
                        .for_kernel(&self.reduce_texels)?,
                        &push,
                        groups(invocations, 64)?,
                    )?;
                    v = v_end;
                }
                w = w_end;
            }
            t = t_end;
        }
        Ok(())
    }

    /// Reads the recorded backward's results and adds the host's f64 share: lighting (raw
    /// colours; normals → positions) and, with `cameras`, the camera gradient per view.
    /// Positions and colours come mesh after mesh for a batch.
    pub fn finish(
        &self,
        ctx: &Context,
        scene: &GpuScene,
        gb: &GradBuffers,
        io: &GradIo<'_>,
        cameras: bool,
    ) -> Result<Gradients> {
        let nv = scene.vertex_count as usize;
        let nf = scene.face_count as usize;
        let batch = scene.meshes.len();
        let widen = |v: [f32; 3]| v.map(f64::from);
        let positions: Vec<[f32; 3]> =
            ctx.read_buffer(io.positions.buffer, io.positions.offset, nv * batch)?;
        let mode = scene.settings.color_mode;
        let slots = reference_grad::color_slots(mode, scene.texture_res);
        let per_mesh_colors = match mode {
            ColorMode::Surface => nf * slots,
            ColorMode::Vertex => nv,
        };
        let lit: Vec<[f32; 3]> =
            ctx.read_buffer(io.colors.buffer, io.colors.offset, per_mesh_colors * batch)?;
        let adjacency = VertexFaces::new(&scene.meshes[0].faces, nv);
        let mut out = Gradients {
            positions: Vec::with_capacity(nv * batch),
            colors: Vec::with_capacity(per_mesh_colors * batch),
            cameras: Vec::new(),
        };
        for (m, mesh) in scene.meshes.iter().enumerate() {
            let d_lit: Vec<[f64; 3]> = lit[m * per_mesh_colors..(m + 1) * per_mesh_colors]
                .iter()
                .map(|&c| widen(c))
                .collect();
            if d_lit.iter().all(|c| *c == [0.0; 3]) {
                // Nothing reached the lit colours (an alpha-only upstream): lighting's share is
                // exactly zero, for colours and positions alike; skip computing it.
                let texels = match mode {
                    ColorMode::Surface => mesh.textures.len(),
                    ColorMode::Vertex => nv,
                };
                out.positions.extend(
                    positions[m * nv..(m + 1) * nv]
                        .iter()
                        .map(|&g| widen(g).map(|c| c + 0.0)),
                );
                out.colors.extend(std::iter::repeat_n([0.0; 3], texels));
                continue;
            }
            let (colors, corners) = match mode {
                ColorMode::Surface => lighting_grad_surface(
                    &scene.lighting,
                    &mesh.positions,
                    &mesh.faces,
                    mesh.texture_res,
                    &mesh.textures,
                    &d_lit,
                ),
                ColorMode::Vertex => lighting_grad_vertex(
                    &scene.lighting,
                    &mesh.positions,
                    &mesh.faces,
                    mesh.vertex_colors.as_deref(),
                    &d_lit,
                ),
            };
            let from_light = adjacency.gather(&corners);
            for (v, light) in from_light.iter().enumerate() {
                let g = widen(positions[m * nv + v]);
                out.positions.push(std::array::from_fn(|k| g[k] + light[k]));
            }
            out.colors.extend(colors);
        }
        if cameras {
            let items = nf * scene.view_count as usize;
            let cam: Vec<[f32; 3]> = ctx.read_buffer(&gb.corner_cam, 0, 3 * items)?;
            let world: Vec<[f32; 3]> = ctx.read_buffer(&gb.corner_world, 0, 3 * items)?;
            for (v, (m, camera)) in scene.views_host.iter().enumerate() {
                let mesh = &scene.meshes[*m];
                let mut d_rotation = [[0.0; 3]; 3];
                let mut d_world_sum = [0.0; 3];
                for (f, face) in mesh.faces.iter().enumerate() {
                    for (c, &vi) in face.iter().enumerate() {
                        let k = 3 * (v * nf + f) + c;
                        let d_cam = widen(cam[k]);
                        let rel: DVec3 = mesh.positions[vi as usize] - camera.eye;
                        for i in 0..3 {
                            for j in 0..3 {
                                d_rotation[i][j] += d_cam[i] * rel[j];
                            }
                            d_world_sum[i] += f64::from(world[k][i]);
                        }
                    }
                }
                out.cameras
                    .push(camera_grad(camera, d_rotation, d_world_sum));
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        for spec in [&specs::GRAD_TILED, &specs::GRAD_BRUTE] {
            assert_eq!(
                std::mem::size_of::<GradPush>() as u32,
                spec.push_constant_size,
                "{}",
                spec.name
            );
        }
        assert_eq!(std::mem::size_of::<GradPush>(), 116);
        assert_eq!(
            std::mem::size_of::<ReducePush>() as u32,
            specs::GRAD_REDUCE.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<TexelReducePush>() as u32,
            specs::GRAD_REDUCE_TEXELS.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<WorldPush>() as u32,
            specs::GRAD_WORLD.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<GatherPush>() as u32,
            specs::GRAD_GATHER.push_constant_size
        );
        assert_eq!(specs::GRAD_TILED.bindings.len(), 10);
        assert_eq!(specs::GRAD_BRUTE.bindings.len(), 7);
        assert_eq!(specs::GRAD_REDUCE.bindings.len(), 3);
        assert_eq!(specs::GRAD_REDUCE_TEXELS.bindings.len(), 4);
    }

    #[test]
    fn stride_counts_screen_and_colour_slots() {
        assert_eq!(grad_stride(ColorMode::Surface, 1), 16);
        assert_eq!(grad_stride(ColorMode::Surface, 3), 4 * (3 + 9));
        assert_eq!(grad_stride(ColorMode::Vertex, 5), 24);
        assert_eq!(face_grad_width(ColorMode::Surface), 9);
        assert_eq!(face_grad_width(ColorMode::Vertex), 18);
    }

    const CAP: u64 = 65_535;

    #[test]
    fn bands_are_the_most_rows_under_the_loop_cap() {
        // No cap: the whole image.
        assert_eq!(band_rows(256, 256, None, None, "llvmpipe").unwrap(), 256);
        assert_eq!(band_rows(256, 256, None, Some(7), "llvmpipe").unwrap(), 7);
        for (w, h) in [(256, 256), (1024, 1024), (64, 64), (65_532, 3)] {
            let rows = u64::from(band_rows(w, h, Some(CAP), None, "llvmpipe").unwrap());
            assert!(brute_backward_iterations(rows, w) <= CAP, "{w}x{h}");
            assert!(
                rows == u64::from(h) || brute_backward_iterations(rows + 1, w) > CAP,
                "{w}x{h}: {rows} rows is not the most"
            );
        }
        // 256 wide: 254 rows fit, so 256² takes two bands.
        assert_eq!(
            band_rows(256, 256, Some(CAP), None, "llvmpipe").unwrap(),
            254
        );
        assert!(matches!(
            band_rows(65_533, 1, Some(CAP), None, "llvmpipe"),
            Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                max: CAP,
                ..
            })
        ));
    }

    #[test]
    fn tile_parts_are_the_most_batches_under_the_loop_cap() {
        // blurry-256 at tile 32: all 5 856 faces in one tile. The cap is llvmpipe's alone, whose
        // subgroups have 4, 8 or 16 lanes (SSE, AVX2, AVX-512).
        let run = 5856;
        // Workgroups of 64 invocations, or of one subgroup (`tiled_backward_workgroup`).
        for sg in [4, 8, 16] {
            for wg in [64, sg] {
                for color in [ColorWork::None, ColorWork::Vertex, ColorWork::Texels] {
                    let work = (sg, wg, color);
                    let step = u64::from(wg);
                    let faces = tile_faces(run, 32, work, Some(CAP), None, "llvmpipe").unwrap();
                    assert_eq!(faces % step, 0);
                    assert!(tiled_backward_iterations(run, 32, faces, work) <= CAP);
                    assert!(tiled_backward_iterations(run, 32, faces + step, work) > CAP);
                    assert!(run.div_ceil(faces) > 1, "{sg} {wg} {color:?}");
                }
            }
        }
        // One subgroup a workgroup: a part takes 8 times fewer faces than 64 invocations do.
        let one = tile_faces(run, 32, (8, 8, ColorWork::Texels), Some(CAP), None, "").unwrap();
        let all = tile_faces(run, 32, (8, 64, ColorWork::Texels), Some(CAP), None, "").unwrap();
        assert!(one * 8 <= all + 64 && one * 8 + 64 >= all, "{one} {all}");
        // Small runs: one part; a cap rounds up to whole batches.
        let llvmpipe = (8, 64, ColorWork::Texels);
        assert_eq!(
            tile_faces(100, 8, llvmpipe, Some(CAP), None, "llvmpipe").unwrap(),
            128
        );
        assert_eq!(
            tile_faces(100, 8, llvmpipe, None, Some(1), "llvmpipe").unwrap(),
            64
        );
        assert_eq!(
            tile_faces(1000, 16, llvmpipe, None, None, "llvmpipe").unwrap(),
            1024
        );
        for tile in [8, 16, 32, 64] {
            let f = tile_faces(1 << 20, tile, llvmpipe, Some(CAP), None, "llvmpipe").unwrap();
            assert!(
                tiled_backward_iterations(1 << 20, tile, f, llvmpipe) <= CAP,
                "{tile}"
            );
        }
        // Past the cap even for one batch: an error, not a truncation.
        assert!(matches!(
            tile_faces(100, 128, llvmpipe, Some(CAP), None, "llvmpipe"),
            Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                ..
            })
        ));
        assert!(
            tile_faces(
                100,
                112,
                (8, 64, ColorWork::None),
                Some(CAP),
                None,
                "llvmpipe"
            )
            .is_ok()
        );
    }

    #[test]
    fn reduce_plans_stay_under_the_loop_cap() {
        let plan = |window, view_step, texel_window, texel_step| ReducePlan {
            window,
            view_step,
            texel_window,
            texel_step,
        };
        assert_eq!(reduce_plan(1000, 30, 5, 25, None), plan(1000, 5, 1000, 25));
        // Everything fits: one dispatch each.
        assert_eq!(
            reduce_plan(400_000, 1024, 1, 25, Some(CAP)),
            plan(400_000, 1, 400_000, 25)
        );
        for (chunk, per_item, views, texels) in [
            (400_000, 1024, 120, 25),
            (400_000, 65_536, 1, 1),
            (400_000, 100_000, 7, 49),
            (10, 65_536, 3, 4),
            (3_000_000, 16_384, 64, 25),
            (3_000_000, 4, 64, 65_536),
            (1_000, 2, 1, 40_000),
        ] {
            let p = reduce_plan(chunk, per_item, views, texels, Some(CAP));
            assert!(reduce_iterations(per_item.min(p.window)) <= CAP);
            assert!(
                texel_reduce_iterations(
                    p.view_step,
                    (p.view_step * per_item).min(p.texel_window),
                    p.texel_step
                ) <= CAP,
                "{chunk} {per_item} {views} {texels}: {p:?}"
            );
            assert!(p.window >= 1 && p.view_step >= 1 && p.texel_window >= 1);
            assert!(p.texel_step >= 1 && p.texel_step <= texels);
        }
    }
}
