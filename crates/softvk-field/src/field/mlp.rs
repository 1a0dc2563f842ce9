//! The MLP field's layout, initialization and loop bounds, and its GPU kernels
//! (`field_mlp_eval`; the backward's `field_mlp_forward`, `field_mlp_delta`, `field_mlp_wgrad`).
//!
//! **Architecture.** `u = (p − c) / h` (the point normalised to the cube), the NeRF encoding
//! `enc(u) = (u, sin(2^k π u), cos(2^k π u) for k < F)` — per k the three sines then the three
//! cosines — so `E = 3 + 6F` inputs; `L` hidden layers of `W` units with softplus, then one linear
//! output unit, the logit. Softplus rather than ReLU: the field and its gradients are smooth, so
//! the finite-difference normals of the geometric loss and the gradient checks see no kinks, while
//! β = [`SOFTPLUS_BETA`] = 100 (IGR's choice) keeps the capacity of a ReLU network:
//! `softplus_β(z) = log(1 + e^{βz}) / β`, computed as `max(z, 0) + log(1 + e^{−β|z|}) / β`.
//!
//! **Parameters**, layer by layer (the L hidden layers, then the output): the weights row-major
//! `[out][in]`, then the biases `[out]`. Count: `W E + W + (L − 1)(W² + W) + W + 1`.
//!
//! **Initialization** from a seed (SplitMix64, the same stream on every platform): hidden weights
//! Kaiming-uniform for ReLU-like units, `U(−√(6/fan_in), √(6/fan_in))`; the output weights the
//! same scaled by 0.01; every bias 0. The initial logit is then within about ±0.05 of 0: φ ≈ 0.5
//! everywhere, no shape prior (Adam, which normalizes each parameter's step, is not slowed by the
//! small output weights).
//!
//! **Loop bounds.** One invocation runs a whole point's forward pass (`field_mlp_eval`, and the
//! backward's `field_mlp_forward`), so its loop count grows as `L W²` (the backward's other
//! kernels work on tiles, with loops of at most `W` or a chunk of points): on llvmpipe
//! ([`crate::gpu::DeviceInfo::shader_loop_limit`]) [`Field::new`](super::Field::new) refuses with
//! [`Error::Limit`] a network whose per-point loops would pass the cap. 4 × 128 with 6
//! frequencies fits; 8 × 256 does not.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::{Cube, FIELD_CHUNK, SumChunks, check_binding_bytes};
use crate::error::{Error, LimitKind, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::rng::SplitMix64;
use crate::specs;

/// β of the hidden layers' softplus.
pub const SOFTPLUS_BETA: f64 = 100.0;
/// Widest hidden layer accepted.
pub const MAX_WIDTH: u32 = 256;
/// The evaluation kernel unrolls a network of at most this many weights and [`UNROLL_WIDTH`]
/// units per layer (3 × 32 with 3 frequencies has 2 752 weights): straight-line code that keeps
/// the activations in registers, 10–13× faster on llvmpipe (`benches/networks.rs`,
/// BENCHMARKS.md). Its compile time is what bounds it: 1–1.5 s for the width-32 networks up
/// to 4 × 32, but 15–21 s for 2 × 56 or 1 × 128 (whole runs of the `mlp_speed` example that
/// bench replaced, compile included), and minutes for 4 × 64.
pub const UNROLL_WEIGHTS: usize = 4096;
/// See [`UNROLL_WEIGHTS`].
pub const UNROLL_WIDTH: u32 = 32;
/// Most hidden layers accepted.
pub const MAX_LAYERS: u32 = 32;
/// Most encoding frequencies accepted (2^15 π already aliases at f32 precision).
pub const MAX_FREQUENCIES: u32 = 16;

/// The shape of an MLP field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MlpLayout {
    /// Hidden layers L ≥ 1.
    pub hidden_layers: u32,
    /// Units per hidden layer W, 1..=[`MAX_WIDTH`].
    pub width: u32,
    /// Encoding frequencies F (0 gives the raw normalised point only).
    pub frequencies: u32,
}

