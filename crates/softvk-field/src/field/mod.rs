//! Implicit fields φ(p) = sigmoid(f(p)) in a bounding cube (SPEC §5), on the GPU, with their
//! f64 CPU twins and the tools around them.
//!
//! - [`Field`]: a field on the GPU that owns its parameter buffer; [`Field::record_eval`] maps
//!   points to φ and [`Field::record_backward`] maps dL/dφ per point to dL/dparams,
//!   deterministically (no float atomics, fixed-order sums), so Adam ([`crate::fit::Adam`]) can
//!   step [`Field::params`]. Three kinds ([`FieldKind`]):
//!   - **Grid** `{ res }`: `res³` logits at the lattice nodes of the cube (cell *corners*: node
//!     `i` at `c + h (2 i / (res − 1) − 1)` per axis, so the cube's corners are nodes), index
//!     `x + res (y + res z)`; trilinear interpolation; a point outside the cube takes the value
//!     of the nearest point of the cube (its grid coordinates are clamped). Initial logits 0
//!     (φ = 0.5; the seed is unused); [`Field::set_params`] sets any other start (a visual hull,
//!     say).
//!   - **Mlp** `{ hidden_layers, width, frequencies }`: NeRF positional encoding of the point
//!     normalised to the cube, softplus hidden layers, a linear output logit, seeded
//!     Kaiming-uniform init with φ ≈ 0.5 everywhere: see [`mlp`].
//!   - **Analytic** `{ shape, sharpness }`: `f = −sharpness · sd(p)` of a sphere, box or torus
//!     whose numbers are the parameters: see [`shape`]. For tests (φ = 0.5 exactly on a known
//!     surface) and for checking losses on a field of a handful of parameters.
//! - [`cpu`]: the f64 twin of every kernel (eval and backward), the oracle of the tests.
//! - [`mcubes`]: the mesh of φ = 0.5 by marching cubes on the GPU (and its twin), as a
//!   [`crate::mesh::Mesh`] ready for [`crate::io::write_obj`].
//! - [`voxel`] (CPU): occupancy grids of a closed mesh (voxelization), of a field (φ > 0.5 at
//!   voxel centres, evaluated on the GPU or by the twin), and of the visual hull of silhouettes
//!   and cameras; their 3D IoU.
//! - [`preview`]: a shaded PNG-ready image of φ = 0.5 by ray marching and bisection (rays and
//!   shading on the host, φ evaluated on the GPU in batches).
//!
//! **Buffers.** Points are `vec4` (xyz; w ignored), one per point; φ, dL/dφ are one `f32` per
//! point; parameters and their gradient `param_count` `f32`s. Ranges larger than needed are
//! fine; smaller ones are [`Error::Input`]. Any point count works: eval runs in dispatches of
//! [`EVAL_BATCH`] points, the backward in batches sized for the field's scratch (the sub-range
//! offsets are multiples of 4 KiB, so a caller's range offset only needs the device's alignment).
//!
//! **Determinism.** The backward's every sum has a fixed order (per chunk of 256 points
//! sequentially, then chunks in order, then batches in order; for the grid after a stable sort of
//! the points by cell, see `grid.rs`); repeated runs give bit-identical gradients.
//!
//! **Loop cap.** Every kernel's loops are bounded by constants except the MLP's, which grow with
//! the network: [`Field::new`] refuses with [`Error::Limit`] an MLP whose per-point loops pass the
//! device's [`shader_loop_limit`](crate::gpu::DeviceInfo::shader_loop_limit).
//!
//! A fit iteration records, into one command buffer:
//! ```text
//! points ─[Field::record_eval]→ φ ─(probing, losses)→ dL/dφ
//!   ─[Field::record_backward]→ dL/dparams ─[Adam::record_step on Field::params]→ params
//! ```

mod analytic;
pub mod cpu;
mod grid;
pub mod mcubes;
pub mod mlp;
pub mod preview;
pub mod shape;
pub mod voxel;

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

pub use mlp::MlpLayout;
pub use shape::Shape;

use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::specs;

/// Points per eval dispatch (16 MiB of points per binding).
pub const EVAL_BATCH: u32 = 1 << 20;
/// Points per chunk of the backward's fixed-order partial sums (`FIELD_CHUNK` in the kernels).
pub(crate) const FIELD_CHUNK: u32 = 256;
/// Largest grid resolution accepted (the device's binding limit may refuse less).
pub const MAX_GRID_RES: u32 = 1024;

/// The field's bounding cube: `center ± half` on every axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cube {
    /// Centre.
    pub center: [f64; 3],
    /// Half the edge length, > 0.
    pub half: f64,
}

