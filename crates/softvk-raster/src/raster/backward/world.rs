//! Stages 4 and 5 of the backward: per (view, face), screen → camera → world through the
//! view's projection (`grad_world.comp`, the twin's `face_screen_to_world_grad`); then per
//! vertex, the sum over views and incident corners in a fixed order (`grad_gather.comp`, the
//! twin's `VertexFaces::gather`).

use bytemuck::{Pod, Zeroable};

use super::{GradBuffers, GradIo, GradKernels};
use crate::error::Result;
use crate::gpu::Recorder;
use crate::raster::scene::GpuScene;
use crate::raster::settings::ColorMode;
use crate::raster::specs;

/// Push constants of `grad_world.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct WorldPush {
    face_count: u32,
    view_count: u32,
    vertex_count: u32,
    stride: u32,
    position_offset: u32,
    position_stride: u32,
}

/// Push constants of `grad_gather.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GatherPush {
    vertex_count: u32,
    mesh_count: u32,
    face_count: u32,
    view_count: u32,
    stride: u32,
    vertex_colors: u32,
    pad: [u32; 2],
}

impl GradKernels {
    /// Stage 4: the per-face screen gradients to camera and world corner gradients.
    pub(super) fn record_world(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        gb: &GradBuffers,
    ) -> Result<()> {
        let items = scene.face_count * scene.view_count;
        let world = WorldPush {
            face_count: scene.face_count,
            view_count: scene.view_count,
            vertex_count: scene.vertex_count,
            stride: gb.width,
            position_offset: scene.position_layout.offset,
            position_stride: scene.position_layout.stride,
        };
        rec.pass("grad world", |rec| {
            rec.dispatch(
                &self.world,
                &specs::GradWorldBindings {
                    positions: scene.position_range()?,
                    faces: scene.faces.whole(),
                    views: scene.views.whole(),
                    face_grads: gb.face_grads.whole(),
                    corner_world: gb.corner_world.whole(),
                    corner_cam: gb.corner_cam.whole(),
                }
                .for_kernel(&self.world)?,
                &world,
                items.div_ceil(64),
            )
        })
    }

    /// Stage 5: the corner gradients summed per vertex into `io.positions` (and, with vertex
    /// colours, the colour gradients into `io.colors`).
    pub(super) fn record_gather(
        &self,
        rec: &mut Recorder<'_>,
        scene: &GpuScene,
        gb: &GradBuffers,
        io: &GradIo<'_>,
    ) -> Result<()> {
        let meshes = scene.meshes.len() as u32;
        let vertex_colors = scene.settings.color_mode == ColorMode::Vertex;
        let gather = GatherPush {
            vertex_count: scene.vertex_count,
            mesh_count: meshes,
            face_count: scene.face_count,
            view_count: scene.view_count,
            stride: gb.width,
            vertex_colors: u32::from(vertex_colors),
            pad: [0; 2],
        };
        rec.pass("grad gather", |rec| {
            rec.dispatch(
                &self.gather,
                &specs::GradGatherBindings {
                    offsets: gb.vertex_offsets.whole(),
                    slots: gb.vertex_slots.whole(),
                    views: gb.mesh_views.whole(),
                    corner_world: gb.corner_world.whole(),
                    face_grads: gb.face_grads.whole(),
                    position_grads: io.positions,
                    color_grads: io.colors,
                }
                .for_kernel(&self.gather)?,
                &gather,
                (scene.vertex_count * meshes).div_ceil(64),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        assert_eq!(
            std::mem::size_of::<WorldPush>() as u32,
            specs::GRAD_WORLD.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<GatherPush>() as u32,
            specs::GRAD_GATHER.push_constant_size
        );
    }
}
