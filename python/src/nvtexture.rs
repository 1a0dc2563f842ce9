//! nvdiffrast's `texture` and `texture_construct_mip` (`softvk.nvdiffrast.torch`), forward and
//! backward, on the engine's [`TextureSampler`]. The Python module checks the arguments first
//! and gives nvdiffrast's errors; these functions check again what the engine would otherwise
//! read out of bounds, and copy the inputs before the GIL is released.
//!
//! A call's mip stack is one of three (nvdiffrast's): built here from `tex` (a mipmap mode with
//! no `mip`), `tex` over the levels a [`NvTextureMip`] holds (its gradients carried into `tex`),
//! or `tex` over a list of the caller's levels (each level's gradient its own).

use std::sync::MutexGuard;

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use softvk::gpu::Context;
use softvk::raster::hard::gpu::texture::{
    Levels, Lookup, Lookups, TexLayout, TexMode, TextureSampler,
};
use softvk::raster::hard::texture::Filter;

use crate::convert::checked;
use crate::engine::{Engine, with_engine};
use crate::error::{to_py, value_error};

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

/// `texture_construct_mip(tex, max_mip_level)`'s result: the mip levels below a texture of one
/// shape, built once for a texture that stays the same between calls.
#[pyclass(frozen, module = "softvk._native")]
pub struct NvTextureMip {
    /// The shape of the texture it was built from: `[B, H, W, C]`, or a cube map's
    /// `[B, 6, S, S, C]`.
    shape: Vec<usize>,
    /// Whether it is a cube map's.
    cube: bool,
    /// The stack's layout (the base included).
    layout: TexLayout,
    /// Levels 1 and below, as the stack lays them out.
    below: Vec<f32>,
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
fn texture_dims<'a>(
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

fn u32_of(what: &str, v: usize) -> PyResult<u32> {
    u32::try_from(v).map_err(|_| value_error(format!("{what} {v} is too large")))
}

fn with_mips(dims: [usize; 4], max_mip_level: Option<u32>) -> PyResult<TexLayout> {
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
fn level_shape(shape: &[usize], layout: &TexLayout, level: u32) -> Vec<usize> {
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

/// Registers the functions on the native module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NvTextureMip>()?;
    m.add_function(wrap_pyfunction!(nv_texture_construct_mip, m)?)?;
    m.add_function(wrap_pyfunction!(nv_texture, m)?)?;
    m.add_function(wrap_pyfunction!(nv_texture_grad, m)?)?;
    Ok(())
}
