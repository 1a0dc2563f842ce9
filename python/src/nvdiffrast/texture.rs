//! nvdiffrast's `texture` and `texture_construct_mip` (`softvk.nvdiffrast.torch`), forward and
//! backward, on the engine's [`TextureSampler`]. The Python module checks the arguments first
//! and gives nvdiffrast's errors; these functions check again what the engine would otherwise
//! read out of bounds, and copy the inputs before the GIL is released.
//!
//! A call's mip stack is one of three (nvdiffrast's): built here from `tex` (a mipmap mode with
//! no `mip`), `tex` over the levels a [`NvTextureMip`] holds (its gradients carried into `tex`),
//! or `tex` over a list of the caller's levels (each level's gradient its own).
//!
//! `texture_construct_mip` itself, and the texture shapes and stack layouts both use, lie in
//! [`super::mip`].
//!
//! [`TextureSampler`]: softvk::raster::hard::gpu::texture::TextureSampler

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use softvk::raster::hard::gpu::texture::{Levels, Lookup, Lookups, TexLayout, TexMode};
use softvk::raster::hard::texture::Filter;

use super::mip::{NvTextureMip, level_shape, texture_dims, u32_of, with_mips};
use super::with_sampler;
use crate::convert::checked;
use crate::error::{to_py, value_error};

/// Where a call's stack comes from.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Source {
    /// Built from `tex` on the device.
    Build,
    /// `tex` over an [`NvTextureMip`]'s levels.
    Prebuilt,
    /// `tex` over the caller's levels (none: `tex` alone, for the modes with no mipmaps).
    Custom,
}

/// One call's checked inputs.
struct TextureCall {
    /// `tex`'s shape.
    shape: Vec<usize>,
    layout: TexLayout,
    mode: TexMode,
    source: Source,
    /// The base alone ([`Source::Build`]) or every level.
    stack: Vec<f32>,
    grid: Lookups,
    uv: Vec<f32>,
    uv_da: Option<Vec<f32>>,
    bias: Option<Vec<f32>>,
}

