//! The GPU backward pass (SPEC §3, §4): from dL/d(image) to dL/d(world vertex positions), dL/d(raw
//! texels or vertex colours) and dL/d(camera), the exact derivative of the forward in f32.
//!
//! The stages mirror the f64 twin [`crate::raster::reference_grad`] step for step:
//!
//! 1. **Per (pixel, face)** (`kernels/include/raster_grad.glsl`, the twin's `pixel_face_grad`):
//!    from the pixel's upstream gradient and the forward's [`PixelAux`](super::fine::PixelAux),
//!    one face's contribution, independently of the other faces.
//! 2. **Per face**, either
//!    - tiled (`grad_tiled.comp`): per (face, tile) entry of the forward's binning (no second
//!      binning), one invocation sums the face over the tile's pixels and writes the partial at
//!      the entry's item-major slot; then `grad_reduce.comp` sums each face's contiguous slots in
//!      order; or
//!    - brute force (`grad_brute.comp`, the baseline): one invocation per (view, face) over every
//!      pixel.
//!
//!    Each value has one writer and a fixed summation order: no float atomics, and repeated
//!    runs are bit-identical.
//! 3. **Per (view, face)** (`grad_world.comp`, the twin's `face_screen_to_world_grad`): screen →
//!    camera → world, through perspective, orthographic or the matrix projection.
//! 4. **Per vertex** (`grad_gather.comp`, the twin's `VertexFaces::gather`) and **per texel**
//!    (`grad_texels.comp`): summed over views and incident corners in a fixed order.
//! 5. **On the host, in f64**, where the forward lights: the lighting's backward (raw colours,
//!    and normals → positions) with the twin's own functions, and the camera gradient (look-at).

use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use super::fine::{FLAG_ANTIALIAS, RasterPush};
use super::gpu::{GpuScene, Method};
use super::reference::ColorMode;
use super::reference_grad::{
    self, Gradients, VertexFaces, camera_grad, lighting_grad_surface, lighting_grad_vertex,
};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, Kernel, MemoryKind, Recorder, specs};

/// Push constants of `grad_reduce.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ReducePush {
    item_count: u32,
    first_item: u32,
    stride: u32,
    entry_total: u32,
}

/// Push constants of `grad_world.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct WorldPush {
    face_count: u32,
    view_count: u32,
    vertex_count: u32,
    stride: u32,
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

/// Push constants of `grad_texels.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct TexelsPush {
    texels: u32,
    face_count: u32,
    mesh_count: u32,
    view_count: u32,
    stride: u32,
    pad: [u32; 3],
}

/// The backward's pipelines, made once per context.
pub struct GradKernels {
    tiled: Kernel,
    brute: Kernel,
    reduce: Kernel,
    world: Kernel,
    gather: Kernel,
    texels: Kernel,
}

impl GradKernels {
    /// Builds the pipelines.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            tiled: Kernel::new(ctx, &specs::GRAD_TILED)?,
            brute: Kernel::new(ctx, &specs::GRAD_BRUTE)?,
            reduce: Kernel::new(ctx, &specs::GRAD_REDUCE)?,
            world: Kernel::new(ctx, &specs::GRAD_WORLD)?,
            gather: Kernel::new(ctx, &specs::GRAD_GATHER)?,
            texels: Kernel::new(ctx, &specs::GRAD_TEXELS)?,
        })
    }
}

/// Floats per face gradient: 9 screen coordinates, then the colour slots (R² texels or 3
/// corners) × RGB.
pub fn grad_stride(mode: ColorMode, texture_res: u32) -> u32 {
    9 + 3 * reference_grad::color_slots(mode, texture_res) as u32
}

/// The buffers of one scene's backward, reusable across backward passes of that scene.
pub struct GradBuffers {
    pub(crate) d_image: Buffer,
    partials: Option<Buffer>,
    face_grads: Buffer,
    corner_world: Buffer,
    corner_cam: Buffer,
    vertex_offsets: Buffer,
    vertex_slots: Buffer,
    pub(crate) position_grads: Buffer,
    color_grads: Buffer,
    method: Method,
    stride: u32,
    entry_capacity: u64,
}

fn checked(ctx: &Context, what: &str, bytes: u64) -> Result<u64> {
    let max = u64::from(ctx.info().limits.max_storage_buffer_range);
    if bytes > max {
        return Err(Error::Limit(format!(
            "the backward's {what} buffer would need {bytes} bytes, over this device's \
             maxStorageBufferRange ({max}); use fewer views, larger tiles, a smaller σ or a \
             smaller texture resolution"
        )));
    }
    Ok(bytes.max(4))
}

