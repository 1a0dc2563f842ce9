//! Stage 6 of the backward, on the host in f64 where the forward lights: the results read back,
//! plus lighting's backward (raw colours, and normals → positions) with the twin's own
//! functions, and the camera gradient (look-at).

use glam::DVec3;

use super::{GradBuffers, GradIo, GradKernels};
use crate::error::Result;
use crate::gpu::Context;
use crate::raster::reference_grad::{
    self, Gradients, VertexFaces, camera_grad, lighting_grad_surface, lighting_grad_vertex,
};
use crate::raster::scene::GpuScene;
use crate::raster::settings::ColorMode;

impl GradKernels {
    /// Reads the recorded backward's results and adds the host's f64 share: lighting (raw
    /// colours; normals → positions) and, with `cameras`, the camera gradient per view.
    /// Positions and colours come mesh after mesh for a batch.
    pub fn finish(
        &self,
        ctx: &Context,
        scene: &GpuScene,
        gb: &GradBuffers,
        io: &GradIo<'_>,
        cameras: bool,
    ) -> Result<Gradients> {
        let nv = scene.vertex_count as usize;
        let nf = scene.face_count as usize;
        let batch = scene.meshes.len();
        let widen = |v: [f32; 3]| v.map(f64::from);
        let positions: Vec<[f32; 3]> =
            ctx.read_buffer(io.positions.buffer, io.positions.offset, nv * batch)?;
        let mode = scene.settings.color_mode;
        let slots = reference_grad::color_slots(mode, scene.texture_res);
        let per_mesh_colors = match mode {
            ColorMode::Surface => nf * slots,
            ColorMode::Vertex => nv,
        };
        let lit: Vec<[f32; 3]> =
            ctx.read_buffer(io.colors.buffer, io.colors.offset, per_mesh_colors * batch)?;
        let adjacency = VertexFaces::new(&scene.meshes[0].faces, nv);
        let mut out = Gradients {
            positions: Vec::with_capacity(nv * batch),
            colors: Vec::with_capacity(per_mesh_colors * batch),
            cameras: Vec::new(),
        };
        for (m, mesh) in scene.meshes.iter().enumerate() {
            let d_lit: Vec<[f64; 3]> = lit[m * per_mesh_colors..(m + 1) * per_mesh_colors]
                .iter()
                .map(|&c| widen(c))
                .collect();
            if d_lit.iter().all(|c| *c == [0.0; 3]) {
                // Nothing reached the lit colours (an alpha-only upstream): lighting's share is
                // exactly zero, for colours and positions alike; skip computing it.
                let texels = match mode {
                    ColorMode::Surface => mesh.textures.len(),
                    ColorMode::Vertex => nv,
                };
                out.positions.extend(
                    positions[m * nv..(m + 1) * nv]
                        .iter()
                        .map(|&g| widen(g).map(|c| c + 0.0)),
                );
                out.colors.extend(std::iter::repeat_n([0.0; 3], texels));
                continue;
            }
            let (colors, corners) = match mode {
                ColorMode::Surface => lighting_grad_surface(
                    &scene.lighting,
                    &mesh.positions,
                    &mesh.faces,
                    mesh.texture_res,
                    &mesh.textures,
                    &d_lit,
                ),
                ColorMode::Vertex => lighting_grad_vertex(
                    &scene.lighting,
                    &mesh.positions,
                    &mesh.faces,
                    mesh.vertex_colors.as_deref(),
                    &d_lit,
                ),
            };
            let from_light = adjacency.gather(&corners);
            for (v, light) in from_light.iter().enumerate() {
                let g = widen(positions[m * nv + v]);
                out.positions.push(std::array::from_fn(|k| g[k] + light[k]));
            }
            out.colors.extend(colors);
        }
        if cameras {
            let items = nf * scene.view_count as usize;
            let cam: Vec<[f32; 3]> = ctx.read_buffer(&gb.corner_cam, 0, 3 * items)?;
            let world: Vec<[f32; 3]> = ctx.read_buffer(&gb.corner_world, 0, 3 * items)?;
            for (v, (m, camera)) in scene.views_host.iter().enumerate() {
                let mesh = &scene.meshes[*m];
                let mut d_rotation = [[0.0; 3]; 3];
                let mut d_world_sum = [0.0; 3];
                for (f, face) in mesh.faces.iter().enumerate() {
                    for (c, &vi) in face.iter().enumerate() {
                        let k = 3 * (v * nf + f) + c;
                        let d_cam = widen(cam[k]);
                        let rel: DVec3 = mesh.positions[vi as usize] - camera.eye;
                        for i in 0..3 {
                            for j in 0..3 {
                                d_rotation[i][j] += d_cam[i] * rel[j];
                            }
                            d_world_sum[i] += f64::from(world[k][i]);
                        }
                    }
                }
                out.cameras
                    .push(camera_grad(camera, d_rotation, d_world_sum));
            }
        }
        Ok(out)
    }
}