impl Default for Cube {
    /// The cube `[−1, 1]³`.
    fn default() -> Self {
        Cube {
            center: [0.0; 3],
            half: 1.0,
        }
    }
}

impl Cube {
    /// A validated cube.
    pub fn new(center: [f64; 3], half: f64) -> Result<Cube> {
        let cube = Cube { center, half };
        cube.validate()?;
        Ok(cube)
    }

    /// [`Error::Input`] unless the centre is finite and `half` finite and > 0.
    pub fn validate(&self) -> Result<()> {
        if !(self.center.iter().all(|c| c.is_finite()) && self.half.is_finite() && self.half > 0.0)
        {
            return Err(Error::Input(format!(
                "field cube {self:?}: need a finite centre and a finite half-size > 0"
            )));
        }
        Ok(())
    }

    /// `(p − centre) / half`: the cube is `[−1, 1]³` after it.
    pub fn normalize(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| (p[k] - self.center[k]) / self.half)
    }

    /// The corner of least coordinates.
    pub fn min(&self) -> [f64; 3] {
        self.center.map(|c| c - self.half)
    }

    /// The corner of greatest coordinates.
    pub fn max(&self) -> [f64; 3] {
        self.center.map(|c| c + self.half)
    }

    /// `(centre, half)` as the kernels' `vec4 cube`.
    pub(crate) fn to_f32(self) -> [f32; 4] {
        [
            self.center[0] as f32,
            self.center[1] as f32,
            self.center[2] as f32,
            self.half as f32,
        ]
    }
}

/// What a field is made of (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FieldKind {
    /// A dense `res³` grid of logits, trilinear; `res ≥ 2`.
    Grid {
        /// Nodes per axis.
        res: u32,
    },
    /// An MLP with positional encoding ([`mlp`]).
    Mlp {
        /// Hidden layers, ≥ 1.
        hidden_layers: u32,
        /// Units per hidden layer, 1..=[`mlp::MAX_WIDTH`].
        width: u32,
        /// Encoding frequencies.
        frequencies: u32,
    },
    /// `f = −sharpness · sd(p)` of an analytic shape; the shape's numbers are the initial
    /// parameters ([`shape`]).
    Analytic {
        /// The shape.
        shape: Shape,
        /// Logit per unit of distance, > 0.
        sharpness: f64,
    },
}

impl FieldKind {
    /// [`Error::Input`] for a grid with `res < 2` or over [`MAX_GRID_RES`], an MLP out of
    /// [`MlpLayout::validate`]'s bounds, or an analytic shape with non-finite numbers or a
    /// sharpness that is not finite and > 0.
    pub fn validate(&self) -> Result<()> {
        match *self {
            FieldKind::Grid { res } => {
                if !(2..=MAX_GRID_RES).contains(&res) {
                    return Err(Error::Input(format!(
                        "grid field of resolution {res}: need 2..={MAX_GRID_RES}"
                    )));
                }
            }
            FieldKind::Mlp { .. } => self.mlp_layout().map_or(Ok(()), |l| l.validate())?,
            FieldKind::Analytic { shape, sharpness } => {
                if !(sharpness.is_finite()
                    && sharpness > 0.0
                    && shape.params().iter().all(|v| v.is_finite()))
                {
                    return Err(Error::Input(format!(
                        "analytic field {shape:?} with sharpness {sharpness}: need finite \
                         numbers and a sharpness > 0"
                    )));
                }
            }
        }
        Ok(())
    }

    /// The MLP's layout, for an MLP.
    pub fn mlp_layout(&self) -> Option<MlpLayout> {
        match *self {
            FieldKind::Mlp {
                hidden_layers,
                width,
                frequencies,
            } => Some(MlpLayout {
                hidden_layers,
                width,
                frequencies,
            }),
            _ => None,
        }
    }

    /// Number of parameters: `res³`, [`MlpLayout::param_count`], or the shape's.
    pub fn param_count(&self) -> usize {
        match *self {
            FieldKind::Grid { res } => (res as usize).pow(3),
            FieldKind::Mlp { .. } => self.mlp_layout().map_or(0, |l| l.param_count()),
            FieldKind::Analytic { shape, .. } => shape.param_count(),
        }
    }

    /// The initial parameters [`Field::new`] uploads: grid zeros, the MLP's seeded init, the
    /// shape's numbers.
    pub fn initial_params(&self, seed: u64) -> Vec<f32> {
        match *self {
            FieldKind::Grid { .. } => vec![0.0; self.param_count()],
            FieldKind::Mlp { .. } => self
                .mlp_layout()
                .map_or_else(Vec::new, |l| l.initial_params(seed)),
            FieldKind::Analytic { shape, .. } => shape.params().iter().map(|&v| v as f32).collect(),
        }
    }
}

