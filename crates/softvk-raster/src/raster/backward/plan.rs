//! How the backward splits its work to stay under a driver's loop cap
//! ([`crate::gpu::DeviceInfo::shader_loop_limit`]): rows per band of the brute-force partials,
//! faces per workgroup of the tiled ones, and the windows of the reductions, each the most the
//! kernels' loop counts (`raster::loops`) allow.

use crate::error::{Error, LimitKind, Result};
use crate::gpu::Context;
use crate::raster::loops::{
    ColorWork, brute_backward_iterations, reduce_iterations, texel_reduce_iterations,
    tiled_backward_iterations,
};

/// Rows per band of the brute-force backward over a `width × height` image: the whole image, or
/// fewer rows where `cap` or the driver's loop `limit` asks.
pub(super) fn band_rows(
    width: u32,
    height: u32,
    limit: Option<u64>,
    cap: Option<u32>,
    device: &str,
) -> Result<u32> {
    let mut rows = u64::from(height);
    if let Some(cap) = cap {
        rows = rows.min(u64::from(cap.max(1)));
    }
    if let Some(limit) = limit {
        let fit =
            limit.saturating_sub(brute_backward_iterations(0, width)) / (u64::from(width) + 1);
        if fit == 0 {
            return Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                what: format!("the brute-force backward of one row of {width} pixels"),
                need: brute_backward_iterations(1, width),
                max: limit,
                device: device.to_string(),
                hint: "use the tiled method",
            });
        }
        rows = rows.min(fit);
    }
    debug_assert!(limit.is_none_or(|l| brute_backward_iterations(rows, width) <= l));
    Ok(rows as u32)
}

/// Faces of one tile per workgroup of `grad_tiled.comp` (a multiple of its `workgroup`
/// invocations), for tiles of at most `run` entries: all of them, or fewer where `cap` or the
/// driver's loop `limit` asks.
pub(super) fn tile_faces(
    run: u64,
    tile: u32,
    work: (u32, u32, ColorWork),
    limit: Option<u64>,
    cap: Option<u32>,
    device: &str,
) -> Result<u64> {
    let wg = u64::from(work.1.max(1));
    let mut faces = run.max(1).div_ceil(wg) * wg;
    if let Some(cap) = cap {
        faces = faces.min(u64::from(cap.max(1)).div_ceil(wg) * wg);
    }
    if let Some(limit) = limit {
        let iterations = |faces| tiled_backward_iterations(run, tile, faces, work);
        let fixed = iterations(0);
        let per_batch = tiled_backward_iterations(run.max(wg), tile, wg, work)
            - tiled_backward_iterations(run.max(wg), tile, 0, work);
        let batches = limit.saturating_sub(fixed) / per_batch;
        if batches == 0 {
            return Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                what: format!(
                    "the tiled backward of one batch of {wg} faces over a {tile}x{tile} tile"
                ),
                need: iterations(wg),
                max: limit,
                device: device.to_string(),
                hint: "use smaller tiles",
            });
        }
        faces = faces.min(wg * batches);
        debug_assert!(iterations(faces) <= limit);
    }
    Ok(faces)
}

/// Texels per invocation of `grad_reduce_texels.comp` for a dispatch over `texels` texels: all
/// of them on a CPU device ([`Context::cpu_workgroups`]), whose driver pays a set-up per
/// subgroup of invocations (llvmpipe: per (face, texel), the reduction took twice as long on
/// spot-256; BENCHMARKS.md); one on a GPU, which wants the threads.
pub(super) fn texel_reduce_group(ctx: &Context, texels: u32) -> u32 {
    if ctx.cpu_workgroups() {
        texels.max(1)
    } else {
        1
    }
}

