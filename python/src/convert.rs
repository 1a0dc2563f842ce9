//! numpy conversion: contiguous arrays checked against a shape ([`checked`]), flat data as
//! triples, and results handed back to Python as numpy arrays.

use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::error::value_error;

/// A contiguous array's data and shape, checked against `want` (`None`: any extent).
pub(crate) fn checked<'a, T: numpy::Element>(
    name: &str,
    array: &'a PyReadonlyArrayDyn<'_, T>,
    want: &[Option<usize>],
) -> PyResult<(&'a [T], Vec<usize>)> {
    let shape = array.shape().to_vec();
    let fits = shape.len() == want.len()
        && shape
            .iter()
            .zip(want)
            .all(|(s, w)| w.is_none_or(|w| *s == w));
    if !fits {
        let want: Vec<String> = want
            .iter()
            .map(|w| w.map_or("*".into(), |w| w.to_string()))
            .collect();
        return Err(value_error(format!(
            "{name} has shape {shape:?}; expected [{}]",
            want.join(", ")
        )));
    }
    let data = array
        .as_slice()
        .map_err(|_| value_error(format!("{name} is not C-contiguous")))?;
    Ok((data, shape))
}

pub(crate) fn triples<T: Copy>(data: &[T]) -> Vec<[T; 3]> {
    data.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// The texture resolution R of `texels` = R² texels a face.
pub(crate) fn texture_res(texels: usize) -> PyResult<u32> {
    let r = (texels as f64).sqrt().round() as usize;
    if r == 0 || r * r != texels {
        return Err(value_error(format!(
            "surface textures need R² texels a face, got {texels}"
        )));
    }
    u32::try_from(r).map_err(|_| value_error(format!("texture resolution {r} is too large")))
}

/// RGBA images `[views, H, W, 4]` as a numpy array.
pub(crate) fn images_array<'py, T: numpy::Element>(
    py: Python<'py>,
    flat: Vec<T>,
    (views, height, width): (usize, usize, usize),
) -> PyResult<Bound<'py, PyAny>> {
    Ok(flat
        .into_pyarray(py)
        .reshape([views, height, width, 4])?
        .into_any())
}

pub(crate) fn array_of<'py>(
    py: Python<'py>,
    flat: Vec<f32>,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, flat).reshape(shape)?.into_any())
}
