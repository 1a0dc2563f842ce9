//! nvdiffrast's `interpolate` ([`nv_interpolate`]) and its backward: attributes at each pixel,
//! and with `rast_db` their pixel derivatives.

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use softvk::raster::hard::reference::AttrLayout;

use super::{extent, image, pixels, triangles, with_hard};
use crate::convert::checked;
use crate::error::value_error;

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