impl TextureCall {
    #[allow(clippy::too_many_arguments)]
    fn new(
        tex: &PyReadonlyArrayDyn<'_, f32>,
        uv: &PyReadonlyArrayDyn<'_, f32>,
        filter: &str,
        boundary: &str,
        uv_da: Option<&PyReadonlyArrayDyn<'_, f32>>,
        bias: Option<&PyReadonlyArrayDyn<'_, f32>>,
        mip: Option<&NvTextureMip>,
        mip_levels: Option<&[PyReadonlyArrayDyn<'_, f32>]>,
        max_mip_level: Option<u32>,
    ) -> PyResult<Self> {
        let filter = Filter::parse(filter, uv_da.is_some() || bias.is_some(), max_mip_level)
            .map_err(to_py)?;
        let mode = TexMode::parse(filter, boundary).map_err(to_py)?;
        let cube = matches!(mode, TexMode::Cube(_));
        let (tex_data, shape, dims) = texture_dims("tex", tex, cube)?;
        let n_uv = mode.uv_floats() as usize;
        let (uv_data, uv_shape) = checked("uv", uv, &[None, None, None, Some(n_uv)])?;
        let [b, h, w] = [uv_shape[0], uv_shape[1], uv_shape[2]];
        let mips = filter.uses_mips();
        let n_da = mode.uv_da_floats() as usize;
        let uv_da = match uv_da.filter(|_| mips) {
            Some(d) => Some(checked("uv_da", d, &[b, h, w, n_da].map(Some))?.0.to_vec()),
            None => None,
        };
        let bias = match bias.filter(|_| mips) {
            Some(d) => Some(
                checked("mip_level_bias", d, &[b, h, w].map(Some))?
                    .0
                    .to_vec(),
            ),
            None => None,
        };
        let base = || {
            let [n, h, w, c] = dims;
            TexLayout::new(
                u32_of("tex minibatch", n)?,
                u32_of("tex height", h)?,
                u32_of("tex width", w)?,
                u32_of("tex channels", c)?,
                1,
            )
            .map_err(to_py)
        };
        let (layout, source, stack) = match (mips, mip, mip_levels) {
            (false, ..) => (base()?, Source::Custom, tex_data.to_vec()),
            (true, Some(m), _) => {
                if m.shape != shape || m.cube != cube {
                    let kind = |c: bool| if c { "cube map" } else { "2D texture" };
                    return Err(value_error(format!(
                        "mip was built for a {:?} {}, tex is a {shape:?} {}",
                        m.shape,
                        kind(m.cube),
                        kind(cube)
                    )));
                }
                let mut stack = tex_data.to_vec();
                stack.extend_from_slice(&m.below);
                (m.layout, Source::Prebuilt, stack)
            }
            (true, None, Some(levels)) => {
                let mut layout = base()?;
                layout = TexLayout::new(
                    layout.items,
                    layout.height,
                    layout.width,
                    layout.channels,
                    1 + u32_of("mip levels", levels.len())?,
                )
                .map_err(to_py)?;
                let mut stack = tex_data.to_vec();
                for (k, level) in levels.iter().enumerate() {
                    let want: Vec<_> = level_shape(&shape, &layout, 1 + k as u32)
                        .into_iter()
                        .map(Some)
                        .collect();
                    stack.extend_from_slice(
                        checked(&format!("mip level {}", k + 1), level, &want)?.0,
                    );
                }
                (layout, Source::Custom, stack)
            }
            (true, None, None) => (
                with_mips(dims, max_mip_level)?,
                Source::Build,
                tex_data.to_vec(),
            ),
        };
        Ok(Self {
            shape,
            layout,
            mode,
            source,
            stack,
            grid: Lookups {
                batch: u32_of("uv minibatch", b)?,
                height: u32_of("uv height", h)?,
                width: u32_of("uv width", w)?,
                uv_da: uv_da.is_some(),
                bias: bias.is_some(),
            },
            uv: uv_data.to_vec(),
            uv_da,
            bias,
        })
    }

    fn levels(&self) -> Levels<'_> {
        match self.source {
            Source::Build => Levels::Build(&self.stack),
            Source::Prebuilt => Levels::Built(&self.stack),
            Source::Custom => Levels::Given(&self.stack),
        }
    }

    fn lookup(&self) -> Lookup<'_> {
        Lookup {
            grid: self.grid,
            uv: &self.uv,
            uv_da: self.uv_da.as_deref(),
            bias: self.bias.as_deref(),
        }
    }

    /// `[B, h, w, n]`.
    fn dims(&self, n: usize) -> Vec<usize> {
        let g = &self.grid;
        let mut d = vec![g.batch as usize, g.height as usize, g.width as usize];
        if n > 0 {
            d.push(n);
        }
        d
    }
}

/// `nv_texture(tex, uv, filter, boundary, uv_da=None, mip_level_bias=None, mip=None,
/// mip_levels=None, max_mip_level=None)`: nvdiffrast's `texture`, `[B, h, w, C]`.
#[pyfunction]
#[pyo3(signature = (tex, uv, filter, boundary, uv_da = None, mip_level_bias = None, mip = None,
    mip_levels = None, max_mip_level = None))]
#[allow(clippy::too_many_arguments)]
pub fn nv_texture<'py>(
    py: Python<'py>,
    tex: PyReadonlyArrayDyn<'py, f32>,
    uv: PyReadonlyArrayDyn<'py, f32>,
    filter: &str,
    boundary: &str,
    uv_da: Option<PyReadonlyArrayDyn<'py, f32>>,
    mip_level_bias: Option<PyReadonlyArrayDyn<'py, f32>>,
    mip: Option<PyRef<'py, NvTextureMip>>,
    mip_levels: Option<Vec<PyReadonlyArrayDyn<'py, f32>>>,
    max_mip_level: Option<u32>,
) -> PyResult<Bound<'py, PyAny>> {
    let call = TextureCall::new(
        &tex,
        &uv,
        filter,
        boundary,
        uv_da.as_ref(),
        mip_level_bias.as_ref(),
        mip.as_deref(),
        mip_levels.as_deref(),
        max_mip_level,
    )?;
    let out = with_sampler(py, |ctx, s| {
        s.sample(ctx, &call.layout, call.mode, call.levels(), &call.lookup())
    })?;
    Ok(out
        .into_pyarray(py)
        .reshape(call.dims(call.layout.channels as usize))?
        .into_any())
}