/// The kernels of one kind.
enum Engine {
    Grid(Box<grid::GridGpu>),
    Mlp(Box<mlp::MlpGpu>),
    Shape(Box<analytic::ShapeGpu>),
}

/// A field on the GPU: its kernels, its parameters (owned) and its backward scratch.
pub struct Field {
    kind: FieldKind,
    cube: Cube,
    param_count: usize,
    params: Buffer,
    engine: Engine,
    sum: SumChunks,
}

impl Field {
    /// A field of `kind` in `cube` with [`FieldKind::initial_params`]`(seed)`.
    ///
    /// [`Error::Input`] for an invalid kind or cube; [`Error::Limit`] for a field the device
    /// cannot hold in one binding, or an MLP whose loops pass the device's loop cap.
    pub fn new(ctx: &Context, kind: FieldKind, cube: Cube, seed: u64) -> Result<Self> {
        kind.validate()?;
        cube.validate()?;
        let engine = match kind {
            FieldKind::Grid { res } => Engine::Grid(Box::new(grid::GridGpu::new(ctx, res)?)),
            FieldKind::Mlp { .. } => Engine::Mlp(Box::new(mlp::MlpGpu::new(
                ctx,
                kind.mlp_layout().expect("an MLP kind has a layout"),
            )?)),
            FieldKind::Analytic { shape, sharpness } => {
                Engine::Shape(Box::new(analytic::ShapeGpu::new(ctx, &shape, sharpness)?))
            }
        };
        let param_count = kind.param_count();
        let params = ctx.create_buffer(
            "field parameters",
            4 * param_count as u64,
            MemoryKind::Device,
        )?;
        ctx.write_buffer(&params, 0, &kind.initial_params(seed))?;
        Ok(Self {
            kind,
            cube,
            param_count,
            params,
            engine,
            sum: SumChunks::new(ctx)?,
        })
    }

    /// The field's kind.
    pub fn kind(&self) -> &FieldKind {
        &self.kind
    }

    /// The bounding cube.
    pub fn cube(&self) -> &Cube {
        &self.cube
    }

    /// Number of parameters.
    pub fn param_count(&self) -> usize {
        self.param_count
    }

    /// The parameters, `param_count` `f32`s (the buffer may be longer: alignment rounding).
    pub fn params(&self) -> &Buffer {
        &self.params
    }

