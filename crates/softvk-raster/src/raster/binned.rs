//! What a forward leaves for its backward, as types: [`ExactRun`], a forward that ran with its
//! binning sized exactly (or brute force), which replays and is differentiated; [`GuardedBins`],
//! the bins of a guarded forward, sized once for a capacity of entries, which a loop records
//! into its own command buffers; and [`Binned`], the scene and the binning of any forward, which
//! the backward takes. A call out of order (replaying a forward that never ran, a guarded
//! forward with no bins, a backward with no forward) does not compile:
//!
//! ```compile_fail,E0061
//! # fn f(r: &softvk_raster::raster::gpu::Renderer, rec: &mut softvk_gpu::gpu::Recorder<'_>,
//! #      scene: &softvk_raster::raster::gpu::GpuScene) {
//! // Replaying takes the run it replays, not a scene.
//! r.record_forward(rec, scene, softvk_raster::raster::gpu::Method::default());
//! # }
//! ```
//!
//! ```compile_fail,E0061
//! # fn f(r: &softvk_raster::raster::gpu::Renderer, rec: &mut softvk_gpu::gpu::Recorder<'_>,
//! #      scene: &softvk_raster::raster::gpu::GpuScene, gate: &mut softvk_gpu::gpu::gate::IterationGate) {
//! // A guarded forward records into the bins `Renderer::reserve_guarded` returned.
//! r.record_forward_guarded(rec, scene, gate, 0, |_, _| Ok(()));
//! # }
//! ```
//!
//! In order, each compiles:
//!
//! ```no_run
//! # use softvk_gpu::gpu::{Context, gate::IterationGate};
//! # use softvk_raster::raster::gpu::{GpuScene, Method, Renderer};
//! # fn f(ctx: &Context, r: &Renderer, scene: &mut GpuScene, gate: &mut IterationGate)
//! #     -> softvk_gpu::Result<()> {
//! // Exact: run once, then replay into any command buffer, and differentiate.
//! let run = r.run(ctx, scene, Method::Tiled { tile: 8 })?;
//! ctx.submit_and_wait(|rec| r.record_forward(rec, &run).map(|_| ()))?;
//! let grads = r.backward(ctx, &run.binned(), &vec![[0.0; 4]; 64 * 64], false)?;
//! // Guarded: reserve bins for the scene, then record forward after forward over them.
//! let bins = r.reserve_guarded(ctx, scene, 8, 4096)?;
//! ctx.submit_and_wait(|rec| r.record_forward_guarded(rec, scene, &bins, gate, 1, |_, _| Ok(())))?;
//! # let _ = grads;
//! # Ok(())
//! # }
//! ```
//!
//! [`PairCounts`] count the (pixel, face) pairs a forward's fine passes visit: what per pair
//! costs mean independently of the device's speed.

use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::primitives::binning::{Bins, cpu};
use crate::raster::method::Method;
use crate::raster::scene::{GpuScene, ViewGroup};
use crate::raster::setup::{FACE_FINITE, GpuFaceSetup};

/// The scene a forward rendered and how its faces met its pixels: with tiles, the bins and view
/// groups of its binning. Every forward gives one ([`ExactRun::binned`], the closure of
/// [`Renderer::record_forward_guarded`]); the backward takes it. It borrows the scene (and the
/// bins), so nothing re-bins, re-sizes or changes the scene while it lives.
///
/// [`Renderer::record_forward_guarded`]: crate::raster::gpu::Renderer::record_forward_guarded
#[derive(Clone, Copy)]
pub struct Binned<'s> {
    pub(crate) scene: &'s GpuScene,
    pub(crate) method: Method,
    /// The view groups (or windows of tile rows) of a tiled forward, each with its bins; empty
    /// for brute force.
    pub(crate) groups: &'s [ViewGroup],
    pub(crate) bins: &'s [Bins],
}

