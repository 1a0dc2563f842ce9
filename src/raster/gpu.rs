//! The GPU forward as a script of stages, for the CLI, tests and benchmarks:
//!
//! 1. light on the host (f64, as SoftRas lights before projection) and upload ([`Renderer::prepare`]);
//! 2. face setup, one invocation per (view, face);
//! 3. [`Method::Tiled`]: binning (count → scan → scatter → sort by tile → ranges,
//!    [`crate::primitives::binning`]) and the tiled fine pass; or [`Method::Brute`]: every face
//!    for every pixel;
//! 4. the 2×2 average with anti-aliasing, and read back.
//!
//! Binning sizes its entry list exactly: the count pass's total is read back before the rest is
//! recorded (two submissions per group of views). Views are binned in groups small enough that
//! the count cannot wrap and the entries fit one storage-buffer binding; a group whose entries do
//! not fit is split and re-counted. [`Renderer`] makes the pipelines once; a [`GpuScene`] keeps a
//! scene's buffers so it can be rendered again (benchmarks record it once and resubmit).

use crate::camera::Camera;
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, MemoryKind, Recorder};
use crate::lighting::Lighting;
use crate::mesh::Mesh;
use crate::primitives::binning::{self, BinJob, Binner, Bins, ItemLayout, TileGrid};
use crate::raster::brute::{BruteBindings, BruteRaster};
use crate::raster::fine::{PixelAux, TiledBindings, TiledRaster, check_tile_size};
use crate::raster::reference::{ColorMode, FaceColors, RasterSettings};
use crate::raster::setup::{FACE_FINITE, FaceSetupKernel, GpuFaceSetup, GpuView};

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
    entry_budget: Option<u64>,
}

/// A scene on the GPU: mesh, lit colours, views, and every buffer of its forward pass, kept so
/// the scene can be rendered again without re-uploading (the bins grow, never shrink).
pub struct GpuScene {
    settings: RasterSettings,
    face_count: u32,
    view_count: u32,
    texture_res: u32,
    /// Rendered size (2× the output with anti-aliasing).
    width: u32,
    height: u32,
    positions: Buffer,
    faces: Buffer,
    colors: Buffer,
    views: Buffer,
    setups: Buffer,
    image: Buffer,
    aux: Buffer,
    small: Option<Buffer>,
    bins: Bins,
    /// The view groups of the last tiled render, with their entry counts.
    groups: Vec<(u32, u32, u64)>,
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

    /// The (face, tile) entries of the last tiled render, over all view groups.
    pub fn binned_entries(&self) -> u64 {
        self.groups.iter().map(|g| g.2).sum()
    }

    /// The (pixel, face) pairs the last run's fine pass evaluated: every face for every pixel
    /// with [`Method::Brute`]; with [`Method::Tiled`], per tile its pixels (clipped to the image)
    /// times its binned faces, read back from the bins. Tiled needs the last run to have binned
    /// every view in one group.
    pub fn evaluated_pairs(&self, ctx: &Context, method: Method) -> Result<u64> {
        let pixels = u64::from(self.width) * u64::from(self.height) * u64::from(self.view_count);
        let Method::Tiled { tile } = method else {
            return Ok(pixels * u64::from(self.face_count));
        };
        if self.groups.len() != 1 {
            return Err(Error::Input(
                "evaluated_pairs needs a previous tiled run in one view group".into(),
            ));
        }
        let grid = self.grid(tile)?;
        let tiles = (grid.tiles_per_view() * u64::from(self.view_count)) as usize;
        let ranges: Vec<[u32; 2]> = ctx.read_buffer(self.bins.ranges(), 0, tiles)?;
        let per_view = grid.tiles_per_view() as usize;
        Ok(ranges
            .iter()
            .enumerate()
            .map(|(t, r)| {
                let t = (t % per_view) as u32;
                let (tx, ty) = (t % grid.tiles_x, t / grid.tiles_x);
                let w = (grid.width - tx * tile).min(tile);
                let h = (grid.height - ty * tile).min(tile);
                u64::from(r[1] - r[0]) * u64::from(w * h)
            })
            .sum())
    }

