//! Stage 3 of the backward: after each chunk of partials, per face, `grad_reduce.comp` adds
//! each item's partials to its screen (and vertex-colour) gradient and `grad_reduce_texels.comp`
//! the texel slots to the face's dL/d(lit texel), both in unit order, so the sums are the same
//! bits however the units are chunked.

use bytemuck::{Pod, Zeroable};

use super::plan::{ReducePlan, reduce_plan, texel_reduce_group};
use super::{GradBuffers, GradIo, GradKernels, groups};
use crate::error::Result;
use crate::gpu::{BufferRange, Recorder};
use crate::raster::scene::GpuScene;
use crate::raster::settings::ColorMode;
use crate::raster::specs;

/// Push constants of `grad_reduce.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ReducePush {
    item_count: u32,
    first_item: u32,
    stride: u32,
    width: u32,
    unit_total: u32,
    chunk_begin: u32,
    window_begin: u32,
    window_end: u32,
    parts: u32,
    pad: [u32; 3],
}

/// Push constants of `grad_reduce_texels.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct TexelReducePush {
    face_count: u32,
    texels: u32,
    texel_begin: u32,
    texel_end: u32,
    texel_group: u32,
    stride: u32,
    unit_total: u32,
    chunk_begin: u32,
    window_begin: u32,
    window_end: u32,
    parts: u32,
    first_view: u32,
    group_views: u32,
    view_begin: u32,
    view_end: u32,
    masked: u32,
}

/// One view group's units, for the reductions.
pub(super) struct UnitGroup<'a> {
    pub(super) first_view: u32,
    pub(super) views: u32,
    pub(super) units: u64,
    /// Brute force: units per item (bands); 0: tiled, from `offsets`.
    pub(super) parts: u32,
    pub(super) offsets: BufferRange<'a>,
    /// The most units one item holds.
    pub(super) per_item: u64,
}

impl GradKernels {
    /// Adds the partials of units `begin .. end` (the chunk in `gb.partials`) of `group` to the
    /// running per-face sums and, with surface colours, per-texel sums, in unit order.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn record_reduce(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        gb: &GradBuffers,
        io: &GradIo<'_>,
        group: &UnitGroup<'_>,
        begin: u64,
        end: u64,
        limit: Option<u64>,
    ) -> Result<()> {
        let item_count = group.views * scene.face_count;
        let texels = scene.texture_res * scene.texture_res;
        let ReducePlan {
            window,
            view_step,
            texel_window,
            texel_step,
        } = reduce_plan(
            end - begin,
            group.per_item,
            u64::from(group.views),
            u64::from(texels),
            limit,
        );
        let mut w = begin;
        while w < end {
            let w_end = end.min(w + window);
            let push = ReducePush {
                item_count,
                first_item: group.first_view * scene.face_count,
                stride: gb.stride,
                width: gb.width,
                unit_total: group.units as u32,
                chunk_begin: begin as u32,
                window_begin: w as u32,
                window_end: w_end as u32,
                parts: group.parts,
                pad: [0; 3],
            };
            rec.dispatch(
                &self.reduce,
                &specs::GradReduceBindings {
                    offsets: group.offsets,
                    partials: gb.partials.whole(),
                    face_grads: gb.face_grads.whole(),
                }
                .for_kernel(&self.reduce)?,
                &push,
                groups(u64::from(item_count), 64)?,
            )?;
            w = w_end;
        }
        if scene.settings.color_mode != ColorMode::Surface {
            return Ok(());
        }
        // Texel ranges are independent; within one, windows and views go in unit order.
        let mut t = 0;
        while t < texels {
            let t_end = texels.min(t + texel_step as u32);
            let group_texels = texel_reduce_group(rec.context(), t_end - t);
            let invocations =
                u64::from(scene.face_count) * u64::from((t_end - t).div_ceil(group_texels));
            let mut w = begin;
            while w < end {
                let w_end = end.min(w + texel_window);
                let mut v = 0;
                while v < group.views {
                    let v_end = group.views.min(v + view_step as u32);
                    let push = TexelReducePush {
                        face_count: scene.face_count,
                        texels,
                        texel_begin: t,
                        texel_end: t_end,
                        texel_group: group_texels,
                        stride: gb.stride,
                        unit_total: group.units as u32,
                        chunk_begin: begin as u32,
                        window_begin: w as u32,
                        window_end: w_end as u32,
                        parts: group.parts,
                        first_view: group.first_view,
                        group_views: group.views,
                        view_begin: v,
                        view_end: v_end,
                        masked: u32::from(gb.texel_masks(scene)),
                    };
                    rec.dispatch(
                        &self.reduce_texels,
                        &specs::GradReduceTexelsBindings {
                            views: scene.views.whole(),
                            offsets: group.offsets,
                            partials: gb.partials.whole(),
                            texel_grads: io.colors,
                        }
                        .for_kernel(&self.reduce_texels)?,
                        &push,
                        groups(invocations, 64)?,
                    )?;
                    v = v_end;
                }
                w = w_end;
            }
            t = t_end;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        assert_eq!(
            std::mem::size_of::<ReducePush>() as u32,
            specs::GRAD_REDUCE.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<TexelReducePush>() as u32,
            specs::GRAD_REDUCE_TEXELS.push_constant_size
        );
        assert_eq!(specs::GRAD_REDUCE.bindings.len(), 3);
        assert_eq!(specs::GRAD_REDUCE_TEXELS.bindings.len(), 4);
    }
}
