//! Recording. The library's main path only records into a command buffer the caller owns
//! ([`Recorder::new`]); [`Context::submit_and_wait`] is the headless convenience that allocates,
//! submits and waits for one.

use std::sync::Arc;

use ash::vk;

use super::context::Context;
use super::kernel::{BindingKind, Kernel};
use super::memory::{Buffer, BufferRange};
use super::shared::Shared;
use super::texel_views::TEXEL_BYTES;
use crate::error::{Error, Result, VkContext};

/// Records softvk work into a command buffer in the recording state.
///
/// Every dispatch and copy is followed by a compute/transfer memory barrier, so the next one sees
/// its writes. Work the host recorded *before* handing the command buffer over, and work it
/// records after, must be synchronized by the host (a barrier from/to `COMPUTE_SHADER`).
pub struct Recorder<'a> {
    ctx: &'a Context,
    cmd: vk::CommandBuffer,
    timer: Option<&'a mut Timer>,
    gate: Option<Gate>,
    /// How many [`Recorder::pass`]es are open around what is recorded now.
    depth: u32,
}

/// The indirect-argument slots of an open [`Recorder::gated`] region.
struct Gate {
    buffer: vk::Buffer,
    offset: u64,
    slots: u64,
    groups: Vec<[u32; 3]>,
}

/// Bytes of one indirect dispatch's arguments (`VkDispatchIndirectCommand`: x, y, z).
pub const INDIRECT_ARGS_BYTES: u64 = 12;

impl<'a> Recorder<'a> {
    /// Wraps a command buffer the caller allocated from a pool of `ctx`'s compute queue family
    /// and began.
    ///
    /// # Safety
    /// `cmd` is a valid command buffer of `ctx`'s device, in the recording state, not recorded
    /// into from another thread while this recorder lives, and submitted to a queue of a family
    /// with compute support.
    pub unsafe fn new(ctx: &'a Context, cmd: vk::CommandBuffer) -> Self {
        Self {
            ctx,
            cmd,
            timer: None,
            gate: None,
            depth: 0,
        }
    }

    /// Attaches a timer: its queries are reset here and [`Recorder::pass`] writes timestamps.
    pub fn with_timer(mut self, timer: &'a mut Timer) -> Self {
        // SAFETY: the pool belongs to this device; resetting inside a command buffer is allowed
        // outside render passes.
        unsafe {
            self.ctx
                .device()
                .cmd_reset_query_pool(self.cmd, timer.pool, 0, timer.capacity)
        };
        timer.labels.clear();
        self.timer = Some(timer);
        self
    }