/// How one chunk's partials are added up: units per `grad_reduce.comp` dispatch (its window),
/// and views, units and texels per `grad_reduce_texels.comp` dispatch, for a chunk of `chunk`
/// units where an item holds at most `per_item` units, the group has `views` views and a face
/// `texels` texels. Under a loop cap of at least 8 iterations, every step is at least 1.
pub(super) fn reduce_plan(
    chunk: u64,
    per_item: u64,
    views: u64,
    texels: u64,
    limit: Option<u64>,
) -> ReducePlan {
    let texels = texels.max(1);
    let Some(limit) = limit else {
        return ReducePlan {
            window: chunk,
            view_step: views,
            texel_window: chunk,
            texel_step: texels,
        };
    };
    let budget = limit - 2;
    let window = if reduce_iterations(per_item) <= limit {
        chunk
    } else {
        budget
    };
    let fits = |views: u64, units: u64, texels: u64| {
        texel_reduce_iterations(views, units, texels) <= limit
    };
    let (view_step, texel_window, texel_step) =
        if fits(views, (views * per_item).min(chunk), texels) {
            (views, chunk, texels)
        } else {
            // Views per dispatch with every texel and whole items; else one view, fewer texels
            // and a window of units.
            let per_view = 2 + texels + (texels + 1) * per_item;
            let step = (budget / per_view).min(views);
            if step >= 1 {
                (step, chunk, texels)
            } else {
                let texel_step = texels.min((budget - 3) / 2);
                let units = (budget - 2 - texel_step) / (texel_step + 1);
                (1, units, texel_step)
            }
        };
    debug_assert!(reduce_iterations(per_item.min(window)) <= limit);
    debug_assert!(fits(
        view_step,
        (view_step * per_item).min(texel_window),
        texel_step
    ));
    ReducePlan {
        window: window.max(1),
        view_step: view_step.max(1),
        texel_window: texel_window.max(1),
        texel_step: texel_step.max(1),
    }
}

