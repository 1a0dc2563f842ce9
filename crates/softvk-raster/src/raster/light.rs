//! Lighting on the GPU: the scene's lit colours from its world positions, and the lighting's
//! backward, recordable into any command buffer (no host round trip), so that a loop whose
//! vertices move (a pose fit, a host engine's deforming mesh) keeps its colours and gradients
//! on the GPU.
//!
//! The maths is [`crate::lighting`]'s (SoftRas's Lambertian lighting in world space, before
//! projection), in f32: `light_forward.comp` (twin: [`Lighting::apply_surface_of`] /
//! [`Lighting::apply_vertex_of`]), then, after a backward has written dL/d(lit colour),
//! `light_backward.comp` (dL/d(unlit colour), and per (face, corner) the normals' share of
//! dL/d(world position); twin: [`lighting_grad_surface`] /
//! [`lighting_grad_vertex`]) and `light_gather.comp`, which adds each vertex's
//! slots, in face order, to the position gradient already there (twin:
//! [`VertexFaces::gather`] and the sum [`GradKernels::finish`] forms on the host). One writer
//! per value and fixed summation orders: repeated runs are bit-identical.
//!
//! [`GradKernels::finish`]: super::backward::GradKernels::finish
//! [`lighting_grad_surface`]: super::reference_grad::lighting_grad_surface
//! [`lighting_grad_vertex`]: super::reference_grad::lighting_grad_vertex

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::reference_grad::VertexFaces;
use super::scene::GpuScene;
use super::settings::ColorMode;
use super::setup::VertexLayout;
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::gpu::{check_binding, groups};
use crate::lighting::Lighting;
use crate::raster::specs;

/// Push constants of the lighting kernels (`kernels/raster/include/light_io.glsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct LightPush {
    vertex_count: u32,
    face_count: u32,
    mesh_count: u32,
    texels: u32,
    directionals: u32,
    vertex_mode: u32,
    phase: u32,
    position_offset: u32,
    position_stride: u32,
}

/// A scene's lighting on the GPU: its unlit colours, lights and vertex–face incidence, and the
/// kernels. Made for one scene ([`SceneLight::new`]); records over any buffers laid out as
/// that scene's.
pub struct SceneLight {
    forward: Arc<Kernel>,
    backward: Arc<Kernel>,
    gather: Arc<Kernel>,
    /// Unlit colours (surface: texels; vertex: vertex colours, white without), RGB + unused.
    base: Buffer,
    /// Ambient, then (direction, I c) per directional light.
    lights: Buffer,
    /// The faces' vertex indices (3 per face), shared by the batch's meshes.
    faces: Buffer,
    /// CSR of each vertex's (face, corner) slots: offsets (V + 1), then slots (3 F).
    incident: Buffer,
    /// Vertex mode: dL/d(normal sum) per vertex of each mesh.
    d_sums: Buffer,
    /// dL/d(world position) per (mesh, face, corner).
    corners: Buffer,
    push: LightPush,
    colors: u64,
}

impl SceneLight {
    /// The lighting of `scene` (its meshes' unlit colours, its [`Lighting`] and colour mode),
    /// uploaded once.
    pub fn new(ctx: &Context, scene: &GpuScene) -> Result<Self> {
        let meshes = &scene.meshes;
        let Some(first) = meshes.first() else {
            return Err(Error::Misuse("lighting a scene without meshes".into()));
        };
        let (nv, nf) = (first.positions.len(), first.faces.len());
        let vertex_mode = scene.settings.color_mode == ColorMode::Vertex;
        let texels = (first.texture_res * first.texture_res) as usize;
        let mut base: Vec<[f32; 4]> = Vec::new();
        for m in meshes {
            if vertex_mode {
                match &m.vertex_colors {
                    Some(cs) => base.extend(cs.iter().map(|c| rgb0(*c))),
                    None => base.extend(std::iter::repeat_n([1.0, 1.0, 1.0, 0.0], nv)),
                }
            } else {
                base.extend(m.textures.iter().map(|c| rgb0(*c)));
            }
        }
        let colors = base.len() as u64;
        let incidence = VertexFaces::new(&first.faces, nv);
        let mut incident = incidence.offsets.clone();
        incident.extend(&incidence.slots);
        let corners = 3 * nf as u64 * meshes.len() as u64;
        check_binding(ctx, "lighting: corner gradients", 16 * corners)?;
        let light_rows = light_rows(&scene.lighting);
        let layout = scene.position_layout();
        Ok(Self {
            forward: ctx.kernel(&specs::LIGHT_FORWARD, &[])?,
            backward: ctx.kernel(&specs::LIGHT_BACKWARD, &[])?,
            gather: ctx.kernel(&specs::LIGHT_GATHER, &[])?,
            base: ctx.upload_buffer("light unlit colours", &base)?,
            faces: ctx.upload_buffer("light faces", first.faces.as_flattened())?,
            lights: ctx.upload_buffer("light parameters", &light_rows)?,
            incident: ctx.upload_buffer("light vertex incidence", &incident)?,
            d_sums: ctx.create_buffer(
                "light normal-sum gradients",
                16 * (nv * meshes.len()).max(1) as u64,
                MemoryKind::Device,
            )?,
            corners: ctx.create_buffer(
                "light corner gradients",
                16 * corners.max(1),
                MemoryKind::Device,
            )?,
            push: LightPush {
                vertex_count: nv as u32,
                face_count: nf as u32,
                mesh_count: meshes.len() as u32,
                texels: texels as u32,
                directionals: scene.lighting.directionals.len() as u32,
                vertex_mode: u32::from(vertex_mode),
                phase: 0,
                position_offset: layout.offset,
                position_stride: layout.stride,
            },
            colors,
        })
    }