    /// The context recorded for.
    pub fn context(&self) -> &'a Context {
        self.ctx
    }

    /// The raw command buffer.
    pub fn command_buffer(&self) -> vk::CommandBuffer {
        self.cmd
    }

    /// Records `f` as a named pass, bracketed by GPU timestamps when a timer is attached. A pass
    /// opened inside another is nested in it ([`PassTime::depth`]): its time is part of its
    /// parent's.
    pub fn pass<R>(&mut self, name: &str, f: impl FnOnce(&mut Self) -> Result<R>) -> Result<R> {
        let first = self.timestamp(name)?;
        self.depth += 1;
        let result = f(self);
        self.depth -= 1;
        let result = result?;
        if let Some(index) = first {
            self.write_timestamp(index + 1);
        }
        Ok(result)
    }

    fn timestamp(&mut self, name: &str) -> Result<Option<u32>> {
        let depth = self.depth;
        let Some(timer) = self.timer.as_deref_mut() else {
            return Ok(None);
        };
        let index = 2 * timer.labels.len() as u32;
        if index + 2 > timer.capacity {
            return Err(Error::Limit(format!(
                "timer holds {} passes; pass `{name}` is one too many",
                timer.capacity / 2
            )));
        }
        timer.labels.push((name.to_string(), depth));
        self.write_timestamp(index);
        Ok(Some(index))
    }

    fn write_timestamp(&mut self, index: u32) {
        if let Some(timer) = self.timer.as_deref() {
            // SAFETY: index < capacity (checked when the pass was opened); pool reset above.
            unsafe {
                self.ctx.device().cmd_write_timestamp(
                    self.cmd,
                    vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                    timer.pool,
                    index,
                )
            };
        }
    }

    /// Records `f` with every dispatch in it made indirect: the `i`-th dispatch (with a nonzero
    /// group count) reads its grid `[x, y, z]` from `args` at byte `12 i`, and the grids it was
    /// recorded with are returned, in order. Whatever writes `args` before they run decides
    /// whether each runs: its own grid, or `[0, 0, 0]` for nothing. That is how a fitting
    /// iteration turns every later stage into a no-op on the GPU when a capacity is exceeded
    /// (`fit::mesh_fit`), without any kernel knowing. Only dispatches are gated: fills and copies
    /// recorded in `f` always run. The writer must be followed by [`Recorder::indirect_barrier`].
    pub fn gated(
        &mut self,
        args: BufferRange<'_>,
        f: impl FnOnce(&mut Self) -> Result<()>,
    ) -> Result<Vec<[u32; 3]>> {
        if self.gate.is_some() {
            return Err(Error::Limit("gated regions do not nest".into()));
        }
        if args.offset % 4 != 0 || args.offset + args.size > args.buffer.size() {
            return Err(Error::Limit(format!(
                "gate arguments {}+{} do not fit buffer `{}`",
                args.offset,
                args.size,
                args.buffer.name()
            )));
        }
        self.gate = Some(Gate {
            buffer: args.buffer.raw,
            offset: args.offset,
            slots: args.size / INDIRECT_ARGS_BYTES,
            groups: Vec::new(),
        });
        let result = f(self);
        let gate = self.gate.take().expect("set above");
        result.map(|()| gate.groups)
    }

    /// Makes shader and transfer writes visible to later indirect-argument reads, and orders
    /// earlier indirect-argument reads before later writes (around a kernel that writes the
    /// arguments of [`Recorder::gated`] dispatches).
    pub fn indirect_barrier(&mut self) {
        let stages = vk::PipelineStageFlags::COMPUTE_SHADER
            | vk::PipelineStageFlags::TRANSFER
            | vk::PipelineStageFlags::DRAW_INDIRECT;
        let barrier = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(
                vk::AccessFlags::INDIRECT_COMMAND_READ
                    | vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::TRANSFER_READ
                    | vk::AccessFlags::TRANSFER_WRITE,
            )];
        // SAFETY: recording command buffer.
        unsafe {
            self.ctx.device().cmd_pipeline_barrier(
                self.cmd,
                stages,
                stages,
                vk::DependencyFlags::empty(),
                &barrier,
                &[],
                &[],
            )
        };
    }

    /// Records one dispatch of `kernel` over `groups` workgroups, with `bindings` in binding order
    /// and `push` as its push constants. Group counts above the device's X limit are folded into a
    /// 2D grid; kernels address their work with `linear_group_id()` and ignore the surplus. Inside
    /// [`Recorder::gated`], the grid is read from the gate's arguments instead.
    pub fn dispatch<P: bytemuck::Pod>(
        &mut self,
        kernel: &Kernel,
        bindings: &[BufferRange<'_>],
        push: &P,
        groups: u32,
    ) -> Result<()> {
        let spec = kernel.spec;
        let fail = |message: String| Error::Kernel {
            kernel: spec.name,
            message,
        };
        if bindings.len() != spec.bindings.len() {
            return Err(fail(format!(
                "expects {} buffer bindings, got {}",
                spec.bindings.len(),
                bindings.len()
            )));
        }
        let push_bytes = bytemuck::bytes_of(push);
        if push_bytes.len() != spec.push_constant_size as usize {
            return Err(fail(format!(
                "expects {} bytes of push constants, got {}",
                spec.push_constant_size,
                push_bytes.len()
            )));
        }
        let limits = &self.ctx.info().limits;
        for (range, b) in bindings.iter().zip(spec.bindings) {
            let what = format!(
                "binding {} `{}` (buffer `{}`)",
                b.binding,
                b.name,
                range.buffer.name()
            );
            if range.size == 0 || range.offset + range.size > range.buffer.size() {
                return Err(fail(format!(
                    "{what}: range {}+{} outside the buffer's {} bytes",
                    range.offset,
                    range.size,
                    range.buffer.size()
                )));
            }
            match b.kind {
                BindingKind::Storage => {
                    if range.offset % limits.min_storage_buffer_offset_alignment != 0 {
                        return Err(fail(format!(
                            "{what}: offset {} is misaligned",
                            range.offset
                        )));
                    }
                    if range.size > u64::from(limits.max_storage_buffer_range) {
                        return Err(fail(format!(
                            "{what}: {} bytes exceed maxStorageBufferRange ({})",
                            range.size, limits.max_storage_buffer_range
                        )));
                    }
                }
                BindingKind::Texels => {
                    if range.offset % limits.min_texel_buffer_offset_alignment != 0
                        || range.size % TEXEL_BYTES != 0
                    {
                        return Err(fail(format!(
                            "{what}: range {}+{} is not whole {TEXEL_BYTES}-byte texels at an \
                             offset aligned to {}",
                            range.offset, range.size, limits.min_texel_buffer_offset_alignment
                        )));
                    }
                    if range.size / TEXEL_BYTES > u64::from(limits.max_texel_buffer_elements) {
                        return Err(fail(format!(
                            "{what}: {} texels exceed maxTexelBufferElements ({})",
                            range.size / TEXEL_BYTES,
                            limits.max_texel_buffer_elements
                        )));
                    }
                }
            }
        }
        if groups == 0 {
            return Ok(());
        }
        let max_x = limits.max_compute_work_group_count[0];
        let x = groups.min(max_x);
        let y = groups.div_ceil(x);
        if y > limits.max_compute_work_group_count[1] {
            return Err(fail(format!(
                "{groups} workgroups exceed the device's grid"
            )));
        }
        let indirect = match self.gate.as_mut() {
            None => None,
            Some(gate) => {
                let slot = gate.groups.len() as u64;
                if slot >= gate.slots {
                    return Err(fail(format!(
                        "the gated region holds {} dispatches; this is one more",
                        gate.slots
                    )));
                }
                gate.groups.push([x, y, 1]);
                Some((gate.buffer, gate.offset + INDIRECT_ARGS_BYTES * slot))
            }
        };

        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = bindings
            .iter()
            .map(|r| {
                [vk::DescriptorBufferInfo {
                    buffer: r.buffer.raw,
                    offset: r.offset,
                    range: r.size,
                }]
            })
            .collect();
        let views = bindings
            .iter()
            .zip(spec.bindings)
            .map(|(r, b)| match b.kind {
                BindingKind::Storage => Ok([vk::BufferView::null()]),
                BindingKind::Texels => self
                    .ctx
                    .shared
                    .texel_views
                    .view(self.ctx.device(), r.buffer.raw, r.offset, r.size)
                    .map(|v| [v]),
            })
            .collect::<Result<Vec<_>>>()?;
        let writes: Vec<_> = spec
            .bindings
            .iter()
            .zip(infos.iter().zip(&views))
            .map(|(b, (info, view))| {
                let write = vk::WriteDescriptorSet::default()
                    .dst_binding(b.binding)
                    .descriptor_type(b.kind.descriptor_type());
                match b.kind {
                    BindingKind::Storage => write.buffer_info(info),
                    BindingKind::Texels => write.texel_buffer_view(view),
                }
            })
            .collect();
        // Without push descriptors: the context's cached set of these writes (made now if these
        // ranges were never bound to this kernel), which outlives whatever the host does with
        // `cmd`.
        let set = match self.ctx.push_descriptor {
            Some(_) => vk::DescriptorSet::null(),
            None => self.ctx.shared.descriptor_set(
                kernel.set_layout,
                bindings
                    .iter()
                    .map(|r| (r.buffer.raw, r.offset, r.size))
                    .collect(),
                &writes,
            )?,
        };
        let device = self.ctx.device();
        // SAFETY: the command buffer is recording (constructor contract); pipeline, layout and
        // buffers belong to this device; bindings and push size were checked against the
        // kernel's reflected interface above.
        unsafe {
            device.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, kernel.pipeline);
            match &self.ctx.push_descriptor {
                Some(push) => push.cmd_push_descriptor_set(
                    self.cmd,
                    vk::PipelineBindPoint::COMPUTE,
                    kernel.layout,
                    0,
                    &writes,
                ),
                // The set was written for this kernel's layout and stays alive, unchanged, until
                // a buffer it names or the kernel is dropped, which needs `cmd` done with.
                None => device.cmd_bind_descriptor_sets(
                    self.cmd,
                    vk::PipelineBindPoint::COMPUTE,
                    kernel.layout,
                    0,
                    &[set],
                    &[],
                ),
            }
            if !push_bytes.is_empty() {
                device.cmd_push_constants(
                    self.cmd,
                    kernel.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    push_bytes,
                );
            }
            match indirect {
                // The buffer has INDIRECT_BUFFER usage (every buffer has) and the slot lies
                // inside the range `gated` checked.
                Some((buffer, offset)) => device.cmd_dispatch_indirect(self.cmd, buffer, offset),
                None => device.cmd_dispatch(self.cmd, x, y, 1),
            }
        }
        self.barrier();
        Ok(())
    }

    /// Copies `size` bytes between buffers.
    pub fn copy(
        &mut self,
        src: &Buffer,
        src_offset: u64,
        dst: &Buffer,
        dst_offset: u64,
        size: u64,
    ) {
        if size == 0 {
            return;
        }
        let region = [vk::BufferCopy {
            src_offset,
            dst_offset,
            size,
        }];
        // SAFETY: recording command buffer; both buffers have TRANSFER usage.
        unsafe {
            self.ctx
                .device()
                .cmd_copy_buffer(self.cmd, src.raw, dst.raw, &region)
        };
        self.barrier();
    }

    /// Fills `range` (offset and size multiples of 4) with the 32-bit word `value`.
    pub fn fill(&mut self, range: BufferRange<'_>, value: u32) {
        // SAFETY: recording command buffer; TRANSFER_DST usage; alignment is the caller's.
        unsafe {
            self.ctx.device().cmd_fill_buffer(
                self.cmd,
                range.buffer.raw,
                range.offset,
                range.size,
                value,
            )
        };
        self.barrier();
    }

    /// Makes every compute and transfer write so far visible to later compute and transfer work.
    pub fn barrier(&mut self) {
        let stages = vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER;
        let barrier = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(
                vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::TRANSFER_READ
                    | vk::AccessFlags::TRANSFER_WRITE,
            )];
        // SAFETY: recording command buffer.
        unsafe {
            self.ctx.device().cmd_pipeline_barrier(
                self.cmd,
                stages,
                stages,
                vk::DependencyFlags::empty(),
                &barrier,
                &[],
                &[],
            )
        };
    }

    /// For a host engine that hands softvk its command buffer between its own passes (and
    /// records no barrier of its own for softvk's buffers, as wgpu cannot): makes every write
    /// recorded before this point available to everything after it, and orders all earlier
    /// commands before all later ones. Record one before softvk's first dispatch (the host's
    /// writes become visible to softvk) and one after its last (softvk's writes become visible
    /// to the host's next pass).
    pub fn full_barrier(&mut self) {
        let barrier = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
            .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE)];
        // SAFETY: recording command buffer.
        unsafe {
            self.ctx.device().cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::PipelineStageFlags::ALL_COMMANDS,
                vk::DependencyFlags::empty(),
                &barrier,
                &[],
                &[],
            )
        };
    }

    fn host_barrier(&mut self) {
        let barrier = [vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)];
        // SAFETY: recording command buffer.
        unsafe {
            self.ctx.device().cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &barrier,
                &[],
                &[],
            )
        };
    }
}

