//! Stage 2 of the backward: per unit of work, a partial gradient — tiled (`grad_tiled.comp`,
//! a unit per (face, tile) entry of the forward's binning) or brute force (`grad_brute.comp`, a
//! unit per (view, face, band of rows)) — written a chunk of units at a time, each chunk then
//! reduced (stage 3).

use bytemuck::{Pod, Zeroable};

use super::plan::tile_faces;
use super::reduce::UnitGroup;
use super::{GradBuffers, GradIo, GradKernels, groups};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::Recorder;
use crate::raster::binned::Binned;
use crate::raster::fine::{RasterPush, tiled_backward_workgroup};
use crate::raster::loops::brute_backward_iterations;
use crate::raster::scene::GpuScene;
use crate::raster::settings::ColorMode;
use crate::raster::specs;

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

impl GradKernels {
    /// The fine pass's push constants for the backward of `scene`, whose partials hold `stride`
    /// floats each.
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

    /// Brute force: (view, face, band) units, chunk by chunk.
    pub(super) fn record_brute(
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
    pub(super) fn record_tiled(
        &self,
        rec: &mut Recorder<'_>,
        binned: &Binned<'_>,
        gb: &GradBuffers,
        io: &GradIo<'_>,
        tile: u32,
    ) -> Result<()> {
        let scene = binned.scene();
        let grid = scene.grid(tile)?;
        // Its sums go quad by quad in a pixel order every power of two from 4 to 64 lanes
        // shares (`grad_tiled.comp`).
        let lanes = rec.context().info().subgroup_size;
        if !(lanes.is_power_of_two() && (4..=64).contains(&lanes)) {
            return Err(Error::Limit(format!(
                "the tiled backward needs subgroups of 4 to 64 lanes (a power of two); {} has \
                 {lanes}: use the brute-force method",
                rec.context().info().name
            )));
        }
        let limit = rec.context().info().shader_loop_limit();
        // The modes, then the tile size (constant 6 of `grad_tiled.comp`).
        let modes = gb
            .modes(scene)
            .constants(rec.context(), tiled_backward_workgroup(rec.context()));
        let mut constants = modes.to_vec();
        constants.push(tile);
        constants.push(u32::from(self.count_loops));
        let kernel = self.tiled.get(rec.context(), &constants)?;
        for (group, bins) in binned.groups().iter().zip(binned.bins) {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layout_matches_the_kernels() {
        for spec in [&specs::GRAD_TILED, &specs::GRAD_BRUTE] {
            assert_eq!(
                std::mem::size_of::<GradPush>() as u32,
                spec.push_constant_size,
                "{}",
                spec.name
            );
        }
        assert_eq!(std::mem::size_of::<GradPush>(), 116);
        assert_eq!(specs::GRAD_TILED.bindings.len(), 10);
        assert_eq!(specs::GRAD_BRUTE.bindings.len(), 7);
    }
}
