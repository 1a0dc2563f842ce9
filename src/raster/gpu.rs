//! The GPU forward as a script of stages, for the CLI, tests and benchmarks:
//!
//! 1. light on the host (f64, as SoftRas lights before projection) and upload ([`Renderer::prepare`]);
//! 2. face setup, one invocation per (view, face);
//! 3. [`Method::Tiled`]: binning (count → scan → scatter → sort by tile → ranges,
//!    [`crate::primitives::binning`]) and the tiled fine pass; or [`Method::Brute`]: every face
//!    for every pixel;
//! 4. the 2×2 average with anti-aliasing, and read back.
//!
//! A scene is one mesh seen from many views, or a batch of meshes of equal topology, each seen
//! from its views ([`Renderer::prepare_batch`]); either renders in one submission per group.
//!
//! Binning sizes its entry list exactly: the count pass's total is read back before the rest is
//! recorded (two submissions per group of views). Views are binned in groups small enough that
//! the count cannot wrap and the entries fit one storage-buffer binding; a group whose entries do
//! not fit is split and re-counted, down to one view, and a view whose entries alone do not fit
//! is split into windows of tile rows ([`TileGrid::window`]), each binned, rendered and
//! differentiated alone (a face's gradient sums its windows' partials in tile order, the order
//! of one binning, so the result is bit for bit the same). [`Renderer`] makes the pipelines
//! once; a [`GpuScene`] keeps a scene's buffers so it can be rendered again (benchmarks record
//! it once and resubmit).
//!
//! Loops that must not wait for the count (fitting, a host engine's frames) bin *guarded*
//! instead: [`Renderer::reserve_guarded`] sizes every view as one group with a capacity of
//! entries, and [`Renderer::record_forward_guarded`] records the forward into any command
//! buffer with the sort over the whole capacity (sentinel keys) and everything after the count
//! gated on the GPU by an [`IterationGate`]: no read-back, no submission.
//!
//! Every forward returns a [`Binned`]: the scene and how its faces were binned, which its
//! backward ([`GradKernels::record`], [`Renderer::backward`]) takes. It borrows the scene, so
//! nothing re-bins it in between.

use crate::camera::Camera;
use crate::error::{Error, LimitKind, Result};
use crate::gpu::gate::IterationGate;
use crate::gpu::{Buffer, BufferRange, Context, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::primitives::binning::{self, BinJob, Binner, Bins, ItemLayout, TileGrid};
#[cfg(doc)]
use crate::raster::backward::GradIo;
use crate::raster::backward::{GradBuffers, GradKernels};
use crate::raster::brute::{BruteBindings, BruteRaster};
use crate::raster::fine::{CARRY_BYTES, PixelAux, TiledBindings, TiledRaster, check_tile_size};
use crate::raster::reference::{FaceColors, MeshF64};
use crate::raster::reference_grad::Gradients;
use crate::raster::settings::{ColorMode, RasterSettings};
use crate::raster::setup::{FACE_FINITE, FaceSetupKernel, GpuFaceSetup, GpuView, VertexLayout};

/// Tile edge (pixels) of [`Method::default`]. Chosen by `softvk bench` on lavapipe; see
/// BENCHMARKS.md.
pub const DEFAULT_TILE: u32 = 8;

/// How the fine pass finds the faces of a pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// SoftRas's own loop: every face for every pixel (the baseline).
    Brute,
    /// Faces binned to `tile × tile`-pixel tiles (a multiple of 8); each pixel visits its tile's.
    Tiled {
        /// Tile edge in pixels.
        tile: u32,
    },
}

impl Default for Method {
    fn default() -> Self {
        Method::Tiled { tile: DEFAULT_TILE }
    }
}

