//! The gate of a guarded binning: lets a whole forward, backward and optimizer step (and many of
//! them) be recorded into one command buffer although the binning's entry count, which its
//! buffers must hold, is only known on the GPU.
//!
//! After the count, [`IterationGate::record_check`] records `iteration_gate.comp`: it compares
//! the count's total with the entry capacity and writes the indirect grids of every later
//! dispatch of the iteration, recorded inside [`IterationGate::record_gated`] (scatter, sort,
//! ranges, fine pass, and whatever the caller records after them: loss, backward, regularizers,
//! optimizer): their own grids when the entries fit, `[0, 0, 0]` when they do not — then none of
//! them runs, so nothing is written out of bounds and parameters stay as they were. The stop is
//! sticky: every later iteration of the submission is skipped too, and the first stop leaves its
//! iteration and total in a status buffer that the host reads after the submission
//! ([`IterationGate::read`]); it then grows the buffers to the total and re-runs from that
//! iteration, which gives exactly the result of a run that never stopped.
//!
//! The grids the check copies are known once the gated region is recorded: the gate writes them
//! then, through a host-visible mapping (no copy, no submission), so the command buffer can be
//! submitted by anyone. Every region recorded between two [`IterationGate::reset`]s must
//! record the same dispatches; they change only when the buffers are resized, which a host does
//! after waiting for its submissions (to read the status), so no submission in flight reads them
//! while they change.
//!
//! Only dispatches are gated; fills and copies recorded in a gated region always run and must be
//! harmless when the rest does not (the binning's sentinel fill of its keys is).

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::{
    Buffer, BufferRange, Context, INDIRECT_ARGS_BYTES, Kernel, MemoryKind, Recorder, specs,
};
use crate::error::{Error, Result};

/// Gated dispatches one iteration may record.
pub const GATE_SLOTS: u64 = 2048;

/// Push constants of `iteration_gate.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GatePush {
    iteration: u32,
    capacity: u32,
    words: u32,
    pad: u32,
}

/// What the gate's status says after a submission.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GateStatus {
    /// The first iteration that was stopped, with the entry total it counted, if any was.
    pub stopped: Option<(u32, u64)>,
    /// The entry total of the last iteration that ran (0 if none did).
    pub last_total: u64,
}

/// The gate's kernel and buffers: the status, the recorded grids (host-visible) and the grids
/// the gated dispatches read.
pub struct IterationGate {
    kernel: Arc<Kernel>,
    status: Buffer,
    grids: Buffer,
    args: Buffer,
    /// The grids last written to `grids`.
    uploaded: Vec<[u32; 3]>,
    /// Whether a gated region was recorded since the last [`IterationGate::reset`] (then
    /// the next must record the same dispatches).
    recorded: bool,
    /// [`IterationGate::reset`] was called and the next check clears the status.
    reset_pending: bool,
}

impl IterationGate {
    /// The gate, for up to [`GATE_SLOTS`] gated dispatches per iteration.
    pub fn new(ctx: &Context) -> Result<Self> {
        let bytes = GATE_SLOTS * INDIRECT_ARGS_BYTES;
        Ok(Self {
            kernel: ctx.kernel(&specs::ITERATION_GATE, &[])?,
            status: ctx.create_buffer("gate status", 16, MemoryKind::Device)?,
            grids: ctx.create_buffer("gate grids", bytes, MemoryKind::Upload)?,
            args: ctx.create_buffer("gate indirect args", bytes, MemoryKind::Device)?,
            uploaded: Vec::new(),
            recorded: false,
            reset_pending: false,
        })
    }

    /// Starts a submission's status: the next check clears it first (the fill is recorded
    /// right before that check, so that a host's command buffer meets softvk's first
    /// *dispatch*, not a fill, and the status is touched only where the gate runs).
    pub fn reset(&mut self) {
        self.reset_pending = true;
        self.recorded = false;
    }

    /// Records the check of iteration `iteration`: run the gated region that follows if `total`
    /// (the count's one `u32`) is at most `capacity` and no earlier iteration since the last
    /// reset was stopped.
    pub fn record_check(
        &mut self,
        rec: &mut Recorder<'_>,
        total: BufferRange<'_>,
        iteration: u32,
        capacity: u64,
    ) -> Result<()> {
        let capacity = u32::try_from(capacity)
            .map_err(|_| Error::Limit(format!("gate: capacity {capacity} over 2^32")))?;
        let push = GatePush {
            iteration,
            capacity,
            words: 3 * GATE_SLOTS as u32,
            pad: 0,
        };
        if std::mem::take(&mut self.reset_pending) {
            rec.fill(self.status.whole(), 0);
        }
        // Earlier gated dispatches have read their grids before the kernel rewrites them.
        rec.indirect_barrier();
        rec.pass("gate", |rec| {
            rec.dispatch(
                &self.kernel,
                &specs::IterationGateBindings {
                    total,
                    status: self.status.whole(),
                    grids: self.grids.whole(),
                    args: self.args.whole(),
                }
                .for_kernel(&self.kernel)?,
                &push,
                1,
            )
        })?;
        rec.indirect_barrier();
        Ok(())
    }

