//! The forward's recorded stages: face setup, the brute-force fine pass, a view group's
//! binned fine pass and its count, and the 2 × 2 downsampling.

use super::Renderer;
use crate::error::Result;
use crate::gpu::Recorder;
use crate::primitives::binning::{Bins, TileGrid};
use crate::raster::brute::BruteBindings;
use crate::raster::fine::TiledBindings;
use crate::raster::scene::{GpuScene, ViewGroup};

impl Renderer {
    pub(super) fn record_setup(&self, rec: &mut Recorder<'_>, scene: &GpuScene) -> Result<()> {
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

    pub(super) fn record_brute(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        cull: bool,
    ) -> Result<()> {
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
    pub(super) fn record_group(
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
    pub(super) fn record_fine(
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

    pub(super) fn record_count(
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

    pub(super) fn record_downsample(&self, rec: &mut Recorder<'_>, scene: &GpuScene) -> Result<()> {
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
}
