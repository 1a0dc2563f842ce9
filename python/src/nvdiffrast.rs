//! nvdiffrast's primitives (`softvk.nvdiffrast.torch`): hard rasterization of clip-space
//! triangles with depth peeling, attribute interpolation and analytic antialiasing, forward and
//! backward, on the engine's [`HardRasterizer`]. Arrays arrive in nvdiffrast's layouts
//! (`pos [B, V, 4]` or `[V, 4]`, `tri [T, 3]` int32, images `[B, H, W, C]`, row 0 at the bottom);
//! the Python module checks them first and gives nvdiffrast's errors, and every function here
//! checks again what the engine would otherwise index out of bounds. Inputs are copied before
//! the GIL is released (another thread may write to a numpy array meanwhile), as
//! [`super::fragments`] does.

use std::sync::MutexGuard;

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use softvk::gpu::Context;
use softvk::raster::hard::antialias::TopologyHash;
use softvk::raster::hard::gpu::{AntialiasArgs, HardRasterizer};
use softvk::raster::hard::reference::AttrLayout;
use softvk::raster::hard::{Shape, Topology};

use crate::convert::checked;
use crate::engine::{Engine, with_engine};
use crate::error::{to_py, value_error};

/// The engine's hard rasterizer, made on first use.
fn engine_hard(engine: &Engine) -> softvk::Result<MutexGuard<'_, Option<HardRasterizer>>> {
    let mut cell = engine.hard.lock().unwrap_or_else(|e| e.into_inner());
    if cell.is_none() {
        *cell = Some(HardRasterizer::new(&engine.ctx)?);
    }
    Ok(cell)
}

/// Runs `f` on the hard rasterizer with the GIL released (see [`with_engine`]).
fn with_hard<T: Send>(
    py: Python<'_>,
    f: impl FnOnce(&Context, &mut HardRasterizer) -> softvk::Result<T> + Send,
) -> PyResult<T> {
    with_engine(py, |engine| {
        let mut cell = engine_hard(engine)?;
        let hard = cell.as_mut().expect("made by engine_hard");
        f(&engine.ctx, hard)
    })
}

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

/// A u32 from an extent (arrays past 2³² entries along one axis are refused).
fn extent(name: &str, n: usize) -> PyResult<u32> {
    u32::try_from(n).map_err(|_| value_error(format!("{name} has {n} entries, too many")))
}

/// `tri [T, 3]` int32 as vertex triples, each index in `0..vertices`.
fn triangles(tri: &PyReadonlyArrayDyn<'_, i32>, vertices: usize) -> PyResult<Vec<[u32; 3]>> {
    let (data, shape) = checked("tri", tri, &[None, Some(3)])?;
    if shape[0] == 0 {
        return Err(value_error("tri must have shape [>0, 3]".into()));
    }
    data.chunks_exact(3)
        .enumerate()
        .map(|(t, c)| {
            let mut out = [0u32; 3];
            for (k, &i) in c.iter().enumerate() {
                out[k] = u32::try_from(i)
                    .ok()
                    .filter(|&i| (i as usize) < vertices)
                    .ok_or_else(|| {
                        value_error(format!(
                            "triangle {t} has vertex index {i}, outside the {vertices} vertices"
                        ))
                    })?;
            }
            Ok(out)
        })
        .collect()
}

