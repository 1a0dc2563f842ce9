//! The brute-force fine pass (`kernels/raster/raster/raster_brute.comp`): one invocation per pixel,
//! every face of its view in index order, exactly as [`super::reference::shade_pixel`] (and SoftRas) do.
//! It is the baseline the tiled kernels must equal bit for bit, and the one benchmarks compare
//! against. Anti-aliasing renders at 2× and averages with `kernels/raster/raster/downsample_2x2.comp`.
//!
//! Besides RGBA, every rendered pixel gets a [`crate::raster::fine::PixelAux`]: the forward's
//! running aggregates that the backward pass needs, so it needs no second forward.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::gpu::pass_size;
use crate::gpu::{BufferRange, Context, Kernel, KernelVariants, Recorder};
use crate::raster::fine::{CARRY_BYTES, FineModes, RasterPush, dispatch_passes};
use crate::raster::settings::RasterSettings;
use crate::raster::specs;

/// Push constants of `downsample_2x2.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DownsamplePush {
    width: u32,
    height: u32,
    view_count: u32,
    pad0: u32,
}

/// The buffers one brute-force render reads and writes, by the kernel's block names (generated
/// by `build.rs` from `raster_brute.comp`): setups (`view_count × face_count`
/// [`crate::raster::setup::GpuFaceSetup`]s), lit colours (RGB f32 and an unused fourth each,
/// mesh after mesh: `F R²` texels or one per vertex), faces (packed u32 triples), image (RGBA f32 per rendered
/// pixel, view-major, row 0 at the top) and aux (one [`crate::raster::fine::PixelAux`] per
/// rendered pixel).
pub use crate::raster::specs::RasterBruteBindings as BruteBindings;

/// The brute-force pipelines, made once per context.
pub struct BruteRaster {
    raster: KernelVariants,
    downsample: Arc<Kernel>,
}

impl BruteRaster {
    /// Builds the pipelines.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            raster: KernelVariants::new(&specs::RASTER_BRUTE),
            downsample: ctx.kernel(&specs::DOWNSAMPLE_2X2, &[])?,
        })
    }

    /// Records the fine pass over a `width × height` image per view (the *rendered* size: pass
    /// 2× the output size with anti-aliasing, then [`BruteRaster::record_downsample`]). On a
    /// driver that caps shader loops, more faces than one invocation may loop over are folded
    /// in passes (`b.carry` then holds 64 bytes per pixel).
    ///
    /// `silhouette_only` renders alpha alone ([`crate::raster::gpu::GpuScene::set_silhouette_only`]).
    /// `cull` skips faces whose grown box excludes the pixel, as SoftRas and the reference's
    /// `render` do; the box is conservative, so it changes no pixel (a test checks this bit for
    /// bit), and the tiled kernels skip exactly what binning skips.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        b: &BruteBindings<'_>,
        settings: &RasterSettings,
        width: u32,
        height: u32,
        face_count: u32,
        view_count: u32,
        vertex_count: u32,
        texture_res: u32,
        cull: bool,
        silhouette_only: bool,
    ) -> Result<()> {
        let pixels = u64::from(width) * u64::from(height) * u64::from(view_count);
        let need = |what: &str, range: &BufferRange<'_>, bytes: u64| {
            if range.size < bytes {
                Err(Error::Limit(format!(
                    "raster_brute: {what} buffer `{}` has {} bytes, needs {bytes}",
                    range.buffer.name(),
                    range.size
                )))
            } else {
                Ok(())
            }
        };
        need("image", &b.image, 16 * pixels)?;
        need("aux", &b.aux, 32 * pixels)?;
        need(
            "face setup",
            &b.setups,
            128 * u64::from(face_count) * u64::from(view_count),
        )?;
        if pixels > u64::from(u32::MAX) || face_count == 0 {
            return Err(Error::Limit(format!(
                "raster_brute: {pixels} pixels and {face_count} faces (need 1..2^32 pixels, > 0 faces)"
            )));
        }
        // More faces than one invocation may loop over are folded in passes.
        let per_pass = pass_size(
            u64::from(face_count),
            rec.context().info().shader_loop_limit(),
            |faces| faces + 2,
        );
        let passes = u64::from(face_count).div_ceil(per_pass);
        if passes > 1 {
            need("carry", &b.carry, CARRY_BYTES * pixels)?;
        }
        let push = RasterPush::new(
            settings,
            width,
            height,
            face_count,
            view_count,
            vertex_count,
            texture_res,
        );
        let mut constants = FineModes::new(settings, cull)
            .alpha_only_if(silhouette_only)
            .constants(rec.context(), 64)
            .to_vec();
        constants.push(u32::from(passes > 1));
        let kernel = self.raster.get(rec.context(), &constants)?;
        let groups = pixels.div_ceil(u64::from(specs::RASTER_BRUTE.workgroup_size[0]));
        dispatch_passes(
            rec,
            &kernel,
            &b.for_kernel(&kernel)?,
            push,
            (passes, per_pass),
            groups as u32,
        )
    }

    /// Records the 2×2 average of `big` (`2W × 2H` per view) into `small` (`W × H` per view).
    pub fn record_downsample(
        &self,
        rec: &mut Recorder<'_>,
        big: BufferRange<'_>,
        small: BufferRange<'_>,
        width: u32,
        height: u32,
        view_count: u32,
    ) -> Result<()> {
        let pixels = u64::from(width) * u64::from(height) * u64::from(view_count);
        if big.size < 64 * pixels || small.size < 16 * pixels {
            return Err(Error::Limit(format!(
                "downsample_2x2 of {pixels} pixels: buffers `{}` ({} bytes) and `{}` ({} bytes) \
                 are too small",
                big.buffer.name(),
                big.size,
                small.buffer.name(),
                small.size
            )));
        }
        let push = DownsamplePush {
            width,
            height,
            view_count,
            pad0: 0,
        };
        let groups = pixels.div_ceil(u64::from(specs::DOWNSAMPLE_2X2.workgroup_size[0]));
        let bindings = specs::Downsample2x2Bindings { big, small };
        rec.dispatch(
            &self.downsample,
            &bindings.for_kernel(&self.downsample)?,
            &push,
            groups as u32,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_structs_match_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<DownsamplePush>() as u32,
            specs::DOWNSAMPLE_2X2.push_constant_size
        );
        assert_eq!(specs::RASTER_BRUTE.bindings.len(), 6);
        assert_eq!(specs::DOWNSAMPLE_2X2.bindings.len(), 2);
    }
}
