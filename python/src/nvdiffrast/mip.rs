//! nvdiffrast's `texture_construct_mip` ([`nv_texture_construct_mip`]): a texture's mip
//! levels built once ([`NvTextureMip`]), and the texture shapes and stack layouts
//! [`super::texture`] shares with it.

use numpy::PyReadonlyArrayDyn;
use pyo3::prelude::*;
use softvk::raster::hard::gpu::texture::TexLayout;

use super::with_sampler;
use crate::convert::checked;
use crate::error::{to_py, value_error};

/// `texture_construct_mip(tex, max_mip_level)`'s result: the mip levels below a texture of one
/// shape, built once for a texture that stays the same between calls.
#[pyclass(frozen, module = "softvk._native")]
pub struct NvTextureMip {
    /// The shape of the texture it was built from: `[B, H, W, C]`, or a cube map's
    /// `[B, 6, S, S, C]`.
    pub(super) shape: Vec<usize>,
    /// Whether it is a cube map's.
    pub(super) cube: bool,
    /// The stack's layout (the base included).
    pub(super) layout: TexLayout,
    /// Levels 1 and below, as the stack lays them out.
    pub(super) below: Vec<f32>,
}

#[pymethods]
impl NvTextureMip {
    /// The shape of the texture it was built from.
    #[getter]
    fn texture_shape(&self) -> Vec<usize> {
        self.shape.clone()
    }

    /// Whether it was built for a cube map.
    #[getter]
    fn cube_mode(&self) -> bool {
        self.cube
    }

    /// Mip levels below the texture.
    #[getter]
    fn max_mip_level(&self) -> u32 {
        self.layout.levels - 1
    }

    fn __repr__(&self) -> String {
        format!(
            "<softvk mip stack of a {:?} texture, {} levels below it>",
            self.shape,
            self.layout.levels - 1
        )
    }
}

/// A float32 texture's data, its shape and the stack's `[items, height, width, channels]`: a
/// 2D texture `[B, H, W, C]`, or a cube map `[B, 6, S, S, C]` (items: its `6 B` faces).
pub(super) fn texture_dims<'a>(
    name: &str,
    tex: &'a PyReadonlyArrayDyn<'_, f32>,
    cube: bool,
) -> PyResult<(&'a [f32], Vec<usize>, [usize; 4])> {
    let want: &[Option<usize>] = if cube {
        &[None, Some(6), None, None, None]
    } else {
        &[None; 4]
    };
    let (data, shape) = checked(name, tex, want)?;
    if shape.contains(&0) {
        return Err(value_error(format!(
            "{name} has shape {shape:?}; every extent must be > 0"
        )));
    }
    let dims = if cube {
        if shape[2] != shape[3] {
            return Err(value_error(format!(
                "{name} has shape {shape:?}; a cube map's faces must be square"
            )));
        }
        [6 * shape[0], shape[2], shape[3], shape[4]]
    } else {
        [shape[0], shape[1], shape[2], shape[3]]
    };
    Ok((data, shape, dims))
}

pub(super) fn u32_of(what: &str, v: usize) -> PyResult<u32> {
    u32::try_from(v).map_err(|_| value_error(format!("{what} {v} is too large")))
}

pub(super) fn with_mips(dims: [usize; 4], max_mip_level: Option<u32>) -> PyResult<TexLayout> {
    let [b, h, w, c] = dims;
    TexLayout::with_mips(
        u32_of("tex minibatch", b)?,
        u32_of("tex height", h)?,
        u32_of("tex width", w)?,
        u32_of("tex channels", c)?,
        max_mip_level,
    )
    .map_err(to_py)
}

/// The Python shape of level `level` of a stack over a texture of `shape`.
pub(super) fn level_shape(shape: &[usize], layout: &TexLayout, level: u32) -> Vec<usize> {
    let [w, h] = layout.level_size(level).map(|v| v as usize);
    let mut s = shape.to_vec();
    let n = s.len();
    s[n - 3] = h;
    s[n - 2] = w;
    s
}

/// `nv_texture_construct_mip(tex, max_mip_level=None, cube_mode=False)`: nvdiffrast's
/// `texture_construct_mip`.
#[pyfunction]
#[pyo3(signature = (tex, max_mip_level = None, cube_mode = false))]
pub fn nv_texture_construct_mip(
    py: Python<'_>,
    tex: PyReadonlyArrayDyn<'_, f32>,
    max_mip_level: Option<u32>,
    cube_mode: bool,
) -> PyResult<NvTextureMip> {
    let (data, shape, dims) = texture_dims("tex", &tex, cube_mode)?;
    let layout = with_mips(dims, max_mip_level)?;
    let data = data.to_vec();
    let mut stack = with_sampler(py, |ctx, s| s.construct_mip(ctx, &layout, &data))?;
    let below = stack.split_off(data.len());
    Ok(NvTextureMip {
        shape,
        cube: cube_mode,
        layout,
        below,
    })
}