/// The rasterization's [`Shape`] from `pos`'s shape (`[B, V, 4]` instanced, `[V, 4]` with
/// `ranges [B, 2]`), the triangle count and the resolution.
fn shape_of(
    pos_shape: &[usize],
    triangle_count: usize,
    height: u32,
    width: u32,
    ranges: Option<&PyReadonlyArrayDyn<'_, i32>>,
) -> PyResult<Shape> {
    let (vertex_count, topology) = match pos_shape {
        [batch, vertices, 4] if *batch > 0 && *vertices > 0 => (
            *vertices,
            Topology::Instanced {
                batch: extent("pos", *batch)?,
            },
        ),
        [vertices, 4] if *vertices > 0 => {
            let ranges = ranges
                .ok_or_else(|| value_error("range mode (pos [V, 4]) needs ranges [B, 2]".into()))?;
            let (data, shape) = checked("ranges", ranges, &[None, Some(2)])?;
            if shape[0] == 0 {
                return Err(value_error("ranges must have shape [>0, 2]".into()));
            }
            let ranges = data
                .chunks_exact(2)
                .enumerate()
                .map(|(b, r)| match (u32::try_from(r[0]), u32::try_from(r[1])) {
                    (Ok(first), Ok(count)) => Ok([first, count]),
                    _ => Err(value_error(format!(
                        "range {b} is [{}, {}]: start and count must not be negative",
                        r[0], r[1]
                    ))),
                })
                .collect::<PyResult<Vec<_>>>()?;
            (*vertices, Topology::Ranged(ranges))
        }
        _ => {
            return Err(value_error(format!(
                "pos has shape {pos_shape:?}; expected [>0, >0, 4] (instanced) or [>0, 4] (range \
                 mode)"
            )));
        }
    };
    Ok(Shape {
        width,
        height,
        vertex_count: extent("pos", vertex_count)?,
        triangle_count: extent("tri", triangle_count)?,
        topology,
    })
}

/// `[B, H, W, C]` as a numpy array.
fn image<'py>(py: Python<'py>, flat: Vec<f32>, dims: [usize; 4]) -> PyResult<Bound<'py, PyAny>> {
    Ok(flat.into_pyarray(py).reshape(dims)?.into_any())
}

/// A contiguous `[B, H, W, C]` float32 array's data, checked against `want`.
fn pixels<'a>(
    name: &str,
    a: &'a PyReadonlyArrayDyn<'_, f32>,
    want: [Option<usize>; 4],
) -> PyResult<(&'a [f32], Vec<usize>)> {
    let (data, shape) = checked(name, a, &want)?;
    if shape.contains(&0) {
        return Err(value_error(format!(
            "{name} has shape {shape:?}; every extent must be > 0"
        )));
    }
    Ok((data, shape))
}

/// `nv_rasterize(pos, tri, height, width, ranges=None, previous=None)`: nvdiffrast's
/// `rasterize`. Returns `(rast, rast_db, keys)`: `(u, v, z/w, id + 1)` and `(du/dX, du/dY,
/// dv/dX, dv/dY)` as `[B, H, W, 4]` float32, and each pixel's depth key `[B, H, W, 2]` uint32;
/// passing a layer's keys as `previous` rasterizes the next depth-peeling layer.
#[pyfunction]
#[pyo3(signature = (pos, tri, height, width, ranges = None, previous = None))]
pub fn nv_rasterize<'py>(
    py: Python<'py>,
    pos: PyReadonlyArrayDyn<'py, f32>,
    tri: PyReadonlyArrayDyn<'py, i32>,
    height: u32,
    width: u32,
    ranges: Option<PyReadonlyArrayDyn<'py, i32>>,
    previous: Option<PyReadonlyArrayDyn<'py, u32>>,
) -> PyResult<Bound<'py, PyTuple>> {
    let pos_shape = pos.shape().to_vec();
    let tri_count = tri.shape().first().copied().unwrap_or(0);
    let shape = shape_of(&pos_shape, tri_count, height, width, ranges.as_ref())?;
    let tri = triangles(&tri, shape.vertex_count as usize)?;
    let pos = pos
        .as_slice()
        .map_err(|_| value_error("pos is not C-contiguous".into()))?
        .to_vec();
    shape.check(&tri).map_err(to_py)?;
    shape.check_pos(&pos).map_err(to_py)?;
    let dims = [shape.batch() as usize, height as usize, width as usize, 4];
    let previous: Option<Vec<[u32; 2]>> = previous
        .as_ref()
        .map(|p| {
            let want = [dims[0], dims[1], dims[2], 2].map(Some);
            checked("previous", p, &want)
                .map(|(d, _)| d.chunks_exact(2).map(|k| [k[0], k[1]]).collect())
        })
        .transpose()?;
    let layer = with_hard(py, |ctx, hard| {
        hard.rasterize(ctx, &shape, &pos, &tri, previous.as_deref())
    })?;
    let keys: Vec<u32> = layer.keys.into_iter().flatten().collect();
    let keys = keys
        .into_pyarray(py)
        .reshape([dims[0], dims[1], dims[2], 2])?
        .into_any();
    PyTuple::new(
        py,
        [
            image(py, layer.rast, dims)?,
            image(py, layer.rast_db, dims)?,
            keys,
        ],
    )
}

