//! The GPU backward pass (SPEC §3, §4): from dL/d(image) to dL/d(world vertex positions), dL/d(raw
//! texels or vertex colours) and dL/d(camera), the exact derivative of the forward in f32.
//!
//! The stages mirror the f64 twin [`crate::raster::reference_grad`] step for step:
//!
//! 1. **Per (pixel, face)** (`kernels/raster/include/raster_grad.glsl`, the twin's `pixel_face_grad`):
//!    from the pixel's upstream gradient and the forward's [`PixelAux`](super::fine::PixelAux),
//!    one face's contribution, independently of the other faces.
//! 2. **Per unit of work** (`partials.rs`), a partial gradient (vec4 records: the 3 screen
//!    corners, then the colour slots, 3 vertex colours or R² texels, RGB each; [`grad_stride`]),
//!    either
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
//! 3. **Per face** (`reduce.rs`), after each chunk: `grad_reduce.comp` adds each item's partials
//!    to its screen (and vertex-colour) gradient, and `grad_reduce_texels.comp` adds the texel
//!    slots to the face's dL/d(lit texel) of the view's mesh. Both keep running sums in unit order,
//!    so the result is bit for bit the same however the units are chunked.
//! 4. **Per (view, face)** (`world.rs`: `grad_world.comp`, the twin's
//!    `face_screen_to_world_grad`): screen → camera → world, through perspective, orthographic or
//!    the matrix projection.
//! 5. **Per vertex** (`world.rs`: `grad_gather.comp`, the twin's `VertexFaces::gather`): summed
//!    over views and incident corners in a fixed order.
//! 6. **On the host, in f64** (`host.rs`), where the forward lights: the lighting's backward
//!    (raw colours, and normals → positions) with the twin's own functions, and the camera gradient
//!    (look-at).
//!
//! Each value has one writer and a fixed summation order: no float atomics, and repeated runs
//! are bit-identical. On a driver that caps shader loops
//! ([`crate::gpu::DeviceInfo::shader_loop_limit`]) every dispatch's loop count is bounded on the
//! host from the real iteration counts (`raster::loops`); work is split (bands, tile parts,
//! reduction windows and view ranges) rather than refused.
//!
//! The buffers a backward keeps between runs are [`GradBuffers`] (`buffers.rs`); how its work is
//! split to stay under a driver's loop cap, `plan.rs`.

mod buffers;
mod host;
mod partials;
mod plan;
mod reduce;
mod world;

pub use buffers::{GradBuffers, GradIo};

use std::sync::Arc;

use super::binned::Binned;
use super::method::Method;
use super::reference_grad;
use super::settings::ColorMode;
use crate::error::{Error, Result};
use crate::gpu::{Context, Kernel, KernelVariants, Recorder};
use crate::raster::specs;

/// The backward's pipelines, made once per context.
pub struct GradKernels {
    tiled: KernelVariants,
    /// The tiled kernel writes its loop and pair counts in place of partials (constant 7).
    count_loops: bool,
    brute: KernelVariants,
    reduce: Arc<Kernel>,
    reduce_texels: Arc<Kernel>,
    world: Arc<Kernel>,
    gather: Arc<Kernel>,
}

impl GradKernels {
    /// Builds the pipelines.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            tiled: KernelVariants::new(&specs::GRAD_TILED),
            count_loops: false,
            brute: KernelVariants::new(&specs::GRAD_BRUTE),
            reduce: ctx.kernel(&specs::GRAD_REDUCE, &[])?,
            reduce_texels: ctx.kernel(&specs::GRAD_REDUCE_TEXELS, &[])?,
            world: ctx.kernel(&specs::GRAD_WORLD, &[])?,
            gather: ctx.kernel(&specs::GRAD_GATHER, &[])?,
        })
    }

    /// Backward kernels whose tiled pass writes, in place of each (face, tile) entry's partial,
    /// `(the iterations its invocation had run by then of the loops whose trip counts depend
    /// on the input, the segments where the entry's face was kept, 0, 0)` at the partial's first
    /// vec4: what the host's loop bound (the driver's loop cap) and pair counts must bound and
    /// predict. The gradients they give are meaningless. For this crate's own tests
    /// (`raster::loops`) only.
    #[cfg(test)]
    pub(crate) fn counting_loops(mut self) -> Self {
        self.count_loops = true;
        self
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
        // Stages 2 and 3: the partials, chunk by chunk, each reduced into the running sums.
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
                Method::Tiled { tile } => self.record_tiled(rec, binned, gb, io, tile),
            }
        })?;
        // Stages 4 and 5.
        self.record_world(rec, scene, gb)?;
        self.record_gather(rec, scene, gb, io)
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

/// Workgroups of `size` invocations for `n` invocations, as the u32 a dispatch takes.
fn groups(n: u64, size: u64) -> Result<u32> {
    u32::try_from(n.div_ceil(size)).map_err(|_| {
        Error::Limit(format!(
            "the backward would dispatch {n} invocations at once"
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stride_counts_screen_and_colour_slots() {
        assert_eq!(grad_stride(ColorMode::Surface, 1), 16);
        assert_eq!(grad_stride(ColorMode::Surface, 3), 4 * (3 + 9));
        assert_eq!(grad_stride(ColorMode::Vertex, 5), 24);
        assert_eq!(face_grad_width(ColorMode::Surface), 9);
        assert_eq!(face_grad_width(ColorMode::Vertex), 18);
    }
}
