//! The wgpu application's own buffers and passes: a WGSL compute pass "deform" before softvk,
//! a WGSL render pass "draw" after it. Nothing here knows about softvk.

use std::borrow::Cow;

use bytemuck::{Pod, Zeroable};

use crate::HostError;

/// Workgroup size of the deform kernel.
const WORKGROUP: u32 = 64;
/// Columns of the drawn image (`WIDTH` in `draw.wgsl`). 128 `u32` texels are 512 bytes, a
/// multiple of wgpu's 256-byte row alignment for copies, so the readback rows are contiguous.
pub const WIDTH: u32 = 128;
/// The drawn image's format: one `u32` per pixel.
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;

/// The uniform block of both WGSL modules.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Params {
    n: u32,
    frame: u32,
    rows: u32,
    pad: u32,
}

/// The application's buffers, image and pipelines, all wgpu's.
pub struct Scene {
    n: u32,
    rows: u32,
    params: wgpu::Buffer,
    /// Written by the deform pass; read by softvk, and by the draw pass as a vertex buffer.
    pub deformed: wgpu::Buffer,
    /// Written by softvk; read by the draw pass as a vertex buffer.
    pub scanned: wgpu::Buffer,
    image: wgpu::Texture,
    image_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    deform: wgpu::ComputePipeline,
    deform_group: wgpu::BindGroup,
    draw: wgpu::RenderPipeline,
    draw_group: wgpu::BindGroup,
}

/// A shader module from WGSL, handed to wgpu as naga IR rather than as text.
///
/// With `InstanceFlags::DEBUG` (which the host needs for VK_EXT_debug_utils) wgpu attaches WGSL
/// text to the SPIR-V it makes, as `OpSource` of source language 10 (WGSL), for debuggers. The
/// validation layer of Debian 12 (1.3.239) predates that language and rejects every such module
/// ("SPIR-V module not valid: Invalid source language operand: 10"). IR carries no source text,
/// so no `OpSource` is written; the shader code is the same.
fn shader(device: &wgpu::Device, label: &str, source: &str) -> wgpu::ShaderModule {
    let module = wgpu::naga::front::wgsl::parse_str(source)
        .unwrap_or_else(|e| panic!("{label}.wgsl: {}", e.emit_to_string(source)));
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Naga(Cow::Owned(module)),
    })
}

