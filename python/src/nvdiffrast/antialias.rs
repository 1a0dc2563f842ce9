//! nvdiffrast's `antialias` ([`nv_antialias`]) and its backward, and the topology hash
//! ([`NvTopologyHash`]) they take.

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use softvk::raster::hard::antialias::TopologyHash;
use softvk::raster::hard::gpu::AntialiasArgs;

use super::{extent, image, pixels, triangles, with_hard};
use crate::convert::checked;
use crate::error::value_error;

/// `antialias_construct_topology_hash(tri)`'s result: which triangles share each edge, by
/// vertex index, built once for a triangle array that stays the same between calls.
#[pyclass(frozen, module = "softvk._native")]
pub struct NvTopologyHash {
    hash: TopologyHash,
}

#[pymethods]
impl NvTopologyHash {
    /// The number of triangles it was built from.
    #[getter]
    fn triangle_count(&self) -> usize {
        self.hash.triangle_count()
    }

    fn __repr__(&self) -> String {
        format!(
            "<softvk topology hash of {} triangles>",
            self.hash.triangle_count()
        )
    }
}

/// `nv_topology_hash(tri)`: nvdiffrast's `antialias_construct_topology_hash` for `tri [T, 3]`
/// int32 (non-negative indices).
#[pyfunction]
pub fn nv_topology_hash(
    py: Python<'_>,
    tri: PyReadonlyArrayDyn<'_, i32>,
) -> PyResult<NvTopologyHash> {
    let tri = triangles(&tri, i32::MAX as usize + 1)?;
    let hash = py.detach(|| TopologyHash::new(&tri));
    Ok(NvTopologyHash { hash })
}

/// What [`nv_antialias`] and its backward share: checked copies of the inputs.
struct AntialiasInputs {
    color: Vec<f32>,
    rast: Vec<f32>,
    pos: Vec<f32>,
    instanced: bool,
    vertex_count: u32,
    tri: Vec<[u32; 3]>,
    dims: [usize; 4],
}

impl AntialiasInputs {
    fn new(
        color: &PyReadonlyArrayDyn<'_, f32>,
        rast: &PyReadonlyArrayDyn<'_, f32>,
        pos: &PyReadonlyArrayDyn<'_, f32>,
        tri: &PyReadonlyArrayDyn<'_, i32>,
        topology: &NvTopologyHash,
    ) -> PyResult<Self> {
        let (color, cshape) = pixels("color", color, [None, None, None, None])?;
        let dims = [cshape[0], cshape[1], cshape[2], cshape[3]];
        let (rast, _) = pixels(
            "rast",
            rast,
            [Some(dims[0]), Some(dims[1]), Some(dims[2]), Some(4)],
        )?;
        let (instanced, vertices) = match pos.shape() {
            [b, v, 4] if *b == dims[0] && *v > 0 => (true, *v),
            [v, 4] if *v > 0 => (false, *v),
            other => {
                return Err(value_error(format!(
                    "pos has shape {other:?}; expected [{}, >0, 4] (instanced) or [>0, 4] \
                     (range mode)",
                    dims[0]
                )));
            }
        };
        let pos = pos
            .as_slice()
            .map_err(|_| value_error("pos is not C-contiguous".into()))?;
        if let Some(i) = pos.iter().position(|c| !c.is_finite()) {
            return Err(value_error(format!(
                "antialias: vertex {} has a coordinate that is not finite ({})",
                i / 4,
                pos[i]
            )));
        }
        let tri = triangles(tri, vertices)?;
        if topology.hash.triangle_count() != tri.len() {
            return Err(value_error(format!(
                "the topology hash was built from {} triangles, tri has {}",
                topology.hash.triangle_count(),
                tri.len()
            )));
        }
        Ok(Self {
            color: color.to_vec(),
            rast: rast.to_vec(),
            pos: pos.to_vec(),
            instanced,
            vertex_count: extent("pos", vertices)?,
            tri,
            dims,
        })
    }

    fn args(&self) -> PyResult<AntialiasArgs<'_>> {
        Ok(AntialiasArgs {
            color: &self.color,
            rast: &self.rast,
            pos: &self.pos,
            instanced: self.instanced,
            vertex_count: self.vertex_count,
            tri: &self.tri,
            batch: extent("color", self.dims[0])?,
            height: extent("color", self.dims[1])?,
            width: extent("color", self.dims[2])?,
            channels: extent("color", self.dims[3])?,
        })
    }
}

/// `nv_antialias(color, rast, pos, tri, topology)`: nvdiffrast's `antialias` of `color
/// [B, H, W, C]` (same shape out).
#[pyfunction]
pub fn nv_antialias<'py>(
    py: Python<'py>,
    color: PyReadonlyArrayDyn<'py, f32>,
    rast: PyReadonlyArrayDyn<'py, f32>,
    pos: PyReadonlyArrayDyn<'py, f32>,
    tri: PyReadonlyArrayDyn<'py, i32>,
    topology: &NvTopologyHash,
) -> PyResult<Bound<'py, PyAny>> {
    let inputs = AntialiasInputs::new(&color, &rast, &pos, &tri, topology)?;
    let args = inputs.args()?;
    let out = with_hard(py, |ctx, hard| hard.antialias(ctx, &args, &topology.hash))?;
    image(py, out, inputs.dims)
}

/// `nv_antialias_grad(color, rast, pos, tri, topology, dy, pos_gradient_boost)`: the backward
/// of [`nv_antialias`]: `(grad_color, grad_pos)`, the latter times `pos_gradient_boost`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn nv_antialias_grad<'py>(
    py: Python<'py>,
    color: PyReadonlyArrayDyn<'py, f32>,
    rast: PyReadonlyArrayDyn<'py, f32>,
    pos: PyReadonlyArrayDyn<'py, f32>,
    tri: PyReadonlyArrayDyn<'py, i32>,
    topology: &NvTopologyHash,
    dy: PyReadonlyArrayDyn<'py, f32>,
    pos_gradient_boost: f64,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let pos_shape = pos.shape().to_vec();
    let inputs = AntialiasInputs::new(&color, &rast, &pos, &tri, topology)?;
    let dy = checked("dy", &dy, &inputs.dims.map(Some))?.0.to_vec();
    if !pos_gradient_boost.is_finite() {
        return Err(value_error(format!(
            "pos_gradient_boost must be finite, got {pos_gradient_boost}"
        )));
    }
    let args = inputs.args()?;
    let (grad_color, grad_pos) = with_hard(py, |ctx, hard| {
        hard.antialias_grad(ctx, &args, &topology.hash, &dy, pos_gradient_boost)
    })?;
    Ok((
        image(py, grad_color, inputs.dims)?,
        grad_pos.into_pyarray(py).reshape(pos_shape)?.into_any(),
    ))
}