/// GPU timestamps around named passes.
pub struct Timer {
    pool: vk::QueryPool,
    capacity: u32,
    /// Each pass's name and depth, in recording order.
    labels: Vec<(String, u32)>,
    shared: Arc<Shared>,
}

/// GPU time of one pass.
#[derive(Clone, Debug, PartialEq)]
pub struct PassTime {
    /// The name given to [`Recorder::pass`].
    pub name: String,
    /// How many passes enclose it: 0 for a top-level pass, 1 for a part of one, and so on.
    pub depth: u32,
    /// Milliseconds between the pass's two timestamps.
    pub ms: f64,
}

impl PassTime {
    /// The time of `times`' top-level passes, summed (a nested pass's time is already part of
    /// its parent's), ms.
    pub fn top_level_ms(times: &[PassTime]) -> f64 {
        times.iter().filter(|t| t.depth == 0).map(|t| t.ms).sum()
    }

    /// The name indented by two spaces per level of [`PassTime::depth`], for listing passes
    /// after their parents.
    pub fn indented(&self) -> String {
        format!("{}{}", "  ".repeat(self.depth as usize), self.name)
    }
}

impl Timer {
    /// A timer for up to `passes` passes per recording.
    pub fn new(ctx: &Context, passes: u32) -> Result<Self> {
        if ctx.info().timestamp_valid_bits == 0 {
            return Err(Error::Limit(format!(
                "{} has no timestamps on its compute queue",
                ctx.info().name
            )));
        }
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(2 * passes.max(1));
        // SAFETY: valid device.
        let pool =
            unsafe { ctx.device().create_query_pool(&info, None) }.vk("vkCreateQueryPool")?;
        ctx.name(pool, "softvk timer");
        Ok(Self {
            pool,
            capacity: 2 * passes.max(1),
            labels: Vec::new(),
            shared: Arc::clone(&ctx.shared),
        })
    }

