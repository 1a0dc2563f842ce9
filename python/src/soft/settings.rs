//! `Settings`: one render's settings, SoftRas's rasterizer arguments (its names and defaults)
//! parsed into the engine's, with the image size and how faces meet pixels.

use pyo3::prelude::*;
use softvk::raster::gpu::Method;
use softvk::raster::settings::{Alpha, ColorMode, Dist, RasterSettings, Rgb};

use crate::error::{to_py, value_error};

/// The settings of one render: SoftRas's rasterizer arguments, the image size and how faces
/// meet pixels.
#[pyclass(frozen, module = "softvk._native")]
#[derive(Clone)]
pub(crate) struct Settings {
    pub(crate) raster: RasterSettings,
    pub(crate) method: Method,
    pub(crate) silhouettes: bool,
}

fn parse_choice<T: Copy>(what: &str, value: &str, choices: &[(&str, T)]) -> PyResult<T> {
    choices
        .iter()
        .find(|(name, _)| *name == value)
        .map(|(_, v)| *v)
        .ok_or_else(|| {
            let names: Vec<&str> = choices.iter().map(|c| c.0).collect();
            value_error(format!("{what} must be one of {names:?}, got {value:?}"))
        })
}

#[pymethods]
impl Settings {
    /// `Settings(width, height, *, sigma=1e-5, gamma=1e-4, near=1, far=100, eps=1e-3,
    /// dist_eps=1e-4, dist_func='euclidean', aggr_func_rgb='softmax', aggr_func_alpha='prod',
    /// background_color=(0, 0, 0), fill_back=True, texture_type='surface', tile=8,
    /// brute=False, silhouettes=False)`: SoftRas's names and defaults. `tile` is the tiled
    /// rasterizer's tile edge (a multiple of 8); `brute=True` runs SoftRas's
    /// every-face-for-every-pixel loop instead; `silhouettes=True` renders alpha alone (the
    /// same bits as a full render's alpha; RGB is left zero), skipping the depth and colour
    /// work forward and backward.
    #[new]
    #[pyo3(signature = (
        width, height, *, sigma = 1e-5, gamma = 1e-4, near = 1.0, far = 100.0, eps = 1e-3,
        dist_eps = 1e-4, dist_func = "euclidean", aggr_func_rgb = "softmax",
        aggr_func_alpha = "prod", background_color = (0.0, 0.0, 0.0), fill_back = true,
        texture_type = "surface", tile = softvk::raster::gpu::DEFAULT_TILE, brute = false,
        silhouettes = false,
    ))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        width: u32,
        height: u32,
        sigma: f64,
        gamma: f64,
        near: f64,
        far: f64,
        eps: f64,
        dist_eps: f64,
        dist_func: &str,
        aggr_func_rgb: &str,
        aggr_func_alpha: &str,
        background_color: (f64, f64, f64),
        fill_back: bool,
        texture_type: &str,
        tile: u32,
        brute: bool,
        silhouettes: bool,
    ) -> PyResult<Self> {
        let raster = RasterSettings {
            width,
            height,
            sigma,
            gamma,
            near,
            far,
            eps,
            dist_eps,
            dist: parse_choice(
                "dist_func",
                dist_func,
                &[
                    ("euclidean", Dist::Euclidean),
                    ("barycentric", Dist::Barycentric),
                    ("hard", Dist::Hard),
                ],
            )?,
            rgb: parse_choice(
                "aggr_func_rgb",
                aggr_func_rgb,
                &[("softmax", Rgb::Softmax), ("hard", Rgb::Hard)],
            )?,
            alpha: parse_choice(
                "aggr_func_alpha",
                aggr_func_alpha,
                &[
                    ("prod", Alpha::Prod),
                    ("sum", Alpha::Sum),
                    ("hard", Alpha::Hard),
                ],
            )?,
            background: [background_color.0, background_color.1, background_color.2],
            double_sided: fill_back,
            antialias: false,
            color_mode: parse_choice(
                "texture_type",
                texture_type,
                &[
                    ("surface", ColorMode::Surface),
                    ("vertex", ColorMode::Vertex),
                ],
            )?,
        };
        raster.validate().map_err(|e| to_py(e.into()))?;
        let method = if brute {
            Method::Brute
        } else {
            softvk::raster::gpu::Method::check_tile(tile).map_err(to_py)?;
            Method::Tiled { tile }
        };
        Ok(Settings {
            raster,
            method,
            silhouettes,
        })
    }

    /// `(height, width)` of the images.
    #[getter]
    fn shape(&self) -> (u32, u32) {
        (self.raster.height, self.raster.width)
    }
}