    /// Colours lit per mesh of the batch: texels (surface) or vertices (vertex mode), all meshes.
    pub fn color_count(&self) -> u64 {
        self.colors
    }

    fn vertices(&self) -> u64 {
        u64::from(self.push.vertex_count) * u64::from(self.push.mesh_count)
    }

    fn face_total(&self) -> u64 {
        u64::from(self.push.face_count) * u64::from(self.push.mesh_count)
    }

    fn check_positions(&self, positions: &BufferRange<'_>, layout: VertexLayout) -> Result<()> {
        if (layout.offset, layout.stride) != (self.push.position_offset, self.push.position_stride)
        {
            return Err(Error::Misuse(format!(
                "lighting: positions laid out as {layout:?}, the scene's were offset {} stride {}",
                self.push.position_offset, self.push.position_stride
            )));
        }
        positions.require(layout.bytes(self.vertices())?, "lighting: world positions")
    }

    /// Records the lit colours of the world positions `positions` (laid out as `layout`, the
    /// scene's) into `lit` ([`GpuScene::colors`]' layout: RGB and an unused float each).
    pub fn record_forward(
        &self,
        rec: &mut Recorder<'_>,
        positions: BufferRange<'_>,
        layout: VertexLayout,
        lit: BufferRange<'_>,
    ) -> Result<()> {
        self.check_positions(&positions, layout)?;
        lit.require(16 * self.colors, "lighting: lit colours")?;
        let n = if self.push.vertex_mode != 0 {
            self.vertices()
        } else {
            self.face_total()
        };
        rec.dispatch(
            &self.forward,
            &specs::LightForwardBindings {
                positions,
                faces: self.faces.whole(),
                base: self.base.whole(),
                lights: self.lights.whole(),
                incident: self.incident.whole(),
                lit,
            }
            .for_kernel(&self.forward)?,
            &self.push,
            groups(n, 64)?,
        )
    }

    /// Records the lighting's backward at `positions`: from `d_lit` (dL/d(lit colour), 3 floats
    /// per colour, as the backward writes them) to `d_base` (dL/d(unlit colour), 3 floats each)
    /// and, through the normals, the positions' share, added to `d_positions` (3 floats per
    /// vertex, mesh after mesh), which holds the rest of dL/d(world position) already.
    #[allow(clippy::too_many_arguments)]
    pub fn record_backward(
        &self,
        rec: &mut Recorder<'_>,
        positions: BufferRange<'_>,
        layout: VertexLayout,
        d_lit: BufferRange<'_>,
        d_base: BufferRange<'_>,
        d_positions: BufferRange<'_>,
    ) -> Result<()> {
        self.check_positions(&positions, layout)?;
        d_lit.require(12 * self.colors, "lighting: dL/d(lit colour)")?;
        d_base.require(12 * self.colors, "lighting: dL/d(unlit colour)")?;
        d_positions.require(12 * self.vertices(), "lighting: dL/d(world position)")?;
        let vertex_mode = self.push.vertex_mode != 0;
        let phases: &[(u32, u64)] = if vertex_mode {
            &[(0, self.vertices()), (1, self.face_total())]
        } else {
            &[(0, self.face_total())]
        };
        for &(phase, n) in phases {
            rec.dispatch(
                &self.backward,
                &specs::LightBackwardBindings {
                    positions,
                    faces: self.faces.whole(),
                    base: self.base.whole(),
                    lights: self.lights.whole(),
                    incident: self.incident.whole(),
                    d_lit,
                    d_base,
                    d_sums: self.d_sums.whole(),
                    corners: self.corners.whole(),
                }
                .for_kernel(&self.backward)?,
                &LightPush { phase, ..self.push },
                groups(n, 64)?,
            )?;
        }
        rec.dispatch(
            &self.gather,
            &specs::LightGatherBindings {
                positions,
                faces: self.faces.whole(),
                base: self.base.whole(),
                lights: self.lights.whole(),
                incident: self.incident.whole(),
                corners: self.corners.whole(),
                d_positions,
            }
            .for_kernel(&self.gather)?,
            &self.push,
            groups(self.vertices(), 64)?,
        )
    }
}

fn rgb0(c: [f64; 3]) -> [f32; 4] {
    [c[0] as f32, c[1] as f32, c[2] as f32, 0.0]
}

/// The rows `lights` holds: ambient `I_a c_a`, then per directional light its direction and
/// `I_l c_l`, in f32 as the kernels read them.
fn light_rows(lighting: &Lighting) -> Vec<[f32; 4]> {
    let ambient = lighting
        .ambient_color
        .map(|c| lighting.ambient_intensity * c);
    let mut rows = vec![rgb0(ambient)];
    for d in &lighting.directionals {
        rows.push(rgb0(d.direction));
        rows.push(rgb0(d.color.map(|c| d.intensity * c)));
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layout_matches_the_kernels() {
        for spec in [
            &specs::LIGHT_FORWARD,
            &specs::LIGHT_BACKWARD,
            &specs::LIGHT_GATHER,
        ] {
            assert_eq!(
                std::mem::size_of::<LightPush>() as u32,
                spec.push_constant_size
            );
        }
    }
}
