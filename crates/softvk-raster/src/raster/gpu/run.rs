//! The forward's drivers over the stages: [`Renderer::run`] (exact binning, two submissions per
//! view group), the entry counts, and the recorded forwards, guarded
//! ([`Renderer::reserve_guarded`], [`Renderer::record_forward_guarded`]) or replaying an
//! [`ExactRun`] ([`Renderer::record_forward`]).

use super::{Renderer, tile_run_bound};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::gate::IterationGate;
use crate::gpu::{Context, Recorder};
use crate::primitives::binning::{self, Bins};
use crate::raster::binned::{Binned, ExactRun, GuardedBins};
use crate::raster::method::Method;
use crate::raster::scene::{GpuScene, ViewGroup};

impl Renderer {
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

    pub(super) fn run_with_cull(
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
}