impl GradBuffers {
    /// Buffers for the backward of `scene` by `method`. Tiled needs the scene's last forward run
    /// to have been tiled with the same tile size (the backward reuses its binning).
    pub fn new(ctx: &Context, scene: &GpuScene, method: Method) -> Result<Self> {
        // Headroom, so that a fit whose entries breathe does not reallocate every step.
        let most = scene.groups.iter().map(|g| g.entries).max().unwrap_or(0);
        Self::with_entry_capacity(ctx, scene, method, most + most / 4)
    }

    /// As [`GradBuffers::new`], with tiled partials for `entries` (face, tile) entries (at least
    /// the scene's largest group; at most what one binding holds): a guarded fitting loop sizes
    /// them as its bins.
    pub(crate) fn with_entry_capacity(
        ctx: &Context,
        scene: &GpuScene,
        method: Method,
        entries: u64,
    ) -> Result<Self> {
        if let Method::Tiled { tile } = method {
            if scene.tile != Some(tile) || scene.groups.is_empty() {
                return Err(Error::Input(format!(
                    "the tiled backward (tile {tile}) needs a forward run with the same tiles \
                     first (the scene was last binned with {:?})",
                    scene.tile
                )));
            }
        }
        let stride = grad_stride(scene.settings.color_mode, scene.texture_res);
        let items = u64::from(scene.face_count) * u64::from(scene.view_count);
        let outputs = u64::from(scene.settings.width)
            * u64::from(scene.settings.height)
            * u64::from(scene.view_count);
        let batch = scene.meshes.len() as u64;
        let vertices = u64::from(scene.vertex_count) * batch;
        let color_values = match scene.settings.color_mode {
            ColorMode::Surface => {
                u64::from(scene.face_count) * u64::from(scene.texture_res).pow(2) * batch
            }
            ColorMode::Vertex => vertices,
        };
        let adjacency = VertexFaces::new(&scene.meshes[0].faces, scene.vertex_count as usize);
        let entry_capacity = match method {
            Method::Brute => 0,
            Method::Tiled { .. } => {
                let most = scene.groups.iter().map(|g| g.entries).max().unwrap_or(0);
                let max =
                    u64::from(ctx.info().limits.max_storage_buffer_range) / (4 * u64::from(stride));
                entries.min(max).max(most)
            }
        };
        let partials = match method {
            Method::Brute => None,
            Method::Tiled { .. } => Some(ctx.create_buffer(
                "grad partials",
                checked(ctx, "partials", entry_capacity * u64::from(stride) * 4)?,
                MemoryKind::Device,
            )?),
        };
        let device = |name: &str, bytes: u64| -> Result<Buffer> {
            ctx.create_buffer(name, checked(ctx, name, bytes)?, MemoryKind::Device)
        };
        Ok(Self {
            d_image: device("d_image", 16 * outputs)?,
            partials,
            face_grads: device("face grads", items * u64::from(stride) * 4)?,
            corner_world: device("corner world grads", items * 36)?,
            corner_cam: device("corner camera grads", items * 36)?,
            vertex_offsets: ctx.upload_buffer("vertex offsets", &adjacency.offsets)?,
            vertex_slots: ctx.upload_buffer("vertex slots", &adjacency.slots)?,
            position_grads: device("position grads", vertices * 12)?,
            color_grads: device("colour grads", color_values * 12)?,
            method,
            stride,
            entry_capacity,
        })
    }

    /// The (face, tile) entries the tiled partials can hold (0 for brute force).
    pub fn entry_capacity(&self) -> u64 {
        self.entry_capacity
    }

    /// Uploads dL/d(image): RGBA per output pixel, view-major, row-major.
    pub fn set_d_image(&self, ctx: &Context, scene: &GpuScene, d_image: &[[f32; 4]]) -> Result<()> {
        let s = &scene.settings;
        let want = (s.width * s.height * scene.view_count) as usize;
        if d_image.len() != want {
            return Err(Error::Input(format!(
                "the image gradient has {} pixels; {} views of {}x{} need {want}",
                d_image.len(),
                scene.view_count,
                s.width,
                s.height
            )));
        }
        if let Some(i) = d_image
            .iter()
            .position(|g| !g.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Input(format!(
                "the image gradient is not finite at pixel {} of view {}",
                i % (s.width * s.height) as usize,
                i / (s.width * s.height) as usize
            )));
        }
        ctx.write_buffer(&self.d_image, 0, d_image)
    }
}

