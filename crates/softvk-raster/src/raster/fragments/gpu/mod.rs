//! PyTorch3D's mesh rasterizer on the GPU: [`FragmentRasterizer`].
//!
//! A rasterization is four steps, over buffers the caller owns (face vertices, meshes,
//! neighbours in; the fragments out) and scratch the rasterizer owns (the binning items and
//! bins, the backward's partials):
//!
//! 1. **Setup** (`kernels/raster/fragments/frag_setup.comp`): per (mesh, face slot) a binning item,
//!    the face's box grown by √`blur_radius`, or none where PyTorch3D skips the face.
//! 2. **Binning** ([`crate::primitives::binning`], 8-pixel tiles): exact, so nothing overflows
//!    and `bin_size` and `max_faces_per_bin` have nothing to say; its count is read back
//!    between two submissions ([`FragmentRasterizer::record_setup`] and
//!    [`FragmentRasterizer::bin`]).
//! 3. **Forward** (`frag_forward.comp`): per pixel, the faces binned to its tile in index
//!    order into its K-list of `(face, z)` (sorted by `(z, face)`), in passes over crowded
//!    tiles where the driver caps loops; then `frag_finish.comp` writes PyTorch3D's outputs from
//!    the lists ([`FragmentRasterizer::record_forward`]).
//! 4. **Backward** (`frag_backward.comp`, `frag_reduce.comp`): per binned (face, tile) entry a
//!    partial gradient over the tile's pixels, then per face the sum of its partials in slot
//!    order ([`FragmentRasterizer::record_backward`]); it needs only the binning's count pass.
//!
//! [`FragmentRasterizer::rasterize_to`] (into a host-visible buffer: what the Python package
//! calls, its arrays then view that memory), [`FragmentRasterizer::rasterize_into`],
//! [`FragmentRasterizer::rasterize`] and [`FragmentRasterizer::rasterize_grad_into`] do all of it
//! from host slices, through host-visible buffers.

mod host;
mod record;

pub use host::{GpuFragments, HostFragments, SlotParts};

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::FragmentSettings;
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, PassTime, Recorder, Timer};
use crate::primitives::binning::{BinJob, Binner, Bins, ItemLayout, TileGrid};
use crate::raster::specs;

/// Words of one binning item (`ITEM_WORDS` in `kernels/raster/include/fragments.glsl`): the box, the
/// flag word, padding.
const ITEM_WORDS: u32 = 8;

/// Push constants of every fragment kernel (`Push` in `kernels/raster/include/fragments.glsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct FragmentPush {
    width: u32,
    height: u32,
    k: u32,
    flags: u32,
    blur_radius: f32,
    grow: f32,
    views: u32,
    items_per_view: u32,
    tile_size: u32,
    tiles_x: u32,
    tiles_y: u32,
    pass_begin: u32,
    pass_end: u32,
    entries: u32,
    face_count: u32,
    pad: u32,
}

const FLAG_PERSPECTIVE: u32 = 1;
const FLAG_CLIP: u32 = 2;
const FLAG_CULL: u32 = 4;

/// What one rasterization is over, planned on the host: the batch's shape, the settings and the
/// binning job. Made by [`FragmentPlan::new`], which checks everything the kernels rely on.
#[derive(Clone, Debug)]
pub struct FragmentPlan {
    settings: FragmentSettings,
    /// Faces in the face-vertex buffer.
    face_count: u32,
    /// `(first, count)` per mesh.
    meshes: Vec<[u32; 2]>,
    job: BinJob,
    push: FragmentPush,
    /// Faces of a tile's run one forward pass visits at most.
    pass_faces: u64,
}