    fn params_range(&self) -> BufferRange<'_> {
        self.params.range(0, 4 * (self.param_count as u64).max(1))
    }

    /// Uploads new parameters (and waits). [`Error::Input`] unless there are `param_count`, all
    /// finite.
    pub fn set_params(&self, ctx: &Context, params: &[f32]) -> Result<()> {
        if params.len() != self.param_count {
            return Err(Error::Input(format!(
                "field parameters: {} given, the field has {}",
                params.len(),
                self.param_count
            )));
        }
        if let Some(i) = params.iter().position(|v| !v.is_finite()) {
            return Err(Error::Input(format!(
                "field parameter {i} is {}, not finite",
                params[i]
            )));
        }
        ctx.write_buffer(&self.params, 0, params)
    }

    /// Reads the parameters back (and waits).
    pub fn read_params(&self, ctx: &Context) -> Result<Vec<f32>> {
        ctx.read_buffer(&self.params, 0, self.param_count)
    }

    /// Records φ of `count` points: `points` holds a `vec4` per point (xyz, w ignored), `phi`
    /// receives one `f32` per point.
    pub fn record_eval(
        &self,
        rec: &mut Recorder<'_>,
        points: BufferRange<'_>,
        count: u32,
        phi: BufferRange<'_>,
    ) -> Result<()> {
        let n = u64::from(count);
        check_range("field eval: points", &points, 16 * n)?;
        check_range("field eval: phi", &phi, 4 * n)?;
        let params = self.params_range();
        for (start, len) in batches(count, EVAL_BATCH) {
            let pts = points.sub(16 * start, 16 * u64::from(len));
            let out = phi.sub(4 * start, 4 * u64::from(len));
            match &self.engine {
                Engine::Grid(g) => g.record_eval(rec, &self.cube, params, pts, len, out)?,
                Engine::Mlp(m) => m.record_eval(rec, &self.cube, params, pts, len, out)?,
                Engine::Shape(s) => s.record_eval(rec, params, pts, len, out)?,
            }
        }
        Ok(())
    }

    /// Records dL/dparams (overwriting `param_count` floats of `d_params`) from dL/dφ of `count`
    /// points (`d_phi`, one `f32` per point). Deterministic: fixed-order sums, no float atomics.
    ///
    /// The field's backward scratch is reused by every call: several backward passes recorded
    /// into one command buffer are fine (each dispatch is followed by a barrier), but two command
    /// buffers holding backward passes of the same field must not run at the same time.
    pub fn record_backward(
        &self,
        rec: &mut Recorder<'_>,
        points: BufferRange<'_>,
        count: u32,
        d_phi: BufferRange<'_>,
        d_params: BufferRange<'_>,
    ) -> Result<()> {
        let n = u64::from(count);
        let p = self.param_count as u64;
        check_range("field backward: points", &points, 16 * n)?;
        check_range("field backward: d_phi", &d_phi, 4 * n)?;
        check_range("field backward: d_params", &d_params, 4 * p)?;
        let d_params = d_params.sub(0, 4 * p.max(1));
        if count == 0 {
            rec.fill(d_params, 0);
            return Ok(());
        }
        let params = self.params_range();
        let batch = match &self.engine {
            Engine::Grid(_) => grid::GRID_BATCH,
            Engine::Mlp(m) => m.batch(),
            Engine::Shape(_) => analytic::SHAPE_BATCH,
        };
        for (b, (start, len)) in batches(count, batch).enumerate() {
            let pts = points.sub(16 * start, 16 * u64::from(len));
            let dphi = d_phi.sub(4 * start, 4 * u64::from(len));
            let acc = b > 0;
            match &self.engine {
                Engine::Grid(g) => {
                    g.record_backward_batch(rec, &self.cube, params, pts, len, dphi, d_params, acc)?
                }
                Engine::Mlp(m) => m.record_backward_batch(
                    rec, &self.sum, &self.cube, params, pts, len, dphi, d_params, acc,
                )?,
                Engine::Shape(s) => {
                    s.record_backward_batch(rec, &self.sum, params, pts, len, dphi, d_params, acc)?
                }
            }
        }
        Ok(())
    }

    /// Convenience (tests, tools): uploads `points`, evaluates φ on the GPU and reads it back.
    pub fn eval(&self, ctx: &Context, points: &[[f32; 4]]) -> Result<Vec<f32>> {
        let count = point_count(points.len())?;
        if count == 0 {
            return Ok(Vec::new());
        }
        let pts = ctx.upload_buffer("field eval points", points)?;
        let phi = ctx.create_buffer("field eval phi", 4 * u64::from(count), MemoryKind::Device)?;
        ctx.submit_and_wait(|rec| self.record_eval(rec, pts.whole(), count, phi.whole()))?;
        ctx.read_buffer(&phi, 0, points.len())
    }

    /// Convenience (tests, tools): dL/dparams on the GPU from `points` and their dL/dφ.
    pub fn backward(&self, ctx: &Context, points: &[[f32; 4]], d_phi: &[f32]) -> Result<Vec<f32>> {
        if points.len() != d_phi.len() {
            return Err(Error::Input(format!(
                "field backward: {} points but {} values of dL/dphi",
                points.len(),
                d_phi.len()
            )));
        }
        let count = point_count(points.len())?;
        let pts = ctx.upload_buffer("field backward points", &pad_empty(points, [0.0; 4]))?;
        let dphi = ctx.upload_buffer("field backward d_phi", &pad_empty(d_phi, 0.0))?;
        let grad = ctx.create_buffer(
            "field backward d_params",
            4 * self.param_count as u64,
            MemoryKind::Device,
        )?;
        ctx.submit_and_wait(|rec| {
            self.record_backward(rec, pts.whole(), count, dphi.whole(), grad.whole())
        })?;
        ctx.read_buffer(&grad, 0, self.param_count)
    }
}

/// `data`, or one `fill` element when empty (a buffer needs a size).
fn pad_empty<T: Copy>(data: &[T], fill: T) -> Vec<T> {
    if data.is_empty() {
        vec![fill]
    } else {
        data.to_vec()
    }
}

/// A point count as the `u32` the kernels take.
pub(crate) fn point_count(n: usize) -> Result<u32> {
    u32::try_from(n).map_err(|_| Error::Limit(format!("{n} points: at most 2^32 − 1 at once")))
}

