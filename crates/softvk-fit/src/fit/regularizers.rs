//! The mesh regularizers of SoftRas's deformation demo on the GPU: [`super::laplacian`] and
//! [`super::flatten`], for one fixed topology.

use std::sync::Arc;

use super::flatten::{EdgesPush, FlattenEdges};
use super::laplacian::{Adjacency, ApplyPush, WeightedPush};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, BufferRange, Context, Kernel, MemoryKind, Recorder};
use crate::gpu::{GradOut, check_binding, check_floats, groups};
use crate::primitives::sum::{Sum, SumPush};
use crate::specs;

/// The regularizers' last values, as read back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RegularizerLosses {
    /// `Σ_i |(L x)_i|²`.
    pub laplacian: f32,
    /// `Σ_edges (cos + 1)²`.
    pub flatten: f32,
}

/// SoftRas's `LaplacianLoss` and `FlattenLoss` for one topology: the CSR tables (built on the
/// host once, from the faces), the kernels and their scratch.
///
/// Loss values land in [`Self::values_buffer`]: float [`Self::LAPLACIAN`] and float
/// [`Self::FLATTEN`].
pub struct Regularizers {
    apply: Arc<Kernel>,
    lap_grad: Arc<Kernel>,
    edges_kernel: Arc<Kernel>,
    gather: Arc<Kernel>,
    sum: Sum,
    vertex_count: u32,
    edge_count: u32,
    adjacency: Adjacency,
    edges: FlattenEdges,
    lap_offsets: Buffer,
    lap_neighbours: Buffer,
    /// (y_i, |y_i|²) per vertex.
    applied: Buffer,
    quads: Buffer,
    edge_loss: Buffer,
    /// 12 floats per edge: the gradient wrt its 4 vertices.
    slots: Buffer,
    slot_offsets: Buffer,
    vertex_slots: Buffer,
    values: Buffer,
}

impl Regularizers {
    /// Index of the Laplacian loss in [`Self::values_buffer`].
    pub const LAPLACIAN: u32 = 0;
    /// Index of the flatten loss in [`Self::values_buffer`].
    pub const FLATTEN: u32 = 1;

    /// Tables and kernels for `faces` over `vertex_count` vertices. No faces, indices out of
    /// range, faces repeating a vertex, or an edge of more than two faces: [`Error::Input`].
    pub fn new(ctx: &Context, faces: &[[u32; 3]], vertex_count: usize) -> Result<Self> {
        if faces.is_empty() {
            return Err(Error::Input("regularizers: the mesh has no faces".into()));
        }
        if u32::try_from(vertex_count).is_err() {
            return Err(Error::Limit(format!(
                "regularizers: {vertex_count} vertices; at most 2^32 - 1"
            )));
        }
        let adjacency = Adjacency::from_faces(faces, vertex_count)?;
        let edges = FlattenEdges::from_faces(faces, vertex_count)?;
        let v = vertex_count as u64;
        let e = edges.edge_count() as u64;
        check_binding(ctx, "regularizers: the flatten gradient slots", 48 * e)?;
        check_binding(
            ctx,
            "regularizers: the Laplacian's adjacency",
            4 * adjacency.neighbours.len() as u64,
        )?;
        let flat_quads: Vec<u32> = edges.quads.iter().flatten().copied().collect();
        let device = |name: &str, bytes: u64| {
            ctx.create_buffer(name, check_binding(ctx, name, bytes)?, MemoryKind::Device)
        };
        Ok(Self {
            apply: ctx.kernel(&specs::LAPLACIAN_APPLY, &[])?,
            lap_grad: ctx.kernel(&specs::LAPLACIAN_GRAD, &[])?,
            edges_kernel: ctx.kernel(&specs::FLATTEN_EDGES, &[])?,
            gather: ctx.kernel(&specs::FLATTEN_GATHER, &[])?,
            sum: Sum::new(ctx)?,
            vertex_count: vertex_count as u32, // checked above
            edge_count: e as u32,
            lap_offsets: ctx.upload_buffer("laplacian offsets", &adjacency.offsets)?,
            lap_neighbours: ctx.upload_buffer("laplacian neighbours", &adjacency.neighbours)?,
            applied: device("laplacian applied", 16 * v)?,
            quads: ctx.upload_buffer("flatten edges", &flat_quads)?,
            edge_loss: device("flatten edge terms", 4 * e)?,
            slots: device("flatten gradient slots", 48 * e)?,
            slot_offsets: ctx.upload_buffer("flatten vertex offsets", &edges.vertex_offsets)?,
            vertex_slots: ctx.upload_buffer("flatten vertex slots", &edges.vertex_slots)?,
            values: device("regularizer losses", 8)?,
            adjacency,
            edges,
        })
    }

    /// The Laplacian's adjacency (for the CPU twin).
    pub fn adjacency(&self) -> &Adjacency {
        &self.adjacency
    }