impl FragmentPlan {
    /// Plans a rasterization of `face_count` packed faces, of which mesh `n` owns
    /// `meshes[n] = (first, count)` (ranges in increasing order, not overlapping, as PyTorch3D
    /// packs them).
    pub fn new(
        ctx: &Context,
        face_count: usize,
        meshes: &[(usize, usize)],
        settings: &FragmentSettings,
    ) -> Result<Self> {
        let s = settings;
        let bad = |m: String| Err(Error::Input(format!("fragment rasterizer: {m}")));
        if s.width == 0 || s.height == 0 {
            return bad(format!("image size {}×{} is empty", s.height, s.width));
        }
        if s.faces_per_pixel == 0 {
            return bad("faces_per_pixel must be at least 1".into());
        }
        if !(s.blur_radius >= 0.0 && s.blur_radius.is_finite()) {
            return bad(format!(
                "blur_radius {} is not a finite number >= 0",
                s.blur_radius
            ));
        }
        if meshes.is_empty() {
            return bad("no meshes".into());
        }
        let face_count = u32::try_from(face_count)
            .ok()
            .filter(|&f| f < i32::MAX as u32)
            .ok_or_else(|| Error::Input(format!("{face_count} faces is too many")))?;
        super::check_meshes(face_count as usize, meshes)?;
        let items_per_view = meshes.iter().map(|m| m.1).max().unwrap_or(0).max(1) as u32;
        let views =
            u32::try_from(meshes.len()).map_err(|_| Error::Input("too many meshes".into()))?;
        let k = u32::try_from(s.faces_per_pixel)
            .map_err(|_| Error::Input("faces_per_pixel is too large".into()))?;
        let slots = u64::from(views) * u64::from(s.width) * u64::from(s.height) * u64::from(k);
        let limit = u64::from(ctx.info().limits.max_storage_buffer_range);
        if 12 * slots > limit || slots > u64::from(u32::MAX) / 3 {
            return Err(Error::DeviceLimit {
                kind: LimitKind::StorageBinding,
                what: format!(
                    "fragment rasterizer: the barycentrics of {views} × {}×{} pixels × K {k}",
                    s.height, s.width
                ),
                need: 12 * slots,
                max: limit,
                device: ctx.info().name.clone(),
                hint: "rasterize fewer meshes at once, a smaller image or a smaller K",
            });
        }
        let grid = TileGrid::new(s.width, s.height, 8)?;
        let loop_cap = ctx.info().shader_loop_limit();
        let k64 = u64::from(k);
        // The backward's loops (frag_backward.comp): its search, then per pixel of the tile one
        // and at most K + 1 list reads; the reduce's: one per tile of a face.
        let backward = 128 + 64 * (k64 + 1);
        let reduce = grid.tiles_per_view() + 8;
        // The forward's: K to find a list's end, then per face of a pass at most 2K + 1, and per
        // batch of a subgroup's faces one and one per ballot word (at most 2: a face's share of
        // them at most 3).
        let pass_faces = match loop_cap {
            Some(cap) => {
                for (what, need) in [
                    ("the backward's per-tile sum", backward),
                    ("the backward's per-face sum over its tiles", reduce),
                    ("a forward pass of one face", 16 + 3 * k64 + 4),
                ] {
                    if need > cap {
                        return Err(Error::DeviceLimit {
                            kind: LimitKind::LoopIterations,
                            what: format!("fragment rasterizer: {what}"),
                            need,
                            max: cap,
                            device: ctx.info().name.clone(),
                            hint: "use a smaller faces_per_pixel or image",
                        });
                    }
                }
                (cap - 16 - k64) / (2 * k64 + 4)
            }
            None => u64::from(u32::MAX),
        };
        let job = BinJob {
            grid,
            layout: ItemLayout {
                stride_words: ITEM_WORDS,
                box_offset: 0,
                flag_offset: 4,
                flag_mask: 1,
            },
            items_per_view,
            views,
            first_item: 0,
        };
        let blur = s.blur_radius as f32;
        let flags = [
            (s.perspective_correct, FLAG_PERSPECTIVE),
            (s.clip_barycentric_coords, FLAG_CLIP),
            (s.cull_backfaces, FLAG_CULL),
        ]
        .iter()
        .filter(|(on, _)| *on)
        .fold(0, |f, (_, bit)| f | bit);
        let push = FragmentPush {
            width: s.width,
            height: s.height,
            k,
            flags,
            blur_radius: blur,
            // PyTorch3D's std::sqrt of the f32 radius, correctly rounded here once.
            grow: blur.sqrt(),
            views,
            items_per_view,
            tile_size: grid.tile_size,
            tiles_x: grid.tiles_x,
            tiles_y: grid.tiles_y,
            pass_begin: 0,
            pass_end: 0,
            entries: 0,
            face_count,
            pad: 0,
        };
        Ok(Self {
            settings: *s,
            face_count,
            meshes: meshes.iter().map(|&(f, c)| [f as u32, c as u32]).collect(),
            job,
            push,
            pass_faces: pass_faces.max(1),
        })
    }

    /// Fragment slots of the output: meshes × H × W × K.
    pub fn slots(&self) -> u64 {
        u64::from(self.push.views)
            * u64::from(self.push.width)
            * u64::from(self.push.height)
            * u64::from(self.push.k)
    }

    /// Faces in the face-vertex buffer.
    pub fn face_count(&self) -> u32 {
        self.face_count
    }

    /// The settings planned for.
    pub fn settings(&self) -> &FragmentSettings {
        &self.settings
    }

    /// `(first, count)` per mesh, as the kernels read them (one `[u32; 2]` each): what the
    /// caller's meshes buffer must hold.
    pub fn mesh_table(&self) -> &[[u32; 2]] {
        &self.meshes
    }

    /// The binning items' bytes.
    fn items_bytes(&self) -> u64 {
        self.job.item_count() * u64::from(ITEM_WORDS) * 4
    }
}