/// `(start, len)` of consecutive batches of at most `batch` items covering `count`.
fn batches(count: u32, batch: u32) -> impl Iterator<Item = (u64, u32)> {
    (0..count.div_ceil(batch)).map(move |b| {
        let start = b * batch;
        (u64::from(start), batch.min(count - start))
    })
}

/// [`Error::Input`] when `range` holds fewer than `bytes` bytes.
fn check_range(what: &str, range: &BufferRange<'_>, bytes: u64) -> Result<()> {
    if range.size < bytes {
        return Err(Error::Input(format!(
            "{what} (buffer `{}`): {} bytes, {bytes} needed",
            range.buffer.name(),
            range.size
        )));
    }
    Ok(())
}

/// [`Error::Limit`] when `bytes` do not fit one storage-buffer binding.
pub(crate) fn check_binding_bytes(ctx: &Context, what: &str, bytes: u64) -> Result<()> {
    let max = u64::from(ctx.info().limits.max_storage_buffer_range);
    if bytes > max {
        return Err(Error::Limit(format!(
            "{what} needs {bytes} bytes in one binding, over this device's \
             maxStorageBufferRange ({max})"
        )));
    }
    Ok(())
}

/// Workgroups of `size` invocations covering `n` items.
pub(crate) fn groups(n: u64, size: u32) -> Result<u32> {
    u32::try_from(n.div_ceil(u64::from(size)))
        .map_err(|_| Error::Limit(format!("{n} items need more than 2^32 workgroups")))
}

/// Push constants of `field_sum_chunks.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct SumPush {
    param_count: u32,
    chunks: u32,
    accumulate: u32,
    pad: u32,
}

/// `field_sum_chunks.comp`: the parameters' gradient from per-chunk partials, summed in chunk
/// order (a fixed order: deterministic). The fields' backward ends with it, and so does any
/// backward that writes a field's partials itself (the conditioned field of reconstruction).
pub struct SumChunks {
    kernel: Arc<Kernel>,
}

impl SumChunks {
    /// The kernel, from `ctx`'s pipeline cache.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            kernel: ctx.kernel(&specs::FIELD_SUM_CHUNKS, &[])?,
        })
    }

    /// `d_params[j] = (accumulate ? d_params[j] : 0) + Σ_{c < chunks} partial[c · P + j]`.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        partial: BufferRange<'_>,
        d_params: BufferRange<'_>,
        param_count: u32,
        chunks: u32,
        accumulate: bool,
    ) -> Result<()> {
        rec.dispatch(
            &self.kernel,
            &specs::FieldSumChunksBindings { partial, d_params }.for_kernel(&self.kernel)?,
            &SumPush {
                param_count,
                chunks,
                accumulate: u32::from(accumulate),
                pad: 0,
            },
            param_count.div_ceil(64),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_structs_match_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<SumPush>() as u32,
            specs::FIELD_SUM_CHUNKS.push_constant_size
        );
        let mlp = std::mem::size_of::<mlp::MlpPush>() as u32;
        assert_eq!(mlp, specs::FIELD_MLP_EVAL.push_constant_size);
        assert_eq!(mlp, specs::FIELD_MLP_FORWARD.push_constant_size);
        assert_eq!(
            std::mem::size_of::<mlp::DeltaPush>() as u32,
            specs::FIELD_MLP_DELTA.push_constant_size
        );
        assert_eq!(mlp, specs::FIELD_MLP_WGRAD.push_constant_size);
    }

    #[test]
    fn batches_cover_the_count_exactly() {
        let b: Vec<_> = batches(10, 4).collect();
        assert_eq!(b, vec![(0, 4), (4, 4), (8, 2)]);
        assert_eq!(batches(0, 4).count(), 0);
    }

    #[test]
    fn kinds_validate_and_count_parameters() {
        assert_eq!(FieldKind::Grid { res: 4 }.param_count(), 64);
        assert!(FieldKind::Grid { res: 1 }.validate().is_err());
        let mlp = FieldKind::Mlp {
            hidden_layers: 2,
            width: 8,
            frequencies: 1,
        };
        // E = 9: 8·9 + 8, then 8·8 + 8, then 8 + 1.
        assert_eq!(mlp.param_count(), 80 + 72 + 9);
        assert!(
            FieldKind::Mlp {
                hidden_layers: 0,
                width: 8,
                frequencies: 1
            }
            .validate()
            .is_err()
        );
        let sphere = FieldKind::Analytic {
            shape: Shape::Sphere {
                center: [0.0; 3],
                radius: 0.5,
            },
            sharpness: 0.0,
        };
        assert!(sphere.validate().is_err());
        assert!(Cube::new([0.0; 3], 0.0).is_err());
    }
}