impl GradKernels {
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
            true,
        );
        if s.antialias {
            push.flags |= FLAG_ANTIALIAS;
        }
        push.out_width = s.width;
        push.out_height = s.height;
        push.grad_stride = stride;
        push
    }

    /// Records the whole backward of `scene` into `gb` (after its forward and
    /// [`GradBuffers::set_d_image`]): per-face gradients by `gb`'s method, then world, vertex and
    /// texel sums. [`GradKernels::finish`] reads them back and adds the host's share.
    pub fn record(&self, rec: &mut Recorder<'_>, scene: &GpuScene, gb: &GradBuffers) -> Result<()> {
        let stride = gb.stride;
        let items = scene.face_count * scene.view_count;
        match gb.method {
            Method::Brute => {
                if let Some(limit) = rec.context().info().shader_loop_limit() {
                    let n = u64::from(scene.width) * u64::from(scene.height + 1) + 2;
                    if n > limit {
                        return Err(Error::Limit(format!(
                            "the brute-force backward loops over all {}x{} rendered pixels in \
                             one shader invocation, over the {limit} iterations {} allows (it \
                             would silently skip the rest); use the tiled method",
                            scene.width,
                            scene.height,
                            rec.context().info().name
                        )));
                    }
                }
                let push = Self::fine_push(scene, stride);
                rec.pass("grad brute", |rec| {
                    rec.dispatch(
                        &self.brute,
                        &[
                            scene.setups.whole(),
                            scene.colors.whole(),
                            scene.faces.whole(),
                            scene.image.whole(),
                            scene.aux.whole(),
                            gb.d_image.whole(),
                            gb.face_grads.whole(),
                        ],
                        &push,
                        items.div_ceil(64),
                    )
                })?;
            }
            Method::Tiled { tile } => {
                let partials = gb
                    .partials
                    .as_ref()
                    .ok_or_else(|| Error::Input("tiled backward without partials".into()))?;
                let grid = scene.grid(tile)?;
                if scene.tile != Some(tile) {
                    return Err(Error::Input(format!(
                        "the tiled backward (tile {tile}) needs the scene binned with those tiles"
                    )));
                }
                if let Some(limit) = rec.context().info().shader_loop_limit() {
                    for g in &scene.groups {
                        let n =
                            super::gpu::tiled_backward_iterations(g.max_tile_entries, tile, stride);
                        if n > limit {
                            return Err(Error::Limit(format!(
                                "a tile holds {} faces: the tiled backward would run {n} loop \
                                 iterations in one shader invocation, over the {limit} {} \
                                 allows (it would silently skip the rest); use smaller tiles",
                                g.max_tile_entries,
                                rec.context().info().name
                            )));
                        }
                    }
                }
                if let Some(g) = scene.groups.iter().find(|g| g.entries > gb.entry_capacity) {
                    return Err(Error::Limit(format!(
                        "the backward's partials hold {} entries; the scene now has {} (make \
                         new GradBuffers)",
                        gb.entry_capacity, g.entries
                    )));
                }
                for (group, bins) in scene.groups.iter().zip(&scene.bins) {
                    if group.entries == 0 {
                        // No face touches these views: their gradients are zero.
                        let first = u64::from(group.first) * u64::from(scene.face_count);
                        let n = u64::from(group.views) * u64::from(scene.face_count);
                        rec.fill(
                            gb.face_grads
                                .range(4 * first * u64::from(stride), 4 * n * u64::from(stride)),
                            0,
                        );
                        continue;
                    }
                    let mut push = Self::fine_push(scene, stride);
                    push.first_view = group.first;
                    push.view_count = group.views;
                    push.tile_size = tile;
                    push.tiles_x = grid.tiles_x;
                    push.tiles_y = grid.tiles_y;
                    push.entry_total = group.entries as u32;
                    let tiles = grid.tiles_per_view() * u64::from(group.views);
                    rec.pass("grad tiled", |rec| {
                        rec.dispatch(
                            &self.tiled,
                            &[
                                scene.setups.whole(),
                                scene.colors.whole(),
                                scene.faces.whole(),
                                scene.image.whole(),
                                scene.aux.whole(),
                                gb.d_image.whole(),
                                partials.whole(),
                                bins.entries().whole(),
                                bins.entry_items().whole(),
                                bins.ranges().whole(),
                            ],
                            &push,
                            u32::try_from(tiles).map_err(|_| {
                                Error::Limit(format!("grad_tiled: {tiles} workgroups"))
                            })?,
                        )
                    })?;
                    let group_items = group.views * scene.face_count;
                    let reduce = ReducePush {
                        item_count: group_items,
                        first_item: group.first * scene.face_count,
                        stride,
                        entry_total: group.entries as u32,
                    };
                    rec.pass("grad reduce", |rec| {
                        rec.dispatch(
                            &self.reduce,
                            &[
                                bins.offsets().whole(),
                                partials.whole(),
                                gb.face_grads.whole(),
                            ],
                            &reduce,
                            group_items.div_ceil(64),
                        )
                    })?;
                }
            }
        }
        let world = WorldPush {
            face_count: scene.face_count,
            view_count: scene.view_count,
            vertex_count: scene.vertex_count,
            stride,
        };
        rec.pass("grad world", |rec| {
            rec.dispatch(
                &self.world,
                &[
                    scene.positions.whole(),
                    scene.faces.whole(),
                    scene.views.whole(),
                    gb.face_grads.whole(),
                    gb.corner_world.whole(),
                    gb.corner_cam.whole(),
                ],
                &world,
                items.div_ceil(64),
            )
        })?;
        let meshes = scene.meshes.len() as u32;
        let vertex_colors = scene.settings.color_mode == ColorMode::Vertex;
        let gather = GatherPush {
            vertex_count: scene.vertex_count,
            mesh_count: meshes,
            face_count: scene.face_count,
            view_count: scene.view_count,
            stride,
            vertex_colors: u32::from(vertex_colors),
            pad: [0; 2],
        };
        rec.pass("grad gather", |rec| {
            rec.dispatch(
                &self.gather,
                &[
                    gb.vertex_offsets.whole(),
                    gb.vertex_slots.whole(),
                    scene.views.whole(),
                    gb.corner_world.whole(),
                    gb.face_grads.whole(),
                    gb.position_grads.whole(),
                    gb.color_grads.whole(),
                ],
                &gather,
                (scene.vertex_count * meshes).div_ceil(64),
            )
        })?;
        if !vertex_colors {
            let texels = scene.texture_res * scene.texture_res;
            let push = TexelsPush {
                texels,
                face_count: scene.face_count,
                mesh_count: meshes,
                view_count: scene.view_count,
                stride,
                pad: [0; 3],
            };
            rec.pass("grad texels", |rec| {
                rec.dispatch(
                    &self.texels,
                    &[
                        scene.views.whole(),
                        gb.face_grads.whole(),
                        gb.color_grads.whole(),
                    ],
                    &push,
                    (scene.face_count * texels * meshes).div_ceil(64),
                )
            })?;
        }
        Ok(())
    }

    /// Reads the recorded backward's results and adds the host's f64 share: lighting (raw
    /// colours; normals → positions) and, with `cameras`, the camera gradient per view.
    /// Positions and colours come mesh after mesh for a batch.
    pub fn finish(
        &self,
        ctx: &Context,
        scene: &GpuScene,
        gb: &GradBuffers,
        cameras: bool,
    ) -> Result<Gradients> {
        let nv = scene.vertex_count as usize;
        let nf = scene.face_count as usize;
        let batch = scene.meshes.len();
        let widen = |v: [f32; 3]| v.map(f64::from);
        let positions: Vec<[f32; 3]> = ctx.read_buffer(&gb.position_grads, 0, nv * batch)?;
        let mode = scene.settings.color_mode;
        let slots = reference_grad::color_slots(mode, scene.texture_res);
        let per_mesh_colors = match mode {
            ColorMode::Surface => nf * slots,
            ColorMode::Vertex => nv,
        };
        let lit: Vec<[f32; 3]> = ctx.read_buffer(&gb.color_grads, 0, per_mesh_colors * batch)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layouts_match_the_kernels() {
        for spec in [&specs::GRAD_TILED, &specs::GRAD_BRUTE] {
            assert_eq!(
                std::mem::size_of::<RasterPush>() as u32,
                spec.push_constant_size,
                "{}",
                spec.name
            );
        }
        assert_eq!(
            std::mem::size_of::<ReducePush>() as u32,
            specs::GRAD_REDUCE.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<WorldPush>() as u32,
            specs::GRAD_WORLD.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<GatherPush>() as u32,
            specs::GRAD_GATHER.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<TexelsPush>() as u32,
            specs::GRAD_TEXELS.push_constant_size
        );
        assert_eq!(specs::GRAD_TILED.bindings.len(), 10);
        assert_eq!(specs::GRAD_BRUTE.bindings.len(), 7);
    }

    #[test]
    fn stride_counts_screen_and_colour_slots() {
        assert_eq!(grad_stride(ColorMode::Surface, 1), 12);
        assert_eq!(grad_stride(ColorMode::Surface, 3), 9 + 27);
        assert_eq!(grad_stride(ColorMode::Vertex, 5), 18);
    }
}