/// Where the face setup's box and flags sit, for binning.
const SETUP_LAYOUT: ItemLayout = ItemLayout {
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

/// The forward's pipelines, made once per context.
pub struct Renderer {
    setup: FaceSetupKernel,
    brute: BruteRaster,
    tiled: TiledRaster,
    binner: Binner,
    grad: GradKernels,
    entry_budget: Option<u64>,
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
    pub(crate) setups: Buffer,
    pub(crate) image: Buffer,
    pub(crate) aux: Buffer,
    /// Every rendered pixel's running state between the passes of a face list too long for
    /// one (`CARRY` in `raster_fine.glsl`): sized where the scene's face count could need
    /// passes on this device, a placeholder elsewhere.
    carry: Buffer,
    small: Option<Buffer>,
    /// Bins per view group: group `i` of the last tiled run used `bins[i]`. They are kept (the
    /// backward pass reuses them: no second binning) and grow, never shrink.
    pub(crate) bins: Vec<Bins>,
    /// The view groups of the last tiled render.
    pub(crate) groups: Vec<ViewGroup>,
    /// The tile size of the last tiled render.
    pub(crate) tile: Option<u32>,
    /// The bins were sized by [`Renderer::reserve_guarded`] (one group of every view, a
    /// capacity), not by an exact run: what a guarded forward needs.
    guarded: bool,
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
    scene: &'s GpuScene,
    method: Method,
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
    /// (face, tile) entries binned; for a guarded binning ([`Renderer::reserve_guarded`], whose
    /// count stays on the GPU), the entry capacity, an upper bound.
    pub entries: u64,
    /// The most entries one tile holds, or an upper bound of it (the entry count) where that
    /// already satisfies the driver's loop cap ([`crate::gpu::DeviceInfo::shader_loop_limit`]).
    pub max_tile_entries: u64,
}

/// Lanes of a subgroup that the 64-invocation tiled kernels use, and the 32-bit words of its
/// ballot.
fn subgroup_lanes(subgroup: u32) -> (u64, u64) {
    let lanes = u64::from(subgroup.clamp(1, 64));
    (lanes, u64::from(subgroup.max(1)).div_ceil(32))
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

/// Loop iterations one invocation of `raster_tiled.comp` runs for a tile of `run` faces with
/// subgroups of `subgroup` lanes and workgroups of `workgroup` invocations: per round (one of
/// the `64 / workgroup` pixels it shades) one iteration, per batch of one face per lane one
/// iteration and one per ballot word, and at most one per face of the run.
pub(crate) fn tiled_forward_iterations(run: u64, subgroup: u32, workgroup: u32) -> u64 {
    let (lanes, words) = subgroup_lanes(subgroup);
    let rounds = 64u64.div_ceil(u64::from(workgroup.clamp(1, 64)));
    rounds * (1 + run + run.div_ceil(lanes) * (1 + words)) + 2
}

/// What `grad_tiled.comp` does per kept face besides the screen sums, for its loop count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ColorWork {
    /// Alpha-only upstream: nothing.
    None,
    /// Vertex colours: three more sums.
    Vertex,
    /// Surface texels: one loop over the segment's coloured pixels.
    Texels,
}

/// Loop iterations one invocation of `grad_tiled.comp` runs for a tile of `run` entries when a
/// workgroup of `workgroup` invocations takes at most `faces` of them, with subgroups of
/// `subgroup` lanes: two binary searches over the run (for the chunk's sub-run), then per batch
/// (a subgroup's lanes' faces, every `workgroup` faces of the workgroup's) one iteration, the
/// final writes (3) and per segment of `lanes` pixels one iteration, one per ballot word, and
/// per kept face (at most `lanes`) one iteration, the three screen sums and the colour work.
pub(crate) fn tiled_backward_iterations(
    run: u64,
    tile: u32,
    faces: u64,
    (subgroup, workgroup, color): (u32, u32, ColorWork),
) -> u64 {
    let (lanes, words) = subgroup_lanes(subgroup);
    let segments = (u64::from(tile) * u64::from(tile)).div_ceil(lanes);
    let per_face = 1
        + 3
        + match color {
            ColorWork::None => 0,
            ColorWork::Vertex => 3,
            ColorWork::Texels => words + lanes,
        };
    let search = u64::from(u64::BITS - run.leading_zeros());
    // Per group of 32 segments one iteration, per segment one of the pre-pass that finds those
    // a face touches, and for each of those (at most all) the visits.
    let batch =
        1 + 3 + segments.div_ceil(32) + segments + segments * (1 + words + lanes * per_face);
    2 * search + faces.min(run).div_ceil(u64::from(workgroup.max(1))) * batch + 2
}

/// Loop iterations one invocation of `grad_brute.comp` runs for a band of `rows` rows of
/// `width` pixels.
pub(crate) fn brute_backward_iterations(rows: u64, width: u32) -> u64 {
    rows * (u64::from(width) + 1) + 2
}

/// Loop iterations one invocation of `grad_reduce.comp` runs to add at most `units` partials.
pub(crate) fn reduce_iterations(units: u64) -> u64 {
    units + 2
}

/// Loop iterations one invocation (one face) of `grad_reduce_texels.comp` runs over `views`
/// views and `texels` texels, adding at most `units` partials in all per texel (with masks,
/// a loop over the units for their union first).
pub(crate) fn texel_reduce_iterations(views: u64, units: u64, texels: u64) -> u64 {
    views * (2 + texels) + (texels + 1) * units + 2
}

/// The most entries any tile of a group holds, read back from its ranges.
fn max_tile_run(ctx: &Context, bins: &Bins, tiles: u64) -> Result<u64> {
    let ranges: Vec<[u32; 2]> = ctx.read_buffer(bins.ranges(), 0, tiles as usize)?;
    Ok(ranges
        .iter()
        .map(|r| u64::from(r[1] - r[0]))
        .max()
        .unwrap_or(0))
}

/// The most entries any tile of the group holds, or an upper bound of it: the entry count
/// where that alone shows one pass of the tiled forward stays under the driver's loop cap, else
/// the exact largest tile, read back (past the cap the forward folds that tile in passes, and
/// more passes than needed would cost time).
fn tile_run_bound(
    ctx: &Context,
    bins: &Bins,
    grid: &TileGrid,
    views: u32,
    total: u64,
    faces: u32,
) -> Result<u64> {
    // A tile belongs to one view, and a face enters a tile at most once.
    let total = total.min(u64::from(faces));
    let Some(limit) = ctx.info().shader_loop_limit() else {
        return Ok(total);
    };
    if tiled_forward_iterations(total, ctx.info().subgroup_size, 64) <= limit {
        return Ok(total);
    }
    max_tile_run(ctx, bins, grid.tiles_per_view() * u64::from(views))
}

/// The most views of a mesh of `faces` faces one scene holds within the device's storage
/// bindings: each view adds its faces' setups, its image and its pixels' aux (and running
/// state, where passes may be needed) to one binding each. At least 1 (a view that does not
/// fit is the scene's own error).
fn views_per_scene(ctx: &Context, faces: u64, settings: &RasterSettings) -> usize {
    let scale = if settings.antialias { 4 } else { 1 };
    let pixels = u64::from(settings.width) * u64::from(settings.height) * scale;
    let carry = if may_need_passes(ctx, faces.min(u64::from(u32::MAX)) as u32) {
        CARRY_BYTES
    } else {
        0
    };
    let per_view = [
        faces * std::mem::size_of::<GpuFaceSetup>() as u64,
        16 * pixels,
        std::mem::size_of::<PixelAux>() as u64 * pixels,
        carry * pixels,
    ];
    let max = u64::from(ctx.info().limits.max_storage_buffer_range);
    per_view
        .iter()
        .filter(|&&bytes| bytes > 0)
        .map(|bytes| max / bytes)
        .min()
        .unwrap_or(u64::MAX)
        .clamp(1, u64::from(u32::MAX)) as usize
}

/// Whether a forward over `faces` faces could need more than one pass on this device (brute
/// force's face list, or a tile holding every face): then the scene keeps a carry buffer.
fn may_need_passes(ctx: &Context, faces: u32) -> bool {
    let faces = u64::from(faces);
    ctx.info().shader_loop_limit().is_some_and(|limit| {
        faces + 2 > limit || tiled_forward_iterations(faces, ctx.info().subgroup_size, 64) > limit
    })
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
    /// before each forward. The scene's own position buffer is dropped. The vertex count (per
    /// mesh of the batch, meshes one after another) stays the scene's; the faces, colours and
    /// views too. The backward's host share (lighting, cameras) keeps reading the meshes given to
    /// [`Renderer::prepare`]: for lit scenes whose vertices move, use an unlit or silhouette
    /// render, relight on the host ([`GpuScene::relight`]), or record the lighting and its
    /// backward on the GPU ([`crate::raster::light::SceneLight`]).
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

    /// Replaces the batch's meshes by `meshes` of the same topology (faces, vertex count,
    /// texture resolution and colour source), for the next forward: their positions and
    /// colours, lit anew with the scene's lighting, are written into the scene's buffers, and
    /// the backward's host share reads them. What a loop that renders new vertices or textures
    /// every iteration through the same views calls instead of [`Renderer::prepare_batch`]:
    /// no buffer is made again, and the bins keep their size. An error, with nothing changed,
    /// when a mesh does not fit.
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
                "update_meshes writes the scene's own positions; this scene renders a host's                  (bind_positions)"
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
                    "mesh {i} does not share the scene's topology (faces, vertex count, texture                      resolution and colour source must be equal)"
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

    fn job(&self, grid: TileGrid, first_view: u32, views: u32) -> BinJob {
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
fn lit_batch(meshes: &[Mesh], lighting: &Lighting, mode: ColorMode) -> Vec<f32> {
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
fn upload_geometry(ctx: &Context, mesh: &Mesh) -> Result<(Buffer, Buffer)> {
    let positions: Vec<f32> = mesh.positions.iter().flatten().copied().collect();
    let faces: Vec<u32> = mesh.faces.iter().flatten().copied().collect();
    Ok((
        ctx.upload_buffer("mesh positions", &positions)?,
        ctx.upload_buffer("mesh faces", &faces)?,
    ))
}

impl Renderer {
    /// Builds every pipeline of the forward.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            setup: FaceSetupKernel::new(ctx)?,
            brute: BruteRaster::new(ctx)?,
            tiled: TiledRaster::new(ctx)?,
            binner: Binner::new(ctx)?,
            grad: GradKernels::new(ctx)?,
            entry_budget: None,
        })
    }

    /// Caps the (face, tile) entries one binning may hold (their buffers take about 28 bytes
    /// each); views are binned in smaller groups to stay under it. Without a budget the cap is
    /// what one storage-buffer binding holds (`maxStorageBufferRange / 8`).
    pub fn with_entry_budget(mut self, entries: u64) -> Self {
        self.entry_budget = Some(entries.max(1));
        self
    }

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
            groups: Vec::new(),
            tile: None,
            guarded: false,
            silhouette_only: false,
            meshes: meshes.iter().map(MeshF64::from_mesh).collect(),
            lighting: lighting.clone(),
            views_host: views.to_vec(),
        })
    }

    fn record_setup(&self, rec: &mut Recorder<'_>, scene: &GpuScene) -> Result<()> {
        rec.pass("face setup", |rec| {
            self.setup.record(
                rec,
                (scene.position_range()?, scene.position_layout),
                scene.faces.whole(),
                scene.views.whole(),
                scene.setups.whole(),
                scene.vertex_count,
                scene.face_count,
                scene.view_count,
                &scene.settings,
            )
        })
    }

    fn record_brute(&self, rec: &mut Recorder<'_>, scene: &GpuScene, cull: bool) -> Result<()> {
        rec.pass("raster brute", |rec| {
            self.brute.record(
                rec,
                &BruteBindings {
                    setups: scene.setups.whole(),
                    colors: scene.colors.whole(),
                    faces: scene.faces.whole(),
                    image: scene.image.whole(),
                    aux: scene.aux.whole(),
                    carry: scene.carry.whole(),
                },
                &scene.settings,
                scene.width,
                scene.height,
                scene.face_count,
                scene.view_count,
                scene.vertex_count,
                scene.texture_res,
                cull,
                scene.silhouette_only,
            )
        })
    }

    /// Scatter, sort and ranges for one view group whose count is known, then its fine pass.
    fn record_group(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        bins: &Bins,
        grid: TileGrid,
        first_view: u32,
        views: u32,
    ) -> Result<()> {
        let job = scene.job(grid, first_view, views);
        rec.pass("bin sort", |rec| {
            self.binner
                .record_sort(rec, bins, scene.setups.whole(), &job)
        })?;
        self.record_fine(rec, scene, bins, grid, first_view, views)
    }

    /// The tiled fine pass of one view group over its sorted bins.
    fn record_fine(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        bins: &Bins,
        grid: TileGrid,
        first_view: u32,
        views: u32,
    ) -> Result<()> {
        // The most entries a tile of these views holds: their group's (windows of one group
        // share it).
        let max_run = scene
            .groups
            .iter()
            .filter(|g| g.first < first_view + views && first_view < g.first + g.views)
            .map(|g| g.max_tile_entries)
            .max()
            .unwrap_or(u64::from(scene.face_count));
        rec.pass("raster tiled", |rec| {
            self.tiled.record(
                rec,
                &TiledBindings {
                    setups: scene.setups.whole(),
                    colors: scene.colors.whole(),
                    faces: scene.faces.whole(),
                    image: scene.image.whole(),
                    aux: scene.aux.whole(),
                    carry: scene.carry.whole(),
                    pairs: bins.entries().whole(),
                    pair_items: bins.entry_items().whole(),
                    ranges: bins.ranges().whole(),
                },
                &scene.settings,
                &grid,
                scene.face_count,
                first_view,
                views,
                scene.vertex_count,
                scene.texture_res,
                scene.silhouette_only,
                max_run,
            )
        })
    }

    fn record_count(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        bins: &Bins,
        grid: TileGrid,
        first_view: u32,
        views: u32,
    ) -> Result<()> {
        let job = scene.job(grid, first_view, views);
        rec.pass("bin count", |rec| {
            self.binner
                .record_count(rec, bins, scene.setups.whole(), &job)
        })
    }

    fn record_downsample(&self, rec: &mut Recorder<'_>, scene: &GpuScene) -> Result<()> {
        if let Some(small) = &scene.small {
            rec.pass("downsample 2x2", |rec| {
                self.brute.record_downsample(
                    rec,
                    scene.image.whole(),
                    small.whole(),
                    scene.settings.width,
                    scene.settings.height,
                    scene.view_count,
                )
            })?;
        }
        Ok(())
    }

    /// Runs the whole forward of `scene` (face setup, fine pass by `method`, downsampling),
    /// leaving images and aux on the GPU. Tiled: two submissions per view group (the count's
    /// total is read back in between to size the entries exactly). A convenience over the
    /// recorded stages, which waits; loops record [`Renderer::record_forward_guarded`].
    pub fn run<'s>(
        &self,
        ctx: &Context,
        scene: &'s mut GpuScene,
        method: Method,
    ) -> Result<Binned<'s>> {
        self.run_with_cull(ctx, scene, method, true)?;
        Ok(Binned { scene, method })
    }

    fn run_with_cull(
        &self,
        ctx: &Context,
        scene: &mut GpuScene,
        method: Method,
        cull: bool,
    ) -> Result<()> {
        let tile = match method {
            Method::Brute => {
                return ctx.submit_and_wait(|rec| {
                    self.record_setup(rec, scene)?;
                    self.record_brute(rec, scene, cull)?;
                    self.record_downsample(rec, scene)
                });
            }
            Method::Tiled { tile } => tile,
        };
        check_tile_size(tile)?;
        let grid = scene.grid(tile)?;
        // Every view at once, as far as the kernels' 32-bit item indices allow: the count is
        // exact (64-bit where it could wrap), and the groups halve only where the real entries
        // do not fit.
        let per_group = (u32::MAX / scene.face_count.max(1)).clamp(1, scene.view_count.max(1));
        let max_entries = binning::max_entries(ctx).min(self.entry_budget.unwrap_or(u64::MAX));
        // Groups of views still to render, first view and count; split on demand.
        let all_rows = (0, grid.tiles_y);
        let mut todo: Vec<(u32, u32, (u32, u32))> = (0..scene.view_count)
            .step_by(per_group as usize)
            .map(|v| (v, per_group.min(scene.view_count - v), all_rows))
            .rev()
            .collect();
        scene.groups.clear();
        scene.tile = Some(tile);
        scene.guarded = false;
        let mut setup_done = false;
        while let Some((first, views, tile_rows)) = todo.pop() {
            let grid = grid.window(tile_rows.0, tile_rows.1)?;
            let job = scene.job(grid, first, views);
            let index = scene.groups.len();
            if scene.bins.len() <= index {
                scene.bins.push(Bins::new(ctx)?);
            }
            let mut bins = std::mem::replace(&mut scene.bins[index], Bins::new(ctx)?);
            bins.reserve(ctx, &job)?;
            ctx.submit_and_wait(|rec| {
                if !setup_done {
                    self.record_setup(rec, scene)?;
                }
                self.record_count(rec, scene, &bins, grid, first, views)
            })?;
            setup_done = true;
            let total = bins.read_total(ctx)?;
            if total > max_entries {
                scene.bins[index] = bins;
                // Too many entries at once: bin two halves separately, of the views or, for one
                // view, of its tile rows (windows render the rows they cover, nothing else).
                let (row0, rows) = tile_rows;
                if views > 1 {
                    let half = views / 2;
                    todo.push((first + half, views - half, tile_rows));
                    todo.push((first, half, tile_rows));
                } else if rows > 1 {
                    let half = rows / 2;
                    todo.push((first, 1, (row0 + half, rows - half)));
                    todo.push((first, 1, (row0, half)));
                } else {
                    return Err(Error::Limit(format!(
                        "one row of {tile}-pixel tiles of one view needs {total} (face, tile) \
                         entries, over the {max_entries} one binning may hold; use a smaller σ \
                         or fewer faces"
                    )));
                }
                continue;
            }
            bins.reserve_entries(ctx, total)?;
            let last = todo.is_empty();
            let done = ctx.submit_and_wait(|rec| {
                self.record_group(rec, scene, &bins, grid, first, views)?;
                if last {
                    self.record_downsample(rec, scene)?;
                }
                Ok(())
            });
            let max_tile_entries = done
                .and_then(|()| tile_run_bound(ctx, &bins, &grid, views, total, scene.face_count));
            scene.bins[index] = bins;
            scene.groups.push(ViewGroup {
                first,
                views,
                tile_rows,
                entries: total,
                max_tile_entries: max_tile_entries?,
            });
        }
        Ok(())
    }

    /// The most (face, tile) entries one binning may hold here: what one storage-buffer binding
    /// holds, or the budget ([`Renderer::with_entry_budget`]) if smaller.
    pub fn max_entries(&self, ctx: &Context) -> u64 {
        binning::max_entries(ctx).min(self.entry_budget.unwrap_or(u64::MAX))
    }

    /// The (face, tile) entries of every view of `scene` binned as one group on `tile`-pixel
    /// tiles, counted on the GPU and read back (one submission): what a guarded loop sizes its
    /// capacity from ([`Renderer::reserve_guarded`]). Sizes the scene's bins as a guarded
    /// binning of capacity 1 (reserve again before recording).
    pub fn count_entries(&self, ctx: &Context, scene: &mut GpuScene, tile: u32) -> Result<u64> {
        self.reserve_guarded(ctx, scene, tile, 1)?;
        ctx.submit_and_wait(|rec| self.record_setup_and_count(rec, scene))?;
        scene.bins[0].read_total(ctx)
    }

    /// Face setup and the count of every view as one group, on the tiles of
    /// [`Renderer::reserve_guarded`] (the total lands in [`Bins::total_buffer`] of the first bins).
    fn record_setup_and_count(&self, rec: &mut Recorder<'_>, scene: &GpuScene) -> Result<()> {
        let (tile, bins) = match (scene.tile, scene.bins.first()) {
            (Some(tile), Some(bins)) if scene.guarded => (tile, bins),
            _ => {
                return Err(Error::Misuse(
                    "a guarded forward needs Renderer::reserve_guarded first".into(),
                ));
            }
        };
        let grid = scene.grid(tile)?;
        self.record_setup(rec, scene)?;
        self.record_count(rec, scene, bins, grid, 0, scene.view_count)
    }

    /// Records the tiled forward of a scene sized by [`Renderer::reserve_guarded`] into any
    /// command buffer, with no read-back: face setup, the count, `gate`'s check of the count
    /// against the capacity for `iteration`, then — gated: they run only when the entries fit —
    /// the sort (over the whole capacity, with sentinels), ranges, the fine pass, the
    /// downsampling, and whatever `then` records with the returned [`Binned`] (a loss, the
    /// backward, an optimizer step). When the entries do not fit, none of the gated work runs and
    /// the gate's status says so ([`IterationGate::read`]): reserve more and record again.
    pub fn record_forward_guarded<'s>(
        &self,
        rec: &mut Recorder<'_>,
        scene: &'s GpuScene,
        gate: &mut IterationGate,
        iteration: u32,
        then: impl FnOnce(&mut Recorder<'_>, Binned<'s>) -> Result<()>,
    ) -> Result<()> {
        self.record_setup_and_count(rec, scene)?;
        let capacity = scene.groups.first().map_or(0, |g| g.entries);
        gate.record_check(
            rec,
            scene.bins[0].total_buffer().whole(),
            iteration,
            capacity,
        )?;
        gate.record_gated(rec, |rec| {
            let tile = scene.tile.expect("checked by record_setup_and_count");
            let grid = scene.grid(tile)?;
            let job = scene.job(grid, 0, scene.view_count);
            let bins = &scene.bins[0];
            rec.pass("bin sort", |rec| {
                self.binner
                    .record_sort_guarded(rec, bins, scene.setups.whole(), &job)
            })?;
            self.record_fine(rec, scene, bins, grid, 0, scene.view_count)?;
            self.record_downsample(rec, scene)?;
            then(
                rec,
                Binned {
                    scene,
                    method: Method::Tiled { tile },
                },
            )
        })
    }

    /// For loops that never wait for the count (fitting, a host's frames; see the guarded
    /// binning of [`crate::primitives::binning`]): sizes `scene`'s bins for every view as one
    /// group on `tile`-pixel tiles with exactly `capacity` entries; the tiled passes are planned
    /// for any count up to it (a tile holds each face at most once, so its run is at most
    /// `min(capacity, faces)`: past the driver's loop cap, the forward folds tiles in passes).
    /// The scene's group then records `capacity` as its entries (an upper bound: the count
    /// itself stays on the GPU). Record each forward
    /// with [`Renderer::record_forward_guarded`].
    pub fn reserve_guarded(
        &self,
        ctx: &Context,
        scene: &mut GpuScene,
        tile: u32,
        capacity: u64,
    ) -> Result<()> {
        check_tile_size(tile)?;
        let grid = scene.grid(tile)?;
        let job = scene.job(grid, 0, scene.view_count);
        let max = self.max_entries(ctx);
        if capacity > max {
            return Err(Error::DeviceLimit {
                kind: LimitKind::BinEntries,
                what: format!("a guarded binning of {} views", scene.view_count),
                need: capacity,
                max,
                device: ctx.info().name.clone(),
                hint: "use fewer views, larger tiles or a smaller σ",
            });
        }
        if job.max_entries() > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "{} views of {} faces over {} tiles each could count past 2^32 entries; use \
                 fewer views or larger tiles",
                scene.view_count,
                scene.face_count,
                grid.tiles_per_view()
            )));
        }
        if scene.bins.is_empty() {
            scene.bins.push(Bins::new(ctx)?);
        }
        scene.bins[0].reserve(ctx, &job)?;
        scene.bins[0].reserve_entry_capacity(ctx, capacity.max(1))?;
        // Past the loop cap, the forward folds a tile this crowded in passes.
        let max_run = capacity.min(u64::from(scene.face_count));
        scene.tile = Some(tile);
        scene.guarded = true;
        scene.groups = vec![ViewGroup {
            first: 0,
            views: scene.view_count,
            tile_rows: (0, grid.tiles_y),
            entries: capacity.max(1),
            max_tile_entries: max_run,
        }];
        Ok(())
    }

    /// Records the whole forward of `scene` into one command buffer, for resubmission
    /// (benchmarks): face setup, then per view group (or window) of the last run count,
    /// scatter, sort, ranges and fine pass, then downsampling. Tiled needs a previous
    /// [`Renderer::run`] with the same method (its entry counts size the buffers; resubmitting
    /// the same scene reproduces them); loops whose scene changes record
    /// [`Renderer::record_forward_guarded`] instead.
    pub fn record_forward<'s>(
        &self,
        rec: &mut Recorder<'_>,
        scene: &'s GpuScene,
        method: Method,
    ) -> Result<Binned<'s>> {
        self.record_setup(rec, scene)?;
        match method {
            Method::Brute => self.record_brute(rec, scene, true)?,
            Method::Tiled { tile } => {
                if scene.tile != Some(tile) || scene.groups.is_empty() {
                    return Err(Error::Misuse(
                        "record_forward needs a previous tiled run with the same tile size".into(),
                    ));
                }
                if scene.guarded {
                    return Err(Error::Misuse(
                        "record_forward replays an exact run's binning; a scene sized by \
                         reserve_guarded records record_forward_guarded"
                            .into(),
                    ));
                }
                for (group, bins) in scene.groups.iter().zip(&scene.bins) {
                    let (first_row, rows) = group.tile_rows;
                    let grid = scene.grid(tile)?.window(first_row, rows)?;
                    self.record_count(rec, scene, bins, grid, group.first, group.views)?;
                    self.record_group(rec, scene, bins, grid, group.first, group.views)?;
                }
            }
        }
        self.record_downsample(rec, scene)?;
        Ok(Binned { scene, method })
    }

    /// The backward's pipelines (for callers that record the backward themselves).
    pub fn grad_kernels(&self) -> &GradKernels {
        &self.grad
    }

    /// The backward of the forward that left `binned`: dL/d(world positions, raw colours, and
    /// with `cameras` the cameras) given `d_image` = dL/d(output RGBA), view-major. A
    /// convenience over [`GradKernels::record`]: uploads, one submission, read-back; the host
    /// adds lighting's and the cameras' share in f64.
    pub fn backward(
        &self,
        ctx: &Context,
        binned: &Binned<'_>,
        d_image: &[[f32; 4]],
        cameras: bool,
    ) -> Result<Gradients> {
        let scene = binned.scene();
        let gb = GradBuffers::new(ctx, scene, binned.method())?;
        gb.set_d_image(ctx, scene, d_image)?;
        ctx.submit_and_wait(|rec| self.grad.record(rec, binned, &gb, &gb.io()))?;
        self.grad.finish(ctx, scene, &gb, &gb.io(), cameras)
    }

    /// Reads back the images and aux of the last run.
    pub fn read_frames(&self, ctx: &Context, scene: &GpuScene) -> Result<Frames> {
        let s = &scene.settings;
        let outputs = (s.width * s.height * scene.view_count) as usize;
        let rendered = (scene.width * scene.height * scene.view_count) as usize;
        let out = scene.small.as_ref().unwrap_or(&scene.image);
        Ok(Frames {
            width: s.width,
            height: s.height,
            images: ctx.read_buffer(out, 0, outputs)?,
            rendered_width: scene.width,
            rendered_height: scene.height,
            aux: ctx.read_buffer(&scene.aux, 0, rendered)?,
        })
    }

    /// Renders `mesh` from every camera and reads back images and aux: in one batch, or in as
    /// many as the device's storage bindings ask for (a batch's face setups, images and aux
    /// are one binding each).
    pub fn render_views(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
        method: Method,
    ) -> Result<Frames> {
        self.render_in_scenes(ctx, mesh, cameras, lighting, settings, method, false)
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
            self.run(ctx, &mut scene, method)?;
            let more = self.read_frames(ctx, &scene)?;
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
    /// rendered as a silhouette ([`GpuScene::set_silhouette_only`]: no depth or colour work,
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
        )?;
        Ok(frames.images.iter().map(|p| p[3]).collect())
    }

    /// Renders `mesh` from every camera with the brute-force kernel and reads back images and aux.
    pub fn render_brute_views(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
    ) -> Result<Frames> {
        self.render_views(ctx, mesh, cameras, lighting, settings, Method::Brute)
    }

    /// As [`Renderer::render_brute_views`], choosing whether the fine pass culls by the grown
    /// boxes (it must make no difference; tests check that it makes none, bit for bit).
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
        let mut scene = self.prepare(ctx, mesh, cameras, lighting, settings)?;
        self.run_with_cull(ctx, &mut scene, Method::Brute, cull)?;
        self.read_frames(ctx, &scene)
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
        let (positions, faces) = upload_geometry(ctx, mesh)?;
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
                (positions.whole(), VertexLayout::default()),
                faces.whole(),
                view_buf.whole(),
                setups.whole(),
                mesh.vertex_count() as u32,
                mesh.face_count() as u32,
                views.len() as u32,
                settings,
            )
        })?;
        ctx.read_buffer(&setups, 0, n)
    }

    /// Bins the faces of `cameras` on `tile`-pixel tiles (after the GPU face setup) and reads the
    /// result back, with the setups it binned (tests compare it with [`binning::cpu::bin`]).
    pub fn bin_faces(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        settings: &RasterSettings,
        tile: u32,
    ) -> Result<(Vec<GpuFaceSetup>, binning::cpu::Binned)> {
        let scene = self.prepare(ctx, mesh, cameras, &Lighting::unlit(), settings)?;
        let grid = scene.grid(tile)?;
        let job = scene.job(grid, 0, scene.view_count);
        ctx.submit_and_wait(|rec| self.record_setup(rec, &scene))?;
        let mut bins = Bins::new(ctx)?;
        let binned = self.binner.run(ctx, &mut bins, &scene.setups, &job)?;
        let setups = ctx.read_buffer(&scene.setups, 0, (job.item_count()) as usize)?;
        Ok((setups, binned))
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