/// What [`nv_texture_grad`] returns: the gradients to `tex`, `uv`, `uv_da` and
/// `mip_level_bias` (`None` where not an input of the mode), and one per custom mip level.
type TextureGrads<'py> = (
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Option<Bound<'py, PyAny>>,
    Option<Bound<'py, PyAny>>,
    Vec<Bound<'py, PyAny>>,
);

/// `nv_texture_grad(tex, uv, dy, filter, boundary, uv_da=None, mip_level_bias=None, mip=None,
/// mip_levels=None, max_mip_level=None)`: the backward of [`nv_texture`].
#[pyfunction]
#[pyo3(signature = (tex, uv, dy, filter, boundary, uv_da = None, mip_level_bias = None,
    mip = None, mip_levels = None, max_mip_level = None))]
#[allow(clippy::too_many_arguments)]
pub fn nv_texture_grad<'py>(
    py: Python<'py>,
    tex: PyReadonlyArrayDyn<'py, f32>,
    uv: PyReadonlyArrayDyn<'py, f32>,
    dy: PyReadonlyArrayDyn<'py, f32>,
    filter: &str,
    boundary: &str,
    uv_da: Option<PyReadonlyArrayDyn<'py, f32>>,
    mip_level_bias: Option<PyReadonlyArrayDyn<'py, f32>>,
    mip: Option<PyRef<'py, NvTextureMip>>,
    mip_levels: Option<Vec<PyReadonlyArrayDyn<'py, f32>>>,
    max_mip_level: Option<u32>,
) -> PyResult<TextureGrads<'py>> {
    let call = TextureCall::new(
        &tex,
        &uv,
        filter,
        boundary,
        uv_da.as_ref(),
        mip_level_bias.as_ref(),
        mip.as_deref(),
        mip_levels.as_deref(),
        max_mip_level,
    )?;
    let c = call.layout.channels as usize;
    let want = call.dims(c).into_iter().map(Some).collect::<Vec<_>>();
    let dy = checked("dy", &dy, &want)?.0.to_vec();
    let mut g = with_sampler(py, |ctx, s| {
        s.sample_grad(
            ctx,
            &call.layout,
            call.mode,
            call.levels(),
            &call.lookup(),
            &dy,
        )
    })?;
    let layout = call.layout;
    let mut levels = Vec::new();
    if call.source == Source::Custom && layout.levels > 1 {
        for l in (1..layout.levels).rev() {
            let part = g.stack.split_off(layout.level_offset(l) as usize);
            let shape = level_shape(&call.shape, &layout, l);
            levels.push(part.into_pyarray(py).reshape(shape)?.into_any());
        }
        levels.reverse();
    }
    // Level 0: the texture's own gradient (with the levels' carried into it but for a custom
    // stack).
    g.stack.truncate(layout.level_texels(0) as usize * c);
    let (n_uv, n_da) = (call.mode.uv_floats(), call.mode.uv_da_floats());
    Ok((
        g.stack
            .into_pyarray(py)
            .reshape(call.shape.clone())?
            .into_any(),
        g.uv.into_pyarray(py)
            .reshape(call.dims(n_uv as usize))?
            .into_any(),
        call.grid
            .uv_da
            .then(|| g.uv_da.into_pyarray(py).reshape(call.dims(n_da as usize)))
            .transpose()?
            .map(|a| a.into_any()),
        call.grid
            .bias
            .then(|| g.bias.into_pyarray(py).reshape(call.dims(0)))
            .transpose()?
            .map(|a| a.into_any()),
        levels,
    ))
}