/// The forward's outputs, in the caller's buffers, `[meshes, H, W, K]` (slot-major): PyTorch3D's
/// `pix_to_face` as i64, `zbuf`, `dists` and `bary_coords` (three f32 a slot).
pub struct FragmentOutputs<'a> {
    /// i64 per slot: the packed face, or −1.
    pub pix_to_face: BufferRange<'a>,
    /// f32 per slot.
    pub zbuf: BufferRange<'a>,
    /// f32 per slot.
    pub dists: BufferRange<'a>,
    /// Three f32 per slot.
    pub bary_coords: BufferRange<'a>,
}

/// The inputs every step reads, in the caller's buffers.
#[derive(Clone, Copy)]
pub struct FragmentInputs<'a> {
    /// Nine f32 per face: its three vertices' `(x, y, z)` in PyTorch3D's NDC.
    pub face_verts: BufferRange<'a>,
    /// [`FragmentPlan::mesh_table`].
    pub meshes: BufferRange<'a>,
}

/// The backward's upstream gradients and the forward's `pix_to_face`, in the caller's buffers.
pub struct FragmentGrads<'a> {
    /// i64 per slot, as the forward wrote it.
    pub pix_to_face: BufferRange<'a>,
    /// f32 per slot.
    pub grad_zbuf: BufferRange<'a>,
    /// Three f32 per slot.
    pub grad_bary: BufferRange<'a>,
    /// f32 per slot.
    pub grad_dists: BufferRange<'a>,
}

/// Host-visible buffers the slice entry points reuse (grown, never shrunk).
#[derive(Default)]
struct HostBuffers {
    inputs: Option<Buffer>,
    outputs: Option<Buffer>,
}

/// PyTorch3D's rasterizer on the GPU: its pipelines, its binning and its scratch.
pub struct FragmentRasterizer {
    setup: Arc<Kernel>,
    forward: Arc<Kernel>,
    finish: Arc<Kernel>,
    backward: Arc<Kernel>,
    reduce: Arc<Kernel>,
    binner: Binner,
    bins: Bins,
    items: Option<Buffer>,
    partials: Option<Buffer>,
    /// Read back by [`FragmentRasterizer::bin`]: the entries of the last binning.
    entries: Option<u64>,
    host: HostBuffers,
    /// GPU timestamps of the slice entry points' passes ([`FragmentRasterizer::time_passes`]).
    timer: Option<Timer>,
    timings: Vec<PassTime>,
}

impl FragmentRasterizer {
    /// Builds the pipelines (from the context's cache) and empty scratch.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            setup: ctx.kernel(&specs::FRAG_SETUP, &[])?,
            forward: ctx.kernel(&specs::FRAG_FORWARD, &[])?,
            finish: ctx.kernel(&specs::FRAG_FINISH, &[])?,
            backward: ctx.kernel(&specs::FRAG_BACKWARD, &[])?,
            reduce: ctx.kernel(&specs::FRAG_REDUCE, &[])?,
            binner: Binner::new(ctx)?,
            bins: Bins::new(ctx)?,
            items: None,
            partials: None,
            entries: None,
            host: HostBuffers::default(),
            timer: None,
            timings: Vec::new(),
        })
    }

    /// Times every pass of the slice entry points ([`FragmentRasterizer::rasterize_into`],
    /// [`FragmentRasterizer::rasterize_grad_into`]) with GPU timestamps, from now on: what
    /// benchmarks read with [`FragmentRasterizer::take_timings`].
    pub fn time_passes(&mut self, ctx: &Context) -> Result<()> {
        self.timer = Some(Timer::new(ctx, 16)?);
        Ok(())
    }

    /// The pass times recorded since the last call, in order.
    pub fn take_timings(&mut self) -> Vec<PassTime> {
        std::mem::take(&mut self.timings)
    }

    /// Submits what `f` records and waits, timed when [`FragmentRasterizer::time_passes`] asked.
    fn submit(
        &mut self,
        ctx: &Context,
        f: impl FnOnce(&mut Self, &mut Recorder<'_>) -> Result<()>,
    ) -> Result<()> {
        let mut timer = self.timer.take();
        let result = ctx.submit_and_wait_timed(timer.as_mut(), |rec| f(self, rec));
        let times = match (&result, &timer) {
            (Ok(()), Some(t)) => t.results(ctx),
            _ => Ok(Vec::new()),
        };
        self.timer = timer;
        result?;
        self.timings.extend(times?);
        Ok(())
    }
}
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layout_matches_the_kernels() {
        for spec in [
            &specs::FRAG_SETUP,
            &specs::FRAG_FORWARD,
            &specs::FRAG_FINISH,
            &specs::FRAG_BACKWARD,
            &specs::FRAG_REDUCE,
        ] {
            assert_eq!(
                std::mem::size_of::<FragmentPush>() as u32,
                spec.push_constant_size,
                "{}",
                spec.name
            );
        }
    }
}