    /// The GPU time of the last completed recording's top-level passes, summed (a nested
    /// pass's time is already part of its parent's), ms.
    pub fn total_ms(&self, ctx: &Context) -> Result<f64> {
        Ok(PassTime::top_level_ms(&self.results(ctx)?))
    }

    /// The pass times of the last completed recording, in recording order.
    pub fn results(&self, ctx: &Context) -> Result<Vec<PassTime>> {
        if self.labels.is_empty() {
            return Ok(Vec::new());
        }
        let mut raw = vec![0u64; 2 * self.labels.len()];
        // SAFETY: the queries were written by a command buffer the caller has waited for.
        unsafe {
            ctx.device().get_query_pool_results(
                self.pool,
                0,
                &mut raw,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .vk("vkGetQueryPoolResults")?;
        let bits = ctx.info().timestamp_valid_bits;
        let mask = if bits >= 64 {
            u64::MAX
        } else {
            (1u64 << bits) - 1
        };
        let period = f64::from(ctx.info().timestamp_period_ns);
        Ok(self
            .labels
            .iter()
            .zip(raw.chunks_exact(2))
            .map(|((name, depth), t)| PassTime {
                name: name.clone(),
                depth: *depth,
                ms: ((t[1].wrapping_sub(t[0])) & mask) as f64 * period * 1e-6,
            })
            .collect())
    }
}

impl Drop for Timer {
    fn drop(&mut self) {
        // SAFETY: created on this device; no pending command buffer uses it (callers wait).
        unsafe { self.shared.device.destroy_query_pool(self.pool, None) };
    }
}

/// A command buffer recorded once and submittable many times (benchmarks, fixed pipelines).
/// Owns the command buffer and a fence; frees both on drop.
pub struct Recorded<'a> {
    ctx: &'a Context,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
}

impl Recorded<'_> {
    /// Submits the recording to the context's queue and waits for it to finish.
    pub fn submit_and_wait(&self) -> Result<()> {
        let device = self.ctx.device();
        let cmds = [self.cmd];
        let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
        // Queue access must be externally synchronized; the pool lock covers it.
        let _guard = self.ctx.pool_lock.lock();
        self.ctx
            .counters
            .submissions
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        // SAFETY: the fence is unsignaled (reset after every wait), the command buffer is
        // executable and not pending (we waited for the previous submit).
        unsafe {
            device
                .queue_submit(self.ctx.queue, &submit, self.fence)
                .vk("vkQueueSubmit")?;
            let waited = device
                .wait_for_fences(&[self.fence], true, u64::MAX)
                .vk("vkWaitForFences");
            device.reset_fences(&[self.fence]).vk("vkResetFences")?;
            waited
        }
    }
}

