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
//! instead: [`Renderer::reserve_guarded`] returns [`GuardedBins`], every view as one group with
//! a capacity of entries, and [`Renderer::record_forward_guarded`] records the forward into any
//! command buffer over them, with the sort over the whole capacity (sentinel keys) and
//! everything after the count gated on the GPU by an [`IterationGate`]: no read-back, no
//! submission.
//!
//! The two modes are types ([`crate::raster::binned`]): [`Renderer::run`] returns an
//! [`ExactRun`], which [`Renderer::record_forward`] replays; a guarded forward needs its
//! [`GuardedBins`]. Every forward gives a [`Binned`] (the scene and how its faces were binned),
//! which its backward ([`GradKernels::record`], [`Renderer::backward`]) takes. It borrows the
//! scene, so nothing re-bins it in between.

use crate::camera::Camera;
use crate::error::{Error, LimitKind, Result};
use crate::gpu::gate::IterationGate;
use crate::gpu::{Context, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::primitives::binning::{self, Binner, Bins, TileGrid};
#[cfg(doc)]
use crate::raster::backward::GradIo;
use crate::raster::backward::{GradBuffers, GradKernels};
pub use crate::raster::binned::{Binned, ExactRun, GuardedBins, PairCounts};
use crate::raster::brute::{BruteBindings, BruteRaster};
use crate::raster::fine::{CARRY_BYTES, PixelAux, TiledBindings, TiledRaster};
use crate::raster::loops::tiled_forward_iterations;
pub use crate::raster::method::{DEFAULT_TILE, Method};
use crate::raster::reference::MeshF64;
use crate::raster::reference_grad::Gradients;
use crate::raster::scene::lit_batch;
pub use crate::raster::scene::{Frames, GpuScene, ViewGroup};
use crate::raster::settings::{ColorMode, RasterSettings};
use crate::raster::setup::{FaceSetupKernel, GpuFaceSetup, GpuView, VertexLayout};

/// The forward's pipelines, made once per context.
pub struct Renderer {
    setup: FaceSetupKernel,
    brute: BruteRaster,
    tiled: TiledRaster,
    binner: Binner,
    grad: GradKernels,
    entry_budget: Option<u64>,
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
pub fn views_per_scene(ctx: &Context, faces: u64, settings: &RasterSettings) -> usize {
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

    fn record_setup(&self, rec: &mut Recorder<'_>, scene: &GpuScene) -> Result<()> {
        rec.pass("face setup", |rec| {
            self.setup.record(
                rec,
                (scene.position_range()?, scene.position_layout),
                scene.faces.whole(),
                scene.views.whole(),
                scene.screen.whole(),
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
        group: &ViewGroup,
    ) -> Result<()> {
        let job = scene.job(grid, group.first, group.views);
        rec.pass("bin sort", |rec| {
            self.binner
                .record_sort(rec, bins, scene.setups.whole(), &job)
        })?;
        self.record_fine(rec, scene, bins, grid, group)
    }

    /// The tiled fine pass of one view group (or window) over its sorted bins, planned for the
    /// most entries a tile of the group holds.
    fn record_fine(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        bins: &Bins,
        grid: TileGrid,
        group: &ViewGroup,
    ) -> Result<()> {
        let (first_view, views, max_run) = (group.first, group.views, group.max_tile_entries);
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
    /// leaving images and aux on the GPU, and returns it as an [`ExactRun`]: what its backward
    /// takes ([`ExactRun::binned`]) and what [`Renderer::record_forward`] replays. Tiled: two
    /// submissions per view group (the count's total is read back in between to size the
    /// entries exactly). A convenience over the recorded stages, which waits; loops record
    /// [`Renderer::record_forward_guarded`].
    pub fn run<'s>(
        &self,
        ctx: &Context,
        scene: &'s mut GpuScene,
        method: Method,
    ) -> Result<ExactRun<'s>> {
        self.run_with_cull(ctx, scene, method, true)?;
        Ok(scene.last_run().expect("a run leaves its binning"))
    }

    fn run_with_cull(
        &self,
        ctx: &Context,
        scene: &mut GpuScene,
        method: Method,
        cull: bool,
    ) -> Result<()> {
        scene.last_run = None;
        let tile = match method {
            Method::Brute => {
                ctx.submit_and_wait(|rec| {
                    self.record_setup(rec, scene)?;
                    self.record_brute(rec, scene, cull)?;
                    self.record_downsample(rec, scene)
                })?;
                scene.last_run = Some((method, Vec::new()));
                return Ok(());
            }
            Method::Tiled { tile } => tile,
        };
        Method::check_tile(tile)?;
        let grid = scene.grid(tile)?;
        // Every view at once, as far as the kernels' 32-bit item indices allow: the count is
        // exact (64-bit where it could wrap), and the groups halve only where the real entries
        // do not fit.
        let per_group = (u32::MAX / scene.face_count.max(1)).clamp(1, scene.view_count.max(1));
        let max_entries = self.max_entries(ctx);
        // Groups of views still to render, first view and count; split on demand.
        let all_rows = (0, grid.tiles_y);
        let mut todo: Vec<(u32, u32, (u32, u32))> = (0..scene.view_count)
            .step_by(per_group as usize)
            .map(|v| (v, per_group.min(scene.view_count - v), all_rows))
            .rev()
            .collect();
        let mut groups: Vec<ViewGroup> = Vec::new();
        let mut setup_done = false;
        while let Some((first, views, tile_rows)) = todo.pop() {
            let grid = grid.window(tile_rows.0, tile_rows.1)?;
            let job = scene.job(grid, first, views);
            let index = groups.len();
            if scene.bins.len() <= index {
                scene.bins.push(Bins::new(ctx)?);
            }
            let bins = &mut scene.bins[index];
            bins.reserve(ctx, &job)?;
            let bins = &scene.bins[index];
            ctx.submit_and_wait(|rec| {
                if !setup_done {
                    self.record_setup(rec, scene)?;
                }
                self.record_count(rec, scene, bins, grid, first, views)
            })?;
            setup_done = true;
            let total = scene.bins[index].read_total(ctx)?;
            if total > max_entries {
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
            scene.bins[index].reserve_entries(ctx, total)?;
            let mut group = ViewGroup {
                first,
                views,
                tile_rows,
                entries: total,
                // A tile holds each face at most once: a bound the fine pass may plan by before
                // the exact largest tile is known.
                max_tile_entries: total.min(u64::from(scene.face_count)),
            };
            let last = todo.is_empty();
            let bins = &scene.bins[index];
            ctx.submit_and_wait(|rec| {
                self.record_group(rec, scene, bins, grid, &group)?;
                if last {
                    self.record_downsample(rec, scene)?;
                }
                Ok(())
            })?;
            group.max_tile_entries =
                tile_run_bound(ctx, bins, &grid, views, total, scene.face_count)?;
            groups.push(group);
        }
        scene.last_run = Some((method, groups));
        Ok(())
    }

    /// The most (face, tile) entries one binning may hold here: what one storage-buffer binding
    /// holds, or the budget ([`Renderer::with_entry_budget`]) if smaller.
    pub fn max_entries(&self, ctx: &Context) -> u64 {
        binning::max_entries(ctx).min(self.entry_budget.unwrap_or(u64::MAX))
    }

    /// The (face, tile) entries of every view of `scene` binned as one group on `tile`-pixel
    /// tiles, counted on the GPU and read back (one submission, into bins of its own): what a
    /// guarded loop sizes its capacity from ([`Renderer::reserve_guarded`]).
    pub fn count_entries(&self, ctx: &Context, scene: &GpuScene, tile: u32) -> Result<u64> {
        let mut bins = self.reserve_guarded(ctx, scene, tile, 1)?;
        ctx.submit_and_wait(|rec| self.record_setup_and_count(rec, scene, &bins))?;
        bins.bins[0].read_total(ctx)
    }

    /// Face setup and the count of every view as one group into guarded bins (the total lands
    /// in their [`Bins::total_buffer`]).
    fn record_setup_and_count(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        bins: &GuardedBins,
    ) -> Result<()> {
        bins.check(scene)?;
        let grid = scene.grid(bins.tile)?;
        self.record_setup(rec, scene)?;
        self.record_count(rec, scene, &bins.bins[0], grid, 0, scene.view_count)
    }

    /// Records the tiled forward of `scene` into `bins` ([`Renderer::reserve_guarded`]) into any
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
        bins: &'s GuardedBins,
        gate: &mut IterationGate,
        iteration: u32,
        then: impl FnOnce(&mut Recorder<'_>, Binned<'s>) -> Result<()>,
    ) -> Result<()> {
        self.record_setup_and_count(rec, scene, bins)?;
        let binned = bins.binned(scene)?;
        let group = &bins.group[0];
        gate.record_check(
            rec,
            bins.bins[0].total_buffer().whole(),
            iteration,
            group.entries,
        )?;
        gate.record_gated(rec, |rec| {
            let grid = scene.grid(bins.tile)?;
            let job = scene.job(grid, 0, scene.view_count);
            rec.pass("bin sort", |rec| {
                self.binner
                    .record_sort_guarded(rec, &bins.bins[0], scene.setups.whole(), &job)
            })?;
            self.record_fine(rec, scene, &bins.bins[0], grid, group)?;
            self.record_downsample(rec, scene)?;
            then(rec, binned)
        })
    }

    /// For loops that never wait for the count (fitting, a host's frames; see the guarded
    /// binning of [`crate::primitives::binning`]): bins for every view of `scene` as one group
    /// on `tile`-pixel tiles with exactly `capacity` entries; the tiled passes are planned for
    /// any count up to it (a tile holds each face at most once, so its run is at most
    /// `min(capacity, faces)`: past the driver's loop cap, the forward folds tiles in passes).
    /// Their group records `capacity` as its entries (an upper bound: the count itself stays on
    /// the GPU). Record each forward with [`Renderer::record_forward_guarded`]; when a gate
    /// reports an overflow, reserve anew with more.
    pub fn reserve_guarded(
        &self,
        ctx: &Context,
        scene: &GpuScene,
        tile: u32,
        capacity: u64,
    ) -> Result<GuardedBins> {
        Method::check_tile(tile)?;
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
        let mut bins = Bins::new(ctx)?;
        bins.reserve(ctx, &job)?;
        bins.reserve_entry_capacity(ctx, capacity.max(1))?;
        Ok(GuardedBins {
            tile,
            made_for: GuardedBins::shape(scene),
            bins: [bins],
            group: [ViewGroup {
                first: 0,
                views: scene.view_count,
                tile_rows: (0, grid.tiles_y),
                entries: capacity.max(1),
                // Past the loop cap, the forward folds a tile this crowded in passes.
                max_tile_entries: capacity.min(u64::from(scene.face_count)),
            }],
        })
    }

    /// Records the forward of `run` again into one command buffer, for resubmission
    /// (benchmarks): face setup, then per view group (or window) of the run count, scatter,
    /// sort, ranges and fine pass, then downsampling, into the run's bins. Resubmitting the
    /// same scene reproduces the run's entry counts; loops whose scene changes record
    /// [`Renderer::record_forward_guarded`] instead.
    pub fn record_forward<'s>(
        &self,
        rec: &mut Recorder<'_>,
        run: &ExactRun<'s>,
    ) -> Result<Binned<'s>> {
        let binned = run.binned();
        let scene = binned.scene;
        self.record_setup(rec, scene)?;
        match binned.method {
            Method::Brute => self.record_brute(rec, scene, true)?,
            Method::Tiled { tile } => {
                for (group, bins) in binned.groups.iter().zip(binned.bins) {
                    let (first_row, rows) = group.tile_rows;
                    let grid = scene.grid(tile)?.window(first_row, rows)?;
                    self.record_count(rec, scene, bins, grid, group.first, group.views)?;
                    self.record_group(rec, scene, bins, grid, group)?;
                }
            }
        }
        self.record_downsample(rec, scene)?;
        Ok(binned)
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
        let gb = GradBuffers::new(ctx, binned)?;
        gb.set_d_image(ctx, scene, d_image)?;
        ctx.submit_and_wait(|rec| self.grad.record(rec, binned, &gb, &gb.io()))?;
        self.grad.finish(ctx, scene, &gb, &gb.io(), cameras)
    }

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