/// `nv_rasterize_grad(pos, tri, rast, dy, ddb=None, ranges=None)`: the backward of
/// [`nv_rasterize`] to `pos` (its shape), given the upstream gradients of `rast` (`dy`) and,
/// when `rast_db`'s gradient flows, of `rast_db` (`ddb`), all `[B, H, W, 4]`.
#[pyfunction]
#[pyo3(signature = (pos, tri, rast, dy, ddb = None, ranges = None))]
pub fn nv_rasterize_grad<'py>(
    py: Python<'py>,
    pos: PyReadonlyArrayDyn<'py, f32>,
    tri: PyReadonlyArrayDyn<'py, i32>,
    rast: PyReadonlyArrayDyn<'py, f32>,
    dy: PyReadonlyArrayDyn<'py, f32>,
    ddb: Option<PyReadonlyArrayDyn<'py, f32>>,
    ranges: Option<PyReadonlyArrayDyn<'py, i32>>,
) -> PyResult<Bound<'py, PyAny>> {
    let (rast, rshape) = pixels("rast", &rast, [None, None, None, Some(4)])?;
    let (batch, height, width) = (rshape[0], rshape[1], rshape[2]);
    let pos_shape = pos.shape().to_vec();
    let tri_count = tri.shape().first().copied().unwrap_or(0);
    let shape = shape_of(
        &pos_shape,
        tri_count,
        extent("rast", height)?,
        extent("rast", width)?,
        ranges.as_ref(),
    )?;
    if shape.batch() as usize != batch {
        return Err(value_error(format!(
            "rast has a minibatch of {batch}, the positions (or ranges) {}",
            shape.batch()
        )));
    }
    let tri = triangles(&tri, shape.vertex_count as usize)?;
    let want = [batch, height, width, 4].map(Some);
    let dy = checked("dy", &dy, &want)?.0.to_vec();
    let ddb = ddb
        .as_ref()
        .map(|d| checked("ddb", d, &want).map(|(d, _)| d.to_vec()))
        .transpose()?;
    let pos = pos
        .as_slice()
        .map_err(|_| value_error("pos is not C-contiguous".into()))?
        .to_vec();
    shape.check(&tri).map_err(to_py)?;
    shape.check_pos(&pos).map_err(to_py)?;
    let rast = rast.to_vec();
    let grad = with_hard(py, |ctx, hard| {
        hard.rasterize_grad(ctx, &shape, &pos, &tri, &rast, &dy, ddb.as_deref())
    })?;
    Ok(grad.into_pyarray(py).reshape(pos_shape)?.into_any())
}

