//! nvdiffrast's `rasterize` ([`nv_rasterize`], with depth peeling) and its backward, in
//! instanced (`pos [B, V, 4]`) or range mode (`pos [V, 4]` with `ranges [B, 2]`).

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use softvk::raster::hard::{Shape, Topology};

use super::{extent, image, pixels, triangles, with_hard};
use crate::convert::checked;
use crate::error::{to_py, value_error};

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