impl std::fmt::Debug for Binned<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Binned")
            .field("method", &self.method)
            .field("groups", &self.groups)
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

    /// The view groups binned together (or windows of one view's tile rows), in order; none for
    /// brute force. A guarded forward's one group holds its capacity as its entries.
    pub fn groups(&self) -> &'s [ViewGroup] {
        self.groups
    }

    /// The (face, tile) entries binned, over all groups (a guarded forward: its capacity).
    pub fn entries(&self) -> u64 {
        self.groups.iter().map(|g| g.entries).sum()
    }

    /// Reads back the binning of each view group (or window) of an exact run, as the CPU twin
    /// lays it out ([`crate::primitives::binning::cpu::bin`]); none for brute force. (A guarded
    /// forward's count stays on the GPU: an error.)
    pub fn read_bins(&self, ctx: &Context) -> Result<Vec<cpu::Binned>> {
        let Method::Tiled { tile } = self.method else {
            return Ok(Vec::new());
        };
        self.groups
            .iter()
            .zip(self.bins)
            .map(|(group, bins)| {
                let Some(total) = bins.total() else {
                    return Err(Error::Input(
                        "a guarded binning's entry count stays on the GPU; read the bins of an \
                         exact run"
                            .into(),
                    ));
                };
                let (first_row, rows) = group.tile_rows;
                let grid = self.scene.grid(tile)?.window(first_row, rows)?;
                bins.read(ctx, &self.scene.job(grid, group.first, group.views), total)
            })
            .collect()
    }

    /// How many (pixel, face) pairs this forward's fine passes bin, visit and accept
    /// ([`PairCounts`]), counted on the host from the setups and bins read back, by the
    /// kernels' own rules for this device's subgroup size (in any view groups and windows).
    pub fn pair_counts(&self, ctx: &Context) -> Result<PairCounts> {
        let scene = self.scene;
        let (w, h) = (scene.width, scene.height);
        let faces = scene.face_count as usize;
        let views = scene.view_count as usize;
        let setups: Vec<GpuFaceSetup> = ctx.read_buffer(&scene.setups, 0, faces * views)?;
        let centers = PixelCenters::new(w, h);
        // Pairs whose pixel lies in the face's box: the box test's (`outside_bbox`) passes.
        let accepted = setups
            .iter()
            .filter(|f| f.flags & FACE_FINITE != 0)
            .map(|f| centers.inside(f.bbox))
            .sum();
        let pixels = u64::from(w) * u64::from(h) * views as u64;
        let Method::Tiled { tile } = self.method else {
            let all = pixels * faces as u64;
            return Ok(PairCounts {
                binned: all,
                forward: all,
                backward: all,
                accepted,
            });
        };
        let lanes = ctx.info().subgroup_size.clamp(1, 64);
        let mut counts = PairCounts {
            accepted,
            ..PairCounts::default()
        };
        // Every group of views, or window of one view's tile rows, with its own bins.
        for (group, bins) in self.groups.iter().zip(self.bins) {
            let (first_row, rows) = group.tile_rows;
            let grid = scene.grid(tile)?.window(first_row, rows)?;
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
                // (`morton_pixel`'s order, those in the image) that the kernel visits, the
                // batch's faces whose box touches the segment. It visits a segment where some
                // face of the batch holds one of its pixel centres in its box (`reach`: a face
                // whose box only passes between the centres adds nothing there, so a segment
                // that only such faces touch is skipped).
                let tile_pixels: Vec<(u32, u32)> = (0..tile * tile)
                    .map(|i| {
                        let (x, y) = morton_pixel(i, tile);
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
                        if batch.iter().any(|f| centers.holds_one(f, &inside)) {
                            counts.backward += u64::from(lanes) * touching(batch, &inside);
                        }
                    }
                }
            }
        }
        Ok(counts)
    }
}

/// A forward that ran to the end with its binning sized exactly from the count read back, or by
/// brute force ([`Renderer::run`]): its backward takes [`ExactRun::binned`], and
/// [`Renderer::record_forward`] records it again into any command buffer (benchmarks resubmit
/// it). It borrows the scene; [`GpuScene::last_run`] gives it back later, while nothing has
/// changed the scene.
///
/// [`Renderer::run`]: crate::raster::gpu::Renderer::run
/// [`Renderer::record_forward`]: crate::raster::gpu::Renderer::record_forward
#[derive(Clone, Copy, Debug)]
pub struct ExactRun<'s> {
    pub(crate) binned: Binned<'s>,
}

impl<'s> ExactRun<'s> {
    /// The brute-force forward of `scene`, which bins nothing: what [`Renderer::record_forward`]
    /// records without a first run (a benchmark spares one slow render). Its backward needs that
    /// forward submitted first.
    ///
    /// [`Renderer::record_forward`]: crate::raster::gpu::Renderer::record_forward
    pub fn brute(scene: &'s GpuScene) -> Self {
        Self {
            binned: Binned {
                scene,
                method: Method::Brute,
                groups: &[],
                bins: &[],
            },
        }
    }

    /// What the backward takes.
    pub fn binned(&self) -> Binned<'s> {
        self.binned
    }
}

impl GpuScene {
    /// The scene's last exact run ([`Renderer::run`]), while nothing has changed the scene
    /// since (each setter and update forgets it): for a caller that keeps the scene between its
    /// forward and its backward without keeping the run's borrow. `None` after a change, or
    /// before the first run.
    ///
    /// [`Renderer::run`]: crate::raster::gpu::Renderer::run
    pub fn last_run(&self) -> Option<ExactRun<'_>> {
        let (method, groups) = self.last_run.as_ref()?;
        Some(ExactRun {
            binned: Binned {
                scene: self,
                method: *method,
                groups,
                bins: &self.bins[..groups.len()],
            },
        })
    }
}

/// The bins of a guarded forward ([`Renderer::reserve_guarded`]): every view of one scene as one
/// group on one tile size, with a fixed capacity of (face, tile) entries, so that a loop records
/// forward after forward with no read-back ([`Renderer::record_forward_guarded`]). Reserve anew
/// (a larger capacity) when a gate reports an overflow. Owned by the loop, beside its scene.
///
/// [`Renderer::reserve_guarded`]: crate::raster::gpu::Renderer::reserve_guarded
/// [`Renderer::record_forward_guarded`]: crate::raster::gpu::Renderer::record_forward_guarded
pub struct GuardedBins {
    pub(crate) tile: u32,
    /// The scene's rendered size, faces and views, which the bins were sized for.
    pub(crate) made_for: (u32, u32, u32, u32),
    /// One bins and one group (of every view; its entries are the capacity).
    pub(crate) bins: [Bins; 1],
    pub(crate) group: [ViewGroup; 1],
}