/// Where interpolation finds its attributes: `attr [V, A]` or `[1, V, A]` shared by the
/// minibatch of `batch`, or `[batch, V, A]`.
fn attr_layout(attr_shape: &[usize], batch: usize) -> PyResult<AttrLayout> {
    let (sets, vertices, count) = match attr_shape {
        [v, a] => (1, *v, *a),
        [s, v, a] => (*s, *v, *a),
        _ => (0, 0, 0),
    };
    if vertices == 0 || count == 0 || sets == 0 {
        return Err(value_error(format!(
            "attr has shape {attr_shape:?}; expected [>0, >0] or [>0, >0, >0]"
        )));
    }
    if sets != 1 && sets != batch {
        return Err(value_error(format!(
            "attr has a minibatch of {sets}, rast {batch} (attr's must be 1 or rast's)"
        )));
    }
    Ok(AttrLayout {
        vertex_count: extent("attr", vertices)?,
        attr_count: extent("attr", count)?,
        per_item: sets > 1,
    })
}

/// The attributes to differentiate, each below `count`.
fn diff_list(diff: &[u32], count: u32) -> PyResult<()> {
    match diff.iter().find(|&&j| j >= count) {
        Some(j) => Err(value_error(format!(
            "diff_attrs names attribute {j}, outside the {count} attributes"
        ))),
        None => Ok(()),
    }
}

/// What [`nv_interpolate`] and its backward share: checked copies of the inputs.
struct InterpolateInputs {
    attr: Vec<f32>,
    layout: AttrLayout,
    rast: Vec<f32>,
    tri: Vec<[u32; 3]>,
    dims: [usize; 3],
    rast_db: Option<Vec<f32>>,
}

impl InterpolateInputs {
    fn new(
        attr: &PyReadonlyArrayDyn<'_, f32>,
        rast: &PyReadonlyArrayDyn<'_, f32>,
        tri: &PyReadonlyArrayDyn<'_, i32>,
        rast_db: Option<&PyReadonlyArrayDyn<'_, f32>>,
        diff: &[u32],
    ) -> PyResult<Self> {
        let (rast, rshape) = pixels("rast", rast, [None, None, None, Some(4)])?;
        let dims = [rshape[0], rshape[1], rshape[2]];
        let layout = attr_layout(attr.shape(), dims[0])?;
        let attr = attr
            .as_slice()
            .map_err(|_| value_error("attr is not C-contiguous".into()))?
            .to_vec();
        let tri = triangles(tri, layout.vertex_count as usize)?;
        diff_list(diff, layout.attr_count)?;
        let rast_db = rast_db
            .map(|d| {
                checked("rast_db", d, &[dims[0], dims[1], dims[2], 4].map(Some))
                    .map(|(d, _)| d.to_vec())
            })
            .transpose()?;
        Ok(Self {
            attr,
            layout,
            rast: rast.to_vec(),
            tri,
            dims,
            rast_db,
        })
    }

    /// `[H, W]`.
    fn resolution(&self) -> [u32; 2] {
        [self.dims[1] as u32, self.dims[2] as u32]
    }

    fn out_dims(&self, channels: usize) -> [usize; 4] {
        [self.dims[0], self.dims[1], self.dims[2], channels]
    }
}

/// `nv_interpolate(attr, rast, tri, rast_db=None, diff=[])`: nvdiffrast's `interpolate`.
/// `attr` is `[V, A]`, `[1, V, A]` or `[B, V, A]`; `diff` lists the attributes whose pixel
/// derivatives `out_da` holds (with `rast_db`). Returns `(out [B, H, W, A], out_da [B, H, W,
/// 2 len(diff)])`.
#[pyfunction]
#[pyo3(signature = (attr, rast, tri, rast_db = None, diff = Vec::new()))]
pub fn nv_interpolate<'py>(
    py: Python<'py>,
    attr: PyReadonlyArrayDyn<'py, f32>,
    rast: PyReadonlyArrayDyn<'py, f32>,
    tri: PyReadonlyArrayDyn<'py, i32>,
    rast_db: Option<PyReadonlyArrayDyn<'py, f32>>,
    diff: Vec<u32>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
    let inputs = InterpolateInputs::new(&attr, &rast, &tri, rast_db.as_ref(), &diff)?;
    let diff = if inputs.rast_db.is_some() {
        diff
    } else {
        Vec::new()
    };
    let (out, out_da) = with_hard(py, |ctx, hard| {
        hard.interpolate(
            ctx,
            &inputs.attr,
            inputs.layout,
            &inputs.rast,
            &inputs.tri,
            inputs.resolution(),
            inputs.rast_db.as_deref(),
            &diff,
        )
    })?;
    Ok((
        image(py, out, inputs.out_dims(inputs.layout.attr_count as usize))?,
        image(py, out_da, inputs.out_dims(2 * diff.len()))?,
    ))
}

