//! nvdiffrast's primitives (`softvk.nvdiffrast.torch`): hard rasterization of clip-space
//! triangles with depth peeling, attribute interpolation and analytic antialiasing, forward and
//! backward, on the engine's [`HardRasterizer`]. Arrays arrive in nvdiffrast's layouts
//! (`pos [B, V, 4]` or `[V, 4]`, `tri [T, 3]` int32, images `[B, H, W, C]`, row 0 at the bottom);
//! the Python module checks them first and gives nvdiffrast's errors, and every function here
//! checks again what the engine would otherwise index out of bounds. Inputs are copied before
//! the GIL is released (another thread may write to a numpy array meanwhile), as
//! [`super::fragments`] does.
//!
//! The functions lie in [`rasterize`], [`interpolate`], [`antialias`], and for nvdiffrast's
//! `texture` and `texture_construct_mip` in [`texture`] and [`mip`]; this file holds what they
//! share: the engine's hard rasterizer and texture sampler, made on first use, and the checks
//! of triangles, extents and image arrays.

use std::sync::MutexGuard;

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use softvk::gpu::Context;
use softvk::raster::hard::gpu::HardRasterizer;
use softvk::raster::hard::gpu::texture::TextureSampler;

use crate::convert::checked;
use crate::engine::{Engine, with_engine};
use crate::error::value_error;

mod antialias;
mod interpolate;
mod mip;
mod rasterize;
mod texture;

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

/// The engine's texture sampler, made on first use.
fn engine_sampler(engine: &Engine) -> softvk::Result<MutexGuard<'_, Option<TextureSampler>>> {
    let mut cell = engine.texture.lock().unwrap_or_else(|e| e.into_inner());
    if cell.is_none() {
        *cell = Some(TextureSampler::new(&engine.ctx)?);
    }
    Ok(cell)
}

/// Runs `f` on the texture sampler with the GIL released.
fn with_sampler<T: Send>(
    py: Python<'_>,
    f: impl FnOnce(&Context, &mut TextureSampler) -> softvk::Result<T> + Send,
) -> PyResult<T> {
    with_engine(py, |engine| {
        let mut cell = engine_sampler(engine)?;
        f(&engine.ctx, cell.as_mut().expect("made by engine_sampler"))
    })
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

/// Registers the functions on the native module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<antialias::NvTopologyHash>()?;
    m.add_function(wrap_pyfunction!(rasterize::nv_rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(rasterize::nv_rasterize_grad, m)?)?;
    m.add_function(wrap_pyfunction!(interpolate::nv_interpolate, m)?)?;
    m.add_function(wrap_pyfunction!(interpolate::nv_interpolate_grad, m)?)?;
    m.add_function(wrap_pyfunction!(antialias::nv_topology_hash, m)?)?;
    m.add_function(wrap_pyfunction!(antialias::nv_antialias, m)?)?;
    m.add_function(wrap_pyfunction!(antialias::nv_antialias_grad, m)?)?;
    m.add_class::<mip::NvTextureMip>()?;
    m.add_function(wrap_pyfunction!(mip::nv_texture_construct_mip, m)?)?;
    m.add_function(wrap_pyfunction!(texture::nv_texture, m)?)?;
    m.add_function(wrap_pyfunction!(texture::nv_texture_grad, m)?)?;
    Ok(())
}