/// [`reduce_plan`]'s answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct ReducePlan {
    /// Units per `grad_reduce.comp` dispatch.
    pub(super) window: u64,
    /// Views per `grad_reduce_texels.comp` dispatch.
    pub(super) view_step: u64,
    /// Units per `grad_reduce_texels.comp` dispatch.
    pub(super) texel_window: u64,
    /// Texels per `grad_reduce_texels.comp` dispatch.
    pub(super) texel_step: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAP: u64 = 65_535;

    #[test]
    fn bands_are_the_most_rows_under_the_loop_cap() {
        // No cap: the whole image.
        assert_eq!(band_rows(256, 256, None, None, "llvmpipe").unwrap(), 256);
        assert_eq!(band_rows(256, 256, None, Some(7), "llvmpipe").unwrap(), 7);
        for (w, h) in [(256, 256), (1024, 1024), (64, 64), (65_532, 3)] {
            let rows = u64::from(band_rows(w, h, Some(CAP), None, "llvmpipe").unwrap());
            assert!(brute_backward_iterations(rows, w) <= CAP, "{w}x{h}");
            assert!(
                rows == u64::from(h) || brute_backward_iterations(rows + 1, w) > CAP,
                "{w}x{h}: {rows} rows is not the most"
            );
        }
        // 256 wide: 254 rows fit, so 256² takes two bands.
        assert_eq!(
            band_rows(256, 256, Some(CAP), None, "llvmpipe").unwrap(),
            254
        );
        assert!(matches!(
            band_rows(65_533, 1, Some(CAP), None, "llvmpipe"),
            Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                max: CAP,
                ..
            })
        ));
    }

    #[test]
    fn tile_parts_are_the_most_batches_under_the_loop_cap() {
        // blurry-256 at tile 32: all 5 856 faces in one tile. The cap is llvmpipe's alone, whose
        // subgroups have 4, 8 or 16 lanes (SSE, AVX2, AVX-512).
        let run = 5856;
        // Workgroups of 64 invocations, or of one subgroup (`tiled_backward_workgroup`).
        for sg in [4, 8, 16] {
            for wg in [64, sg] {
                for color in [ColorWork::None, ColorWork::Vertex, ColorWork::Texels] {
                    let work = (sg, wg, color);
                    let step = u64::from(wg);
                    let faces = tile_faces(run, 32, work, Some(CAP), None, "llvmpipe").unwrap();
                    assert_eq!(faces % step, 0);
                    assert!(tiled_backward_iterations(run, 32, faces, work) <= CAP);
                    assert!(tiled_backward_iterations(run, 32, faces + step, work) > CAP);
                    assert!(run.div_ceil(faces) > 1, "{sg} {wg} {color:?}");
                }
            }
        }
        // One subgroup a workgroup: a part takes 8 times fewer faces than 64 invocations do.
        let one = tile_faces(run, 32, (8, 8, ColorWork::Texels), Some(CAP), None, "").unwrap();
        let all = tile_faces(run, 32, (8, 64, ColorWork::Texels), Some(CAP), None, "").unwrap();
        assert!(one * 8 <= all + 64 && one * 8 + 64 >= all, "{one} {all}");
        // Small runs: one part; a cap rounds up to whole batches.
        let llvmpipe = (8, 64, ColorWork::Texels);
        assert_eq!(
            tile_faces(100, 8, llvmpipe, Some(CAP), None, "llvmpipe").unwrap(),
            128
        );
        assert_eq!(
            tile_faces(100, 8, llvmpipe, None, Some(1), "llvmpipe").unwrap(),
            64
        );
        assert_eq!(
            tile_faces(1000, 16, llvmpipe, None, None, "llvmpipe").unwrap(),
            1024
        );
        for tile in [8, 16, 32, 64] {
            let f = tile_faces(1 << 20, tile, llvmpipe, Some(CAP), None, "llvmpipe").unwrap();
            assert!(
                tiled_backward_iterations(1 << 20, tile, f, llvmpipe) <= CAP,
                "{tile}"
            );
        }
        // Past the cap even for one batch: an error, not a truncation.
        assert!(matches!(
            tile_faces(100, 128, llvmpipe, Some(CAP), None, "llvmpipe"),
            Err(Error::DeviceLimit {
                kind: LimitKind::LoopIterations,
                ..
            })
        ));
        assert!(
            tile_faces(
                100,
                112,
                (8, 64, ColorWork::None),
                Some(CAP),
                None,
                "llvmpipe"
            )
            .is_ok()
        );
    }

    #[test]
    fn reduce_plans_stay_under_the_loop_cap() {
        let plan = |window, view_step, texel_window, texel_step| ReducePlan {
            window,
            view_step,
            texel_window,
            texel_step,
        };
        assert_eq!(reduce_plan(1000, 30, 5, 25, None), plan(1000, 5, 1000, 25));
        // Everything fits: one dispatch each.
        assert_eq!(
            reduce_plan(400_000, 1024, 1, 25, Some(CAP)),
            plan(400_000, 1, 400_000, 25)
        );
        for (chunk, per_item, views, texels) in [
            (400_000, 1024, 120, 25),
            (400_000, 65_536, 1, 1),
            (400_000, 100_000, 7, 49),
            (10, 65_536, 3, 4),
            (3_000_000, 16_384, 64, 25),
            (3_000_000, 4, 64, 65_536),
            (1_000, 2, 1, 40_000),
        ] {
            let p = reduce_plan(chunk, per_item, views, texels, Some(CAP));
            assert!(reduce_iterations(per_item.min(p.window)) <= CAP);
            assert!(
                texel_reduce_iterations(
                    p.view_step,
                    (p.view_step * per_item).min(p.texel_window),
                    p.texel_step
                ) <= CAP,
                "{chunk} {per_item} {views} {texels}: {p:?}"
            );
            assert!(p.window >= 1 && p.view_step >= 1 && p.texel_window >= 1);
            assert!(p.texel_step >= 1 && p.texel_step <= texels);
        }
    }
}