impl Drop for Recorded<'_> {
    fn drop(&mut self) {
        let _guard = self.ctx.pool_lock.lock();
        // SAFETY: every submit waited for its fence, so the command buffer is not pending.
        unsafe {
            self.ctx.device().destroy_fence(self.fence, None);
            self.ctx
                .device()
                .free_command_buffers(self.ctx.command_pool, &[self.cmd]);
        }
    }
}

impl Context {
    /// Records `f` into a fresh command buffer, submits it to the context's queue and waits.
    pub fn submit_and_wait(&self, f: impl FnOnce(&mut Recorder<'_>) -> Result<()>) -> Result<()> {
        self.record(None, f)?.submit_and_wait()
    }

    /// As [`Context::submit_and_wait`], with GPU timestamps into `timer`.
    pub fn submit_and_wait_timed(
        &self,
        timer: Option<&mut Timer>,
        f: impl FnOnce(&mut Recorder<'_>) -> Result<()>,
    ) -> Result<()> {
        self.record(timer, f)?.submit_and_wait()
    }

    /// Records `f` once into a command buffer of the context's pool (with timestamps into
    /// `timer`, re-reset on every submit), for [`Recorded::submit_and_wait`].
    ///
    /// `f` must only record: submitting through this context from inside it would deadlock on
    /// the pool lock.
    pub fn record<'a>(
        &'a self,
        timer: Option<&mut Timer>,
        f: impl FnOnce(&mut Recorder<'_>) -> Result<()>,
    ) -> Result<Recorded<'a>> {
        let info = vk::CommandBufferAllocateInfo::default()
            .command_pool(self.command_pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        let cmd = {
            let _guard = self.pool_lock.lock();
            // SAFETY: the pool is ours and externally synchronized by `pool_lock`.
            unsafe { self.device().allocate_command_buffers(&info) }
                .vk("vkAllocateCommandBuffers")?[0]
        };
        // SAFETY: valid device.
        let fence = match unsafe {
            self.device()
                .create_fence(&vk::FenceCreateInfo::default(), None)
        } {
            Ok(fence) => fence,
            Err(result) => {
                let _guard = self.pool_lock.lock();
                // SAFETY: never begun nor submitted.
                unsafe {
                    self.device()
                        .free_command_buffers(self.command_pool, &[cmd])
                };
                return Err(Error::Vulkan {
                    call: "vkCreateFence",
                    result,
                });
            }
        };
        // From here on, `Recorded`'s drop frees the command buffer and fence on any error.
        let recorded = Recorded {
            ctx: self,
            cmd,
            fence,
        };
        // Recording into a command buffer needs its pool externally synchronized too.
        let _guard = self.pool_lock.lock();
        // SAFETY: freshly allocated command buffer of our pool, which `pool_lock` guards.
        unsafe {
            self.device()
                .begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default())
                .vk("vkBeginCommandBuffer")?;
            let mut rec = Recorder::new(self, cmd);
            if let Some(timer) = timer {
                rec = rec.with_timer(timer);
            }
            f(&mut rec)?;
            rec.host_barrier();
            self.device()
                .end_command_buffer(cmd)
                .vk("vkEndCommandBuffer")?;
        }
        Ok(recorded)
    }
}