    /// The rendered (pre-downsampling) image size.
    pub fn rendered_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The tile grid of `tile`-pixel tiles over the rendered image.
    fn grid(&self, tile: u32) -> Result<TileGrid> {
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

/// Lights on the host in f64 and rounds to the packed f32 triples the kernels read.
fn lit_colors(mesh: &Mesh, lighting: &Lighting, mode: ColorMode) -> Vec<f32> {
    let colors = match FaceColors::new(mesh, lighting, mode) {
        FaceColors::Surface { texels, .. } => texels,
        FaceColors::Vertex { colors, .. } => colors,
    };
    colors.iter().flatten().map(|&c| c as f32).collect()
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
    /// uploads the scene.
    pub fn prepare(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
    ) -> Result<GpuScene> {
        let views = checked_views(mesh, cameras, settings)?;
        let face_count = u32::try_from(mesh.face_count())
            .map_err(|_| Error::Limit(format!("{} faces exceed 2^32", mesh.face_count())))?;
        let view_count = u32::try_from(views.len())
            .map_err(|_| Error::Limit(format!("{} views exceed 2^32", views.len())))?;
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
        if rendered > u64::from(u32::MAX) {
            return Err(Error::Limit(format!(
                "{rendered} rendered pixels exceed 2^32"
            )));
        }

        let (positions, faces) = upload_geometry(ctx, mesh)?;
        Ok(GpuScene {
            settings: *settings,
            face_count,
            view_count,
            texture_res: mesh.texture_res,
            width: w,
            height: h,
            positions,
            faces,
            colors: ctx.upload_buffer(
                "lit colours",
                &lit_colors(mesh, lighting, settings.color_mode),
            )?,
            views: ctx.upload_buffer("views", &views)?,
            setups: ctx.create_buffer(
                "face setups",
                pairs * std::mem::size_of::<GpuFaceSetup>() as u64,
                MemoryKind::Device,
            )?,
            image: ctx.create_buffer("image", 16 * rendered, MemoryKind::Device)?,
            aux: ctx.create_buffer("pixel aux", 16 * rendered, MemoryKind::Device)?,
            small: if settings.antialias {
                Some(ctx.create_buffer("image (anti-aliased)", 16 * outputs, MemoryKind::Device)?)
            } else {
                None
            },
            bins: Bins::new(ctx)?,
            groups: Vec::new(),
        })
    }

    fn record_setup(&self, rec: &mut Recorder<'_>, scene: &GpuScene) -> Result<()> {
        rec.pass("face setup", |rec| {
            self.setup.record(
                rec,
                scene.positions.whole(),
                scene.faces.whole(),
                scene.views.whole(),
                scene.setups.whole(),
                scene.face_count,
                scene.view_count,
                scene.settings.dist,
                scene.settings.sigma,
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
                },
                &scene.settings,
                scene.width,
                scene.height,
                scene.face_count,
                scene.view_count,
                scene.texture_res,
                cull,
            )
        })
    }

    /// Scatter, sort and ranges for one view group whose count is known, then its fine pass.
    fn record_group(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        grid: TileGrid,
        first_view: u32,
        views: u32,
    ) -> Result<()> {
        let job = scene.job(grid, first_view, views);
        rec.pass("bin sort", |rec| {
            self.binner
                .record_sort(rec, &scene.bins, scene.setups.whole(), &job)
        })?;
        rec.pass("raster tiled", |rec| {
            self.tiled.record(
                rec,
                &TiledBindings {
                    setups: scene.setups.whole(),
                    colors: scene.colors.whole(),
                    faces: scene.faces.whole(),
                    image: scene.image.whole(),
                    aux: scene.aux.whole(),
                    entries: scene.bins.entries().whole(),
                    entry_items: scene.bins.entry_items().whole(),
                    ranges: scene.bins.ranges().whole(),
                },
                &scene.settings,
                &grid,
                scene.face_count,
                first_view,
                views,
                scene.texture_res,
            )
        })
    }

    fn record_count(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        grid: TileGrid,
        first_view: u32,
        views: u32,
    ) -> Result<()> {
        let job = scene.job(grid, first_view, views);
        rec.pass("bin count", |rec| {
            self.binner
                .record_count(rec, &scene.bins, scene.setups.whole(), &job)
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
    /// total is read back in between to size the entries exactly).
    pub fn run(&self, ctx: &Context, scene: &mut GpuScene, method: Method) -> Result<()> {
        self.run_with_cull(ctx, scene, method, true)
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
        let per_group = binning::max_views_per_group(scene.face_count, &grid);
        let max_entries = binning::max_entries(ctx).min(self.entry_budget.unwrap_or(u64::MAX));
        // Groups of views still to render, first view and count; split on demand.
        let mut todo: Vec<(u32, u32)> = (0..scene.view_count)
            .step_by(per_group as usize)
            .map(|v| (v, per_group.min(scene.view_count - v)))
            .rev()
            .collect();
        scene.groups.clear();
        let mut setup_done = false;
        while let Some((first, views)) = todo.pop() {
            let job = scene.job(grid, first, views);
            scene.bins.reserve(ctx, &job)?;
            ctx.submit_and_wait(|rec| {
                if !setup_done {
                    self.record_setup(rec, scene)?;
                }
                self.record_count(rec, scene, grid, first, views)
            })?;
            setup_done = true;
            let total = scene.bins.read_total(ctx)?;
            if total > max_entries {
                if views == 1 {
                    return Err(Error::Limit(format!(
                        "one view needs {total} (face, tile) entries, over the {max_entries} \
                         one binning may hold; use larger tiles, a smaller σ or fewer faces"
                    )));
                }
                // Too many entries at once: bin the two halves separately.
                let half = views / 2;
                todo.push((first + half, views - half));
                todo.push((first, half));
                continue;
            }
            scene.bins.reserve_entries(ctx, total)?;
            let last = todo.is_empty();
            ctx.submit_and_wait(|rec| {
                self.record_group(rec, scene, grid, first, views)?;
                if last {
                    self.record_downsample(rec, scene)?;
                }
                Ok(())
            })?;
            scene.groups.push((first, views, total));
        }
        Ok(())
    }

    /// Records the whole tiled forward of `scene` into one command buffer, for resubmission
    /// (benchmarks): face setup, count, scatter, sort, ranges, fine pass, downsampling. Needs a
    /// previous [`Renderer::run`] with the same method that binned all views in one group (its
    /// entry count sizes the buffers; resubmitting the same scene reproduces it).
    pub fn record_forward(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        method: Method,
    ) -> Result<()> {
        self.record_setup(rec, scene)?;
        match method {
            Method::Brute => self.record_brute(rec, scene, true)?,
            Method::Tiled { tile } => {
                let grid = scene.grid(tile)?;
                if scene.groups.len() != 1 || scene.groups[0].1 != scene.view_count {
                    return Err(Error::Input(
                        "record_forward needs a previous tiled run that binned every view in \
                         one group"
                            .into(),
                    ));
                }
                self.record_count(rec, scene, grid, 0, scene.view_count)?;
                self.record_group(rec, scene, grid, 0, scene.view_count)?;
            }
        }
        self.record_downsample(rec, scene)
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

    /// Renders `mesh` from every camera in one batch and reads back images and aux.
    pub fn render_views(
        &self,
        ctx: &Context,
        mesh: &Mesh,
        cameras: &[Camera],
        lighting: &Lighting,
        settings: &RasterSettings,
        method: Method,
    ) -> Result<Frames> {
        let mut scene = self.prepare(ctx, mesh, cameras, lighting, settings)?;
        self.run(ctx, &mut scene, method)?;
        self.read_frames(ctx, &scene)
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
        let mut scene = self.prepare(ctx, mesh, cameras, &Lighting::unlit(), settings)?;
        let grid = scene.grid(tile)?;
        let job = scene.job(grid, 0, scene.view_count);
        if job.max_entries() > u64::from(u32::MAX) {
            return Err(Error::Limit("bin_faces: bin fewer views".into()));
        }
        ctx.submit_and_wait(|rec| self.record_setup(rec, &scene))?;
        let binned = self.binner.run(ctx, &mut scene.bins, &scene.setups, &job)?;
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