impl MlpLayout {
    /// The specialization constants of `field_mlp.glsl`: layers, width, frequencies, the half
    /// of the activation array (`max(inputs, width)`) and whether the loops unroll (asked for,
    /// and the network small enough: [`UNROLL_WIDTH`], [`UNROLL_WEIGHTS`]).
    pub(crate) fn constants(&self, unroll: bool) -> [u32; 5] {
        let weights = self.param_count() - self.biases();
        [
            self.hidden_layers,
            self.width,
            self.frequencies,
            (self.inputs() as u32).max(self.width),
            u32::from(unroll && self.width <= UNROLL_WIDTH && weights <= UNROLL_WEIGHTS),
        ]
    }

    /// Biases: one per hidden unit and the output's.
    fn biases(&self) -> usize {
        (self.hidden_layers * self.width) as usize + 1
    }

    /// [`Error::Input`] unless `1 ≤ L ≤ MAX_LAYERS`, `1 ≤ W ≤ MAX_WIDTH`, `F ≤ MAX_FREQUENCIES`.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_LAYERS).contains(&self.hidden_layers)
            || !(1..=MAX_WIDTH).contains(&self.width)
            || self.frequencies > MAX_FREQUENCIES
        {
            return Err(Error::Input(format!(
                "MLP field with {} hidden layers of width {} and {} frequencies: need 1..={MAX_LAYERS} \
                 layers, width 1..={MAX_WIDTH} and at most {MAX_FREQUENCIES} frequencies",
                self.hidden_layers, self.width, self.frequencies
            )));
        }
        Ok(())
    }

    /// Inputs of the first layer, `E = 3 + 6F`.
    pub fn inputs(&self) -> usize {
        3 + 6 * self.frequencies as usize
    }

    /// Layer `l` (0..=L, L the output): `(parameter offset, inputs, outputs)`.
    pub fn layer(&self, l: usize) -> (usize, usize, usize) {
        let (e, w, layers) = (
            self.inputs(),
            self.width as usize,
            self.hidden_layers as usize,
        );
        let offset = if l == 0 {
            0
        } else {
            w * e + w + (l - 1) * (w * w + w)
        };
        let inputs = if l == 0 { e } else { w };
        let outputs = if l == layers { 1 } else { w };
        (offset, inputs, outputs)
    }

    /// Number of parameters.
    pub fn param_count(&self) -> usize {
        let (offset, inputs, outputs) = self.layer(self.hidden_layers as usize);
        offset + outputs * inputs + outputs
    }

    /// The seeded initial parameters (see the module doc).
    pub fn initial_params(&self, seed: u64) -> Vec<f32> {
        let mut rng = SplitMix64(seed);
        let mut params = vec![0f32; self.param_count()];
        for l in 0..=self.hidden_layers as usize {
            let (offset, inputs, outputs) = self.layer(l);
            let mut bound = (6.0 / inputs as f64).sqrt();
            if l == self.hidden_layers as usize {
                bound *= 0.01;
            }
            for w in &mut params[offset..offset + inputs * outputs] {
                *w = (bound * (2.0 * rng.unit() - 1.0)) as f32;
            }
        }
        params
    }

    /// Loop iterations one invocation of `field_mlp_eval` runs, an upper bound mirroring the
    /// kernel's loops (the encoding, then per layer the rows and the 4-wide dot products).
    pub fn eval_iterations(&self) -> u64 {
        let dot = |n: u64| n / 4 + n % 4 + 2;
        let mut total = u64::from(self.frequencies) + 1;
        for l in 0..=self.hidden_layers as usize {
            let (_, inputs, outputs) = self.layer(l);
            total += 1 + outputs as u64 * (1 + dot(inputs as u64));
        }
        total
    }

    /// Tiles of `field_mlp_wgrad` per chunk of points: per layer, its `outputs × (inputs + 1)`
    /// parameters (the bias as a last column) in tiles of [`WGRAD_TILE`].
    fn wgrad_tiles(&self) -> u64 {
        let (rows, cols) = WGRAD_TILE;
        (0..=self.hidden_layers as usize)
            .map(|l| {
                let (_, inputs, outputs) = self.layer(l);
                (outputs.div_ceil(rows) * (inputs + 1).div_ceil(cols)) as u64
            })
            .sum()
    }

    /// Loop iterations of one invocation of `field_mlp_forward`: the forward with its stores.
    pub fn forward_iterations(&self) -> u64 {
        self.eval_iterations() + self.inputs() as u64 + 1
    }
}

