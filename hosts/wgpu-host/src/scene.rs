//! The wgpu application's own buffers and passes: a WGSL compute pass "deform" before softvk
//! (it writes the vertex buffer softvk renders), a WGSL compute pass "consume" after it (it
//! reads softvk's silhouettes and gradients). Nothing here knows about softvk.

use std::borrow::Cow;

use bytemuck::{Pod, Zeroable};

use crate::HostError;

/// Workgroup size of both kernels.
const WORKGROUP: u32 = 64;

/// The uniform block of both WGSL modules.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Params {
    n: u32,
    frame: u32,
    pixels: u32,
    grads: u32,
}

/// The application's buffers and pipelines, all wgpu's.
pub struct Scene {
    n: u32,
    pixels: u32,
    params: wgpu::Buffer,
    /// Written by the deform pass (x y z 1 per vertex); softvk renders it.
    pub vertices: wgpu::Buffer,
    /// dL/d(image), RGBA per pixel (written at creation); softvk's backward reads it.
    pub upstream: wgpu::Buffer,
    /// softvk's silhouettes (RGBA per pixel), written by softvk; read by the consume pass.
    pub image: wgpu::Buffer,
    /// softvk's dL/d(vertex positions) (x y z per vertex); read by the consume pass.
    pub d_positions: wgpu::Buffer,
    consumed: wgpu::Buffer,
    readback: wgpu::Buffer,
    deform: wgpu::ComputePipeline,
    deform_group: wgpu::BindGroup,
    consume: wgpu::ComputePipeline,
    consume_group: wgpu::BindGroup,
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
    /// Buffers for the rest mesh `rest` and `upstream` (RGBA per pixel of every view), and the
    /// two pipelines.
    ///
    /// Every buffer is mapped at creation (with its data, or zeros) and unmapped at once: that
    /// marks it initialized in wgpu's lazy-initialization tracking. Without it, wgpu would zero
    /// `image` before its first read in the consume pass, after softvk wrote it (wgpu does not
    /// see softvk's write).
    pub fn new(
        device: &wgpu::Device,
        rest: &[[f32; 3]],
        upstream: &[[f32; 4]],
    ) -> Result<Self, HostError> {
        let n = rest.len() as u32;
        let pixels = upstream.len() as u32;
        let buffer = |label, data: &[u8], size: u64, usage| -> Result<wgpu::Buffer, HostError> {
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: true,
            });
            {
                let mut view = buffer
                    .slice(..)
                    .get_mapped_range_mut()
                    .map_err(|e| HostError::Wgpu(format!("writing {label} at creation: {e}")))?;
                view.slice(..data.len()).copy_from_slice(data);
            }
            buffer.unmap();
            Ok(buffer)
        };
        // softvk binds these as storage buffers, and copies into `image`.
        let shared = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let params = buffer(
            "params",
            &[],
            std::mem::size_of::<Params>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        let rest4: Vec<[f32; 4]> = rest.iter().map(|p| [p[0], p[1], p[2], 1.0]).collect();
        let rest = buffer(
            "rest",
            bytemuck::cast_slice(&rest4),
            16 * u64::from(n),
            wgpu::BufferUsages::STORAGE,
        )?;
        let vertices = buffer("vertices", &[], 16 * u64::from(n), shared)?;
        let upstream = buffer(
            "upstream",
            bytemuck::cast_slice(upstream),
            16 * u64::from(pixels),
            shared,
        )?;
        let image = buffer("image", &[], 16 * u64::from(pixels), shared)?;
        let d_positions = buffer("d_positions", &[], 12 * u64::from(n), shared)?;
        let consumed_bytes = 4 * (u64::from(pixels) + 3 * u64::from(n));
        let consumed = buffer("consumed", &[], consumed_bytes, shared)?;
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: consumed_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let pipeline = |label, source| {
            let module = shader(device, label, source);
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: None,
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let deform = pipeline("deform", include_str!("shaders/deform.wgsl"));
        let consume = pipeline("consume", include_str!("shaders/consume.wgsl"));
        let group = |pipeline: &wgpu::ComputePipeline, label, buffers: &[&wgpu::Buffer]| {
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
                layout: &pipeline.get_bind_group_layout(0),
                entries: &entries,
            })
        };
        // The rest mesh (x y z 1 per vertex) lives on in the bind group that reads it.
        let deform_group = group(&deform, "deform", &[&params, &rest, &vertices]);
        let consume_group = group(
            &consume,
            "consume",
            &[&params, &image, &d_positions, &consumed],
        );
        Ok(Self {
            n,
            pixels,
            params,
            vertices,
            upstream,
            image,
            d_positions,
            consumed,
            readback,
            deform,
            deform_group,
            consume,
            consume_group,
        })
    }

    /// The raw `VkBuffer` of `vertices`, for a host's own raw Vulkan commands.
    pub fn raw_vertices(&self) -> Result<ash::vk::Buffer, HostError> {
        // SAFETY: the guard borrows the buffer for this call; the handle is used only while the
        // scene (which owns the buffer) is alive, and never destroyed by the caller.
        unsafe { raw_buffer(&self.vertices) }
    }

    /// Vertices per frame.
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
            pixels: self.pixels,
            grads: 3 * self.n,
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

    /// The consume pass and the copy of what it wrote to the readback buffer.
    pub fn encode_consume(&self, device: &wgpu::Device) -> wgpu::CommandBuffer {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("consume"),
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("consume"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.consume);
            pass.set_bind_group(0, &self.consume_group, &[]);
            pass.dispatch_workgroups((self.pixels + 3 * self.n).div_ceil(WORKGROUP), 1, 1);
        }
        encoder.copy_buffer_to_buffer(&self.consumed, 0, &self.readback, 0, self.readback.size());
        encoder.finish()
    }

    /// Waits for the last submission and reads what the consume pass wrote: every pixel's
    /// alpha, then dL/d(positions), as softvk wrote them (undoubled).
    pub fn read_result(
        &self,
        device: &wgpu::Device,
    ) -> Result<(Vec<f32>, Vec<[f32; 3]>), HostError> {
        let (tx, rx) = std::sync::mpsc::channel();
        self.readback
            .map_async(wgpu::MapMode::Read, .., move |r| drop(tx.send(r)));
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| HostError::Wgpu(format!("waiting for the frame: {e}")))?;
        rx.recv()
            .map_err(|_| HostError::Wgpu("the map callback never ran".into()))?
            .map_err(|e| HostError::Wgpu(format!("mapping the readback: {e}")))?;
        let values: Vec<f32> = {
            let view = self
                .readback
                .get_mapped_range(..)
                .map_err(|e| HostError::Wgpu(format!("reading the readback: {e}")))?;
            bytemuck::pod_collect_to_vec(&view[..])
        };
        self.readback.unmap();
        let (alpha, grads) = values.split_at(self.pixels as usize);
        Ok((
            alpha.iter().map(|a| a / 2.0).collect(),
            grads
                .chunks_exact(3)
                .map(|g| [g[0] / 2.0, g[1] / 2.0, g[2] / 2.0])
                .collect(),
        ))
    }
}

/// The raw `VkBuffer` behind a wgpu buffer.
///
/// # Safety
/// The handle is used only while `buffer` is alive, and never destroyed by the caller.
pub unsafe fn raw_buffer(buffer: &wgpu::Buffer) -> Result<ash::vk::Buffer, HostError> {
    // SAFETY: the guard borrows the buffer for this call; the caller keeps it alive for as long
    // as it uses the handle.
    unsafe {
        buffer
            .as_hal::<wgpu::hal::api::Vulkan>()
            .map(|b| b.raw_handle())
            .ok_or_else(|| HostError::Wgpu("the buffer is not on the Vulkan backend".into()))
    }
}