    /// Records `f` as the gated region of the check just recorded, and writes its grids for the
    /// check to copy. Every region between two resets must record the same dispatches
    /// ([`Error::Misuse`] otherwise).
    pub fn record_gated(
        &mut self,
        rec: &mut Recorder<'_>,
        f: impl FnOnce(&mut Recorder<'_>) -> Result<()>,
    ) -> Result<()> {
        let grids = rec.gated(self.args.whole(), f)?;
        if self.recorded && grids != self.uploaded {
            return Err(Error::Misuse(
                "gated regions between two gate resets recorded different dispatches".into(),
            ));
        }
        self.upload(&grids)?;
        self.recorded = true;
        Ok(())
    }

    /// Writes the grids of the gated regions through the mapping, if they changed. No
    /// submission in flight may read them (see the module docs).
    pub fn upload(&mut self, grids: &[[u32; 3]]) -> Result<()> {
        if grids == self.uploaded.as_slice() {
            return Ok(());
        }
        if grids.len() as u64 > GATE_SLOTS {
            return Err(Error::Misuse(format!(
                "{} gated dispatches, over the gate's {GATE_SLOTS}",
                grids.len()
            )));
        }
        let mut words = vec![0u32; 3 * GATE_SLOTS as usize];
        for (w, g) in words.chunks_exact_mut(3).zip(grids) {
            w.copy_from_slice(g);
        }
        let bytes: &[u8] = bytemuck::cast_slice(&words);
        self.grids
            .mapped_mut()
            .ok_or_else(|| Error::Limit("upload memory is not host-mapped".into()))?[..bytes.len()]
            .copy_from_slice(bytes);
        self.uploaded = grids.to_vec();
        Ok(())
    }

    /// Reads the status (after the submission finished).
    pub fn read(&self, ctx: &Context) -> Result<GateStatus> {
        let s: Vec<u32> = ctx.read_buffer(&self.status, 0, 4)?;
        Ok(GateStatus {
            stopped: (s[0] != 0).then_some((s[1], u64::from(s[2]))),
            last_total: u64::from(s[3]),
        })
    }

    /// The status buffer (`[stopped, iteration, total, last total]`) and the grids the gated
    /// dispatches read (3 words each), for tests.
    pub fn buffers(&self) -> (&Buffer, &Buffer) {
        (&self.status, &self.args)
    }
}

/// CPU twin.
pub mod cpu {
    /// One check: updates `status` (`[stopped, iteration, total, last total]`) and returns the
    /// grids the gated dispatches get.
    pub fn gate(
        status: &mut [u32; 4],
        total: u32,
        iteration: u32,
        capacity: u32,
        grids: &[[u32; 3]],
    ) -> Vec<[u32; 3]> {
        let stopped = status[0] != 0;
        let fits = total <= capacity;
        if !stopped && !fits {
            *status = [1, iteration, total, status[3]];
        }
        if !stopped && fits {
            status[3] = total;
        }
        let run = !stopped && fits;
        grids
            .iter()
            .map(|&g| if run { g } else { [0; 3] })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_layout_matches_the_kernel() {
        assert_eq!(
            std::mem::size_of::<GatePush>() as u32,
            specs::ITERATION_GATE.push_constant_size
        );
        assert_eq!(specs::ITERATION_GATE.bindings.len(), 4);
    }

    #[test]
    fn twin_stops_over_capacity_and_stays_stopped() {
        let grids = [[3, 1, 1], [7, 2, 1]];
        let mut s = [0; 4];
        assert_eq!(cpu::gate(&mut s, 10, 1, 10, &grids), grids.to_vec());
        assert_eq!(s, [0, 0, 0, 10]);
        assert_eq!(cpu::gate(&mut s, 11, 2, 10, &grids), vec![[0; 3]; 2]);
        assert_eq!(s, [1, 2, 11, 10]);
        // Sticky: a later iteration that would fit is skipped too, and the first stop stays.
        assert_eq!(cpu::gate(&mut s, 5, 3, 10, &grids), vec![[0; 3]; 2]);
        assert_eq!(s, [1, 2, 11, 10]);
    }
}