/// Rows and columns of `field_mlp_wgrad`'s tiles (`WG_ROWS`, `WG_COLS` there).
const WGRAD_TILE: (usize, usize) = (8, 8);

/// Units and points of `field_mlp_delta`'s tiles (`DELTA_UNITS`, `DELTA_POINTS` there).
const DELTA_TILE: (u32, u32) = (8, 4);

/// Push constants of `field_mlp_delta.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct DeltaPush {
    n: u32,
    batch: u32,
    layer: u32,
    pad: u32,
}

/// Push constants shared by the other MLP kernels (`Push` in each).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct MlpPush {
    cube: [f32; 4],
    n: u32,
    layers: u32,
    width: u32,
    freqs: u32,
    beta: f32,
    batch: u32,
    chunks: u32,
    param_count: u32,
}

/// Bytes of per-point scratch the backward may hold at once (activations and deltas).
const SCRATCH_BUDGET: u64 = 32 << 20;

/// The MLP's kernels and backward scratch (sized for one batch of points).
pub(crate) struct MlpGpu {
    layout: MlpLayout,
    eval: Arc<Kernel>,
    forward: Arc<Kernel>,
    delta: Arc<Kernel>,
    wgrad: Arc<Kernel>,
    acts: Buffer,
    deltas: Buffer,
    partial: Buffer,
    /// Points per backward batch, a multiple of [`FIELD_CHUNK`].
    batch: u32,
}

impl MlpGpu {
    pub fn new(ctx: &Context, layout: MlpLayout) -> Result<Self> {
        let what = format!(
            "MLP field ({} × {}, {} frequencies)",
            layout.hidden_layers, layout.width, layout.frequencies
        );
        if let Some(limit) = ctx.info().shader_loop_limit() {
            let needed = layout.forward_iterations();
            if needed > limit {
                return Err(Error::DeviceLimit {
                    kind: LimitKind::LoopIterations,
                    what: format!("{what}: one point's forward pass"),
                    need: needed,
                    max: limit,
                    device: ctx.info().name.clone(),
                    hint: "use fewer or narrower layers",
                });
            }
        }
        let p = layout.param_count() as u64;
        check_binding_bytes(ctx, &what, 4 * p)?;
        let act_features =
            (layout.inputs() + (layout.hidden_layers * layout.width) as usize) as u64;
        let delta_features = u64::from(layout.hidden_layers * layout.width) + 1;
        let per_point = 4 * (act_features + delta_features);
        let chunk = u64::from(FIELD_CHUNK);
        let mut batch = (SCRATCH_BUDGET / per_point / chunk * chunk).clamp(chunk, 64 * chunk);
        // The chunk partials of a batch must fit one binding too.
        let max = u64::from(ctx.info().limits.max_storage_buffer_range);
        while batch > chunk && (batch / chunk) * p * 4 > max {
            batch -= chunk;
        }
        check_binding_bytes(ctx, &what, 4 * act_features * batch)?;
        check_binding_bytes(ctx, &what, (batch / chunk) * p * 4)?;
        Ok(Self {
            layout,
            eval: ctx.kernel(&specs::FIELD_MLP_EVAL, &layout.constants(true))?,
            forward: ctx.kernel(&specs::FIELD_MLP_FORWARD, &layout.constants(true))?,
            delta: ctx.kernel(&specs::FIELD_MLP_DELTA, &layout.constants(false))?,
            wgrad: ctx.kernel(&specs::FIELD_MLP_WGRAD, &[])?,
            acts: ctx.create_buffer(
                "mlp field activations",
                4 * act_features * batch,
                MemoryKind::Device,
            )?,
            deltas: ctx.create_buffer(
                "mlp field deltas",
                4 * delta_features * batch,
                MemoryKind::Device,
            )?,
            partial: ctx.create_buffer(
                "mlp field chunk partials",
                4 * (batch / chunk) * p,
                MemoryKind::Device,
            )?,
            batch: batch as u32,
        })
    }