impl GuardedBins {
    /// The tile edge the bins are laid out for.
    pub fn tile(&self) -> u32 {
        self.tile
    }

    /// The (face, tile) entries the bins hold.
    pub fn capacity(&self) -> u64 {
        self.group[0].entries
    }

    /// The binning the last guarded forward of `scene` into these bins left, for work recorded
    /// apart from that forward (a benchmark's pair counts, a backward in another submission).
    /// An error when the bins were reserved for a scene of another size.
    pub fn binned<'a>(&'a self, scene: &'a GpuScene) -> Result<Binned<'a>> {
        self.check(scene)?;
        Ok(Binned {
            scene,
            method: Method::Tiled { tile: self.tile },
            groups: &self.group,
            bins: &self.bins,
        })
    }

    pub(crate) fn check(&self, scene: &GpuScene) -> Result<()> {
        let shape = GuardedBins::shape(scene);
        if shape != self.made_for {
            return Err(Error::Input(format!(
                "guarded bins reserved for a scene of {:?} (width, height, faces, views), used \
                 with one of {shape:?}",
                self.made_for
            )));
        }
        Ok(())
    }

    pub(crate) fn shape(scene: &GpuScene) -> (u32, u32, u32, u32) {
        (
            scene.width,
            scene.height,
            scene.face_count,
            scene.view_count,
        )
    }
}

/// The (pixel, face) pairs of one render's fine passes ([`Binned::pair_counts`]): what per
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

    /// Whether `face` is finite and holds the centre of one of `pixels` (col, row) in its box.
    fn holds_one(&self, face: &GpuFaceSetup, pixels: &[(u32, u32)]) -> bool {
        let b = face.bbox;
        face.flags & FACE_FINITE != 0
            && pixels.iter().any(|&(c, r)| {
                let (x, y) = (self.x[c as usize], self.y[r as usize]);
                x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3]
            })
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

/// `segment_shape` of `kernels/raster/include/subgroup_face.glsl`: the block (width, height) of pixels
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

/// `morton_pixel` of `kernels/raster/include/subgroup_face.glsl`: pixel `i` of a `size`-wide tile (a
/// multiple of 8) in the backward's order, 8 × 8 blocks row-major and Z order within a block.
fn morton_pixel(i: u32, size: u32) -> (u32, u32) {
    let (block, m) = (i >> 6, i & 63);
    let per_row = size / 8;
    let x = (m & 1) | ((m >> 1) & 2) | ((m >> 2) & 4);
    let y = ((m >> 1) & 1) | ((m >> 2) & 2) | ((m >> 3) & 4);
    ((block % per_row) * 8 + x, (block / per_row) * 8 + y)
}

/// Whether face box `f` can hold a pixel centre of box `p` (the kernels' ballot test).
fn boxes_touch(f: [f32; 4], p: [f32; 4]) -> bool {
    !(p[2] < f[0] || p[3] < f[1] || p[0] > f[2] || p[1] > f[3])
}

#[cfg(test)]
mod tests {
    use super::{morton_pixel, segment_pixel, segment_shape};

    /// The backward's order covers each pixel of a tile once, and any power-of-two run of 4 to
    /// 64 of its pixels is one `segment_shape` block whose quads (2 × 2) are the same pixels
    /// whatever the run: what makes its sums independent of the subgroup size.
    #[test]
    fn the_backward_order_covers_each_pixel_once_in_blocks_of_any_lanes() {
        for size in [8u32, 16, 24, 32] {
            let mut seen = vec![false; (size * size) as usize];
            for i in 0..size * size {
                let (x, y) = morton_pixel(i, size);
                assert!(x < size && y < size, "size {size}, i {i}");
                assert!(!std::mem::replace(&mut seen[(y * size + x) as usize], true));
            }
            for lanes in [4u32, 8, 16, 32, 64] {
                let (w, h) = segment_shape(lanes).unwrap();
                for first in (0..size * size).step_by(lanes as usize) {
                    let (x0, y0) = morton_pixel(first, size);
                    assert!(x0 % w == 0 && y0 % h == 0, "lanes {lanes}: {x0}, {y0}");
                    for i in first..first + lanes {
                        let (x, y) = morton_pixel(i, size);
                        assert!((x0..x0 + w).contains(&x) && (y0..y0 + h).contains(&y));
                        // Quad k of the run: the pixels 4k .. 4k + 3, a 2 × 2 block.
                        let (qx, qy) = morton_pixel(i & !3, size);
                        assert!(qx % 2 == 0 && qy % 2 == 0 && x / 2 == qx / 2 && y / 2 == qy / 2);
                    }
                }
            }
        }
    }

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