    /// The flatten loss's edges (for the CPU twin).
    pub fn flatten_edges(&self) -> &FlattenEdges {
        &self.edges
    }

    /// Two floats: the Laplacian and flatten losses of the last recorded runs.
    pub fn values_buffer(&self) -> &Buffer {
        &self.values
    }

    /// Reads both losses back (waits).
    pub fn read_losses(&self, ctx: &Context) -> Result<RegularizerLosses> {
        let v: Vec<f32> = ctx.read_buffer(&self.values, 0, 2)?;
        Ok(RegularizerLosses {
            laplacian: v[Self::LAPLACIAN as usize],
            flatten: v[Self::FLATTEN as usize],
        })
    }

    fn check(
        &self,
        what: &str,
        positions: &BufferRange<'_>,
        grad: &Option<GradOut<'_>>,
    ) -> Result<u64> {
        let n = 3 * u64::from(self.vertex_count);
        check_floats(&format!("{what}: positions"), positions, n)?;
        if let Some(g) = grad {
            check_floats(&format!("{what}: gradient"), &g.range, n)?;
        }
        Ok(n)
    }

    /// Records the Laplacian loss of `positions` (`3 V` floats) into float
    /// [`Self::LAPLACIAN`] of the values buffer and, with `grad`, its gradient (`3 V` floats).
    pub fn record_laplacian(
        &self,
        rec: &mut Recorder<'_>,
        positions: BufferRange<'_>,
        grad: Option<GradOut<'_>>,
    ) -> Result<()> {
        let n = self.check("Laplacian loss", &positions, &grad)?;
        let vertex_groups = groups(u64::from(self.vertex_count), 64)?;
        rec.dispatch(
            &self.apply,
            &specs::LaplacianApplyBindings {
                offsets: self.lap_offsets.whole(),
                neighbours: self.lap_neighbours.whole(),
                positions: positions.sub(0, 4 * n),
                applied: self.applied.whole(),
            }
            .for_kernel(&self.apply)?,
            &ApplyPush {
                vertex_count: self.vertex_count,
            },
            vertex_groups,
        )?;
        self.sum.record(
            rec,
            self.applied.whole(),
            self.values.whole(),
            SumPush {
                n: self.vertex_count,
                stride: 4,
                offset: 3,
                out_index: Self::LAPLACIAN,
                scale: 1.0,
                bias: 0.0,
            },
            1,
        )?;
        if let Some(g) = grad {
            rec.dispatch(
                &self.lap_grad,
                &specs::LaplacianGradBindings {
                    offsets: self.lap_offsets.whole(),
                    neighbours: self.lap_neighbours.whole(),
                    applied: self.applied.whole(),
                    grads: g.range.sub(0, 4 * n),
                }
                .for_kernel(&self.lap_grad)?,
                &WeightedPush {
                    vertex_count: self.vertex_count,
                    weight: g.weight,
                    accumulate: u32::from(g.accumulate),
                    pad: 0,
                },
                vertex_groups,
            )?;
        }
        Ok(())
    }

    /// Records the flatten loss of `positions` (`3 V` floats) into float [`Self::FLATTEN`] of
    /// the values buffer and, with `grad`, its gradient (`3 V` floats).
    pub fn record_flatten(
        &self,
        rec: &mut Recorder<'_>,
        positions: BufferRange<'_>,
        grad: Option<GradOut<'_>>,
    ) -> Result<()> {
        let n = self.check("flatten loss", &positions, &grad)?;
        rec.dispatch(
            &self.edges_kernel,
            &specs::FlattenEdgesBindings {
                quads: self.quads.whole(),
                positions: positions.sub(0, 4 * n),
                edge_loss: self.edge_loss.whole(),
                slots: self.slots.whole(),
            }
            .for_kernel(&self.edges_kernel)?,
            &EdgesPush {
                edge_count: self.edge_count,
            },
            groups(u64::from(self.edge_count), 64)?,
        )?;
        self.sum.record(
            rec,
            self.edge_loss.whole(),
            self.values.whole(),
            SumPush {
                n: self.edge_count,
                stride: 1,
                offset: 0,
                out_index: Self::FLATTEN,
                scale: 1.0,
                bias: 0.0,
            },
            1,
        )?;
        if let Some(g) = grad {
            rec.dispatch(
                &self.gather,
                &specs::FlattenGatherBindings {
                    offsets: self.slot_offsets.whole(),
                    vertex_slots: self.vertex_slots.whole(),
                    slots: self.slots.whole(),
                    grads: g.range.sub(0, 4 * n),
                }
                .for_kernel(&self.gather)?,
                &WeightedPush {
                    vertex_count: self.vertex_count,
                    weight: g.weight,
                    accumulate: u32::from(g.accumulate),
                    pad: 0,
                },
                groups(u64::from(self.vertex_count), 64)?,
            )?;
        }
        Ok(())
    }
}