    fn push(&self, cube: &Cube, n: u32, chunks: u32) -> MlpPush {
        MlpPush {
            cube: cube.to_f32(),
            n,
            layers: self.layout.hidden_layers,
            width: self.layout.width,
            freqs: self.layout.frequencies,
            beta: SOFTPLUS_BETA as f32,
            batch: self.batch,
            chunks,
            param_count: self.layout.param_count() as u32,
        }
    }

    pub fn batch(&self) -> u32 {
        self.batch
    }

    pub fn record_eval(
        &self,
        rec: &mut Recorder<'_>,
        cube: &Cube,
        params: BufferRange<'_>,
        points: BufferRange<'_>,
        n: u32,
        phi: BufferRange<'_>,
    ) -> Result<()> {
        rec.dispatch(
            &self.eval,
            &specs::FieldMlpEvalBindings {
                params,
                points,
                phi,
            }
            .for_kernel(&self.eval)?,
            &self.push(cube, n, 0),
            n.div_ceil(64),
        )
    }

    /// One batch of at most [`MlpGpu::batch`] points: d_params = (accumulate ? d_params : 0) +
    /// the batch's gradient. Four steps: the forward per point, saving every layer's input and
    /// softplus' (`field_mlp_forward`); the deltas down the layers, one dispatch per hidden
    /// layer over tiles of units × points (`field_mlp_delta`); each chunk's partial sums over
    /// tiles of parameters (`field_mlp_wgrad`); the partials summed in chunk order
    /// ([`SumChunks`]).
    #[allow(clippy::too_many_arguments)]
    pub fn record_backward_batch(
        &self,
        rec: &mut Recorder<'_>,
        sum: &SumChunks,
        cube: &Cube,
        params: BufferRange<'_>,
        points: BufferRange<'_>,
        n: u32,
        d_phi: BufferRange<'_>,
        d_params: BufferRange<'_>,
        accumulate: bool,
    ) -> Result<()> {
        let chunks = n.div_ceil(FIELD_CHUNK);
        let push = self.push(cube, n, chunks);
        rec.dispatch(
            &self.forward,
            &specs::FieldMlpForwardBindings {
                params,
                points,
                d_phi,
                acts: self.acts.whole(),
                deltas: self.deltas.whole(),
            }
            .for_kernel(&self.forward)?,
            &push,
            n.div_ceil(64),
        )?;
        let (units, points) = DELTA_TILE;
        let tiles = u64::from(n.div_ceil(points)) * u64::from(self.layout.width.div_ceil(units));
        for layer in (0..self.layout.hidden_layers).rev() {
            rec.dispatch(
                &self.delta,
                &specs::FieldMlpDeltaBindings {
                    params,
                    deltas: self.deltas.whole(),
                }
                .for_kernel(&self.delta)?,
                &DeltaPush {
                    n,
                    batch: self.batch,
                    layer,
                    pad: 0,
                },
                super::groups(tiles, 64)?,
            )?;
        }
        let p = self.layout.param_count() as u64;
        let partial = self.partial.range(0, 4 * p * u64::from(chunks));
        let invocations = self.layout.wgrad_tiles() * u64::from(chunks);
        rec.dispatch(
            &self.wgrad,
            &specs::FieldMlpWgradBindings {
                acts: self.acts.whole(),
                deltas: self.deltas.whole(),
                partial,
            }
            .for_kernel(&self.wgrad)?,
            &push,
            super::groups(invocations, 64)?,
        )?;
        sum.record(rec, partial, d_params, p as u32, chunks, accumulate)
    }
}