impl Scene {
    /// Buffers for `n` vertices (one `u32` each), the image, and the two pipelines.
    ///
    /// Every buffer is mapped at creation and unmapped at once: that zero-fills it and marks it
    /// initialized in wgpu's lazy-initialization tracking. Without it, wgpu would zero
    /// `scanned` before its first read in the draw pass, after softvk wrote it (wgpu does not
    /// see softvk's write), and the first frame would draw zeros.
    pub fn new(device: &wgpu::Device, n: u32) -> Self {
        let n = n.max(1);
        let rows = n.div_ceil(WIDTH);
        let bytes = 4 * u64::from(n);
        let buffer = |label, size, usage| {
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: true,
            });
            buffer.unmap();
            buffer
        };
        // softvk binds `deformed` and `scanned` as storage buffers; COPY_SRC/COPY_DST too, as
        // softvk's import contract asks of buffers it may copy or fill.
        let shared = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::VERTEX
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let params = buffer(
            "params",
            std::mem::size_of::<Params>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let deformed = buffer("deformed", bytes, shared);
        let scanned = buffer("scanned", bytes, shared);
        let extent = wgpu::Extent3d {
            width: WIDTH,
            height: rows,
            depth_or_array_layers: 1,
        };
        let image = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("drawn"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let image_view = image.create_view(&Default::default());
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: 4 * u64::from(WIDTH) * u64::from(rows),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });

        let module = shader(device, "deform", include_str!("shaders/deform.wgsl"));
        let deform = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("deform"),
            layout: None,
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let module = shader(device, "draw", include_str!("shaders/draw.wgsl"));
        let attribute = |location| wgpu::VertexAttribute {
            format: wgpu::VertexFormat::Uint32,
            offset: 0,
            shader_location: location,
        };
        let (deformed_attr, scanned_attr) = ([attribute(0)], [attribute(1)]);
        let layout = |attributes| {
            Some(wgpu::VertexBufferLayout {
                array_stride: 4,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes,
            })
        };
        let draw = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("draw"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[layout(&deformed_attr), layout(&scanned_attr)],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::PointList,
                ..Default::default()
            },
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        let group = |layout: &wgpu::BindGroupLayout, label, buffers: &[&wgpu::Buffer]| {
            let entries: Vec<_> = buffers
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry {
                    binding: i as u32,
                    resource: b.as_entire_binding(),
                })
                .collect();
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout,
                entries: &entries,
            })
        };
        let deform_group = group(
            &deform.get_bind_group_layout(0),
            "deform",
            &[&params, &deformed],
        );
        let draw_group = group(&draw.get_bind_group_layout(0), "draw", &[&params]);
        Self {
            n,
            rows,
            params,
            deformed,
            scanned,
            image,
            image_view,
            readback,
            deform,
            deform_group,
            draw,
            draw_group,
        }
    }

    /// The raw `VkBuffer` of `deformed`, for a host's own raw Vulkan commands.
    pub fn raw_deformed(&self) -> Result<ash::vk::Buffer, HostError> {
        // SAFETY: the guard borrows the buffer for this call; the handle is used only while the
        // scene (which owns the buffer) is alive, and never destroyed by the caller.
        unsafe {
            self.deformed
                .as_hal::<wgpu::hal::api::Vulkan>()
                .map(|b| b.raw_handle())
                .ok_or_else(|| HostError::Wgpu("the buffer is not on the Vulkan backend".into()))
        }
    }

    /// Vertices (and drawn pixels) per frame.
    pub fn len(&self) -> u32 {
        self.n
    }

    /// Never true: a scene has at least one vertex.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Queues the frame number for both passes (a wgpu staging write, submitted with the
    /// frame's `queue.submit`).
    pub fn set_frame(&self, queue: &wgpu::Queue, frame: u32) {
        let params = Params {
            n: self.n,
            frame,
            rows: self.rows,
            pad: 0,
        };
        queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
    }

    /// The deform compute pass, alone in its encoder.
    pub fn encode_deform(&self, device: &wgpu::Device) -> wgpu::CommandBuffer {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("deform"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("deform"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.deform);
            pass.set_bind_group(0, &self.deform_group, &[]);
            pass.dispatch_workgroups(self.n.div_ceil(WORKGROUP), 1, 1);
        }
        encoder.finish()
    }

    /// The draw render pass and the copy of its image to the readback buffer.
    pub fn encode_draw(&self, device: &wgpu::Device) -> wgpu::CommandBuffer {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("draw"),
        });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("draw"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.image_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.draw);
            pass.set_bind_group(0, &self.draw_group, &[]);
            pass.set_vertex_buffer(0, self.deformed.slice(..));
            pass.set_vertex_buffer(1, self.scanned.slice(..));
            pass.draw(0..self.n, 0..1);
        }
        encoder.copy_texture_to_buffer(
            self.image.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * WIDTH),
                    rows_per_image: None,
                },
            },
            self.image.size(),
        );
        encoder.finish()
    }

    /// Waits for the last submission and reads the first `n` pixels of the drawn image
    /// (row-major, so pixel `i` is vertex `i`'s value).
    pub fn read_result(&self, device: &wgpu::Device) -> Result<Vec<u32>, HostError> {
        let (tx, rx) = std::sync::mpsc::channel();
        self.readback
            .map_async(wgpu::MapMode::Read, .., move |r| drop(tx.send(r)));
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| HostError::Wgpu(format!("waiting for the frame: {e}")))?;
        rx.recv()
            .map_err(|_| HostError::Wgpu("the map callback never ran".into()))?
            .map_err(|e| HostError::Wgpu(format!("mapping the readback: {e}")))?;
        let out = {
            let view = self
                .readback
                .get_mapped_range(..)
                .map_err(|e| HostError::Wgpu(format!("reading the readback: {e}")))?;
            bytemuck::pod_collect_to_vec(&view[..4 * self.n as usize])
        };
        self.readback.unmap();
        Ok(out)
    }
}