/// The gradients [`nv_interpolate_grad`] returns: to `attr`, `rast` and (with `rast_db`)
/// `rast_db`.
type InterpolateGrads<'py> = (
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Option<Bound<'py, PyAny>>,
);

/// `nv_interpolate_grad(attr, rast, tri, dy, rast_db=None, dda=None, diff=[])`: the backward
/// of [`nv_interpolate`]: `(grad_attr (attr's shape), grad_rast [B, H, W, 4], grad_rast_db
/// [B, H, W, 4] or None without rast_db)`.
#[pyfunction]
#[pyo3(signature = (attr, rast, tri, dy, rast_db = None, dda = None, diff = Vec::new()))]
#[allow(clippy::too_many_arguments)]
pub fn nv_interpolate_grad<'py>(
    py: Python<'py>,
    attr: PyReadonlyArrayDyn<'py, f32>,
    rast: PyReadonlyArrayDyn<'py, f32>,
    tri: PyReadonlyArrayDyn<'py, i32>,
    dy: PyReadonlyArrayDyn<'py, f32>,
    rast_db: Option<PyReadonlyArrayDyn<'py, f32>>,
    dda: Option<PyReadonlyArrayDyn<'py, f32>>,
    diff: Vec<u32>,
) -> PyResult<InterpolateGrads<'py>> {
    let attr_shape = attr.shape().to_vec();
    let inputs = InterpolateInputs::new(&attr, &rast, &tri, rast_db.as_ref(), &diff)?;
    let diff = if inputs.rast_db.is_some() {
        diff
    } else {
        Vec::new()
    };
    let dy = checked(
        "dy",
        &dy,
        &inputs.out_dims(inputs.layout.attr_count as usize).map(Some),
    )?
    .0
    .to_vec();
    let dda = match (&dda, diff.is_empty()) {
        (Some(d), false) => Some(
            checked("dda", d, &inputs.out_dims(2 * diff.len()).map(Some))?
                .0
                .to_vec(),
        ),
        _ => None,
    };
    let grads = with_hard(py, |ctx, hard| {
        hard.interpolate_grad(
            ctx,
            &inputs.attr,
            inputs.layout,
            &inputs.rast,
            &inputs.tri,
            inputs.resolution(),
            inputs.rast_db.as_deref(),
            &diff,
            &dy,
            dda.as_deref(),
        )
    })?;
    let with_db = inputs.rast_db.is_some();
    Ok((
        grads.attr.into_pyarray(py).reshape(attr_shape)?.into_any(),
        image(py, grads.rast, inputs.out_dims(4))?,
        if with_db {
            Some(image(py, grads.rast_db, inputs.out_dims(4))?)
        } else {
            None
        },
    ))
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

/// Registers the functions on the native module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NvTopologyHash>()?;
    m.add_function(wrap_pyfunction!(nv_rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(nv_rasterize_grad, m)?)?;
    m.add_function(wrap_pyfunction!(nv_interpolate, m)?)?;
    m.add_function(wrap_pyfunction!(nv_interpolate_grad, m)?)?;
    m.add_function(wrap_pyfunction!(nv_topology_hash, m)?)?;
    m.add_function(wrap_pyfunction!(nv_antialias, m)?)?;
    m.add_function(wrap_pyfunction!(nv_antialias_grad, m)?)?;
    Ok(())
}
