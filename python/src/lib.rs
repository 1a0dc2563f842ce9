//! `softvk._native`: the engine as Python sees it. The Python package (`softvk.torch`,
//! `softvk.soft_renderer`) wraps these calls in autograd functions and SoftRas's classes; this
//! module only moves arrays in and out of the engine.
//!
//! - One engine (a [`Context`] and a [`Renderer`]) per process, made on first use from the
//!   environment (`SOFTVK_DEVICE`, `SOFTVK_VALIDATION`, ...), and used by one call at a time:
//!   calls from several threads queue on its lock, with the GIL released while the device works.
//! - A forked child never touches its parent's engine (a Vulkan device does not survive a fork):
//!   it gets a clear error instead, and drops what it inherited without freeing it.
//! - [`rasterize`] is SoftRas's `soft_rasterize`: faces already in screen space, rendered with
//!   the identity camera ([`Camera::screen_space`]) and no lighting, so the engine's backward to
//!   world positions is the gradient with respect to the screen-space face vertices.
//! - [`render_mesh`] keeps the camera, the lighting and the face set-up on the device: vertices,
//!   faces and cameras in, images out.
//! - [`fragments`] is PyTorch3D's rasterizer (`softvk.pytorch3d`): the fragment kernels and
//!   their f64 twin, on packed projected faces.
//! - `nv_*` ([`nvdiffrast`]) are nvdiffrast's primitives (`softvk.nvdiffrast.torch`): hard
//!   rasterization with depth peeling, `interpolate` and `antialias`, forward and backward.
//! - [`reference_rasterize`] and [`reference_rasterize_grad`] are the f64 CPU twin of
//!   [`rasterize`] and its backward: the oracle of the tests, and what `soft_rasterize` computes
//!   for float64 tensors.
//! - A training loop renders the same shapes through the same views every iteration: when a
//!   render's [`Raster`] is dropped (its backward done), its scene is kept as a spare, and the
//!   next render of the same key (topology, views, lights, settings) writes its new vertices
//!   and textures into it ([`GpuScene::update_meshes`]) instead of making every buffer again;
//!   the buffers of its backward are kept with it ([`GradBuffers::fits`]), since on a CPU device
//!   new device memory costs a page fault per page at its first write.
//!
//! This file registers the module; the code lies by role: [`engine`] (the process's engine,
//! its lock and the fork rule), [`error`] (softvk's errors as Python exceptions), [`scene`]
//! (the cache of spare scenes), [`soft`] (SoftRas's rasterizer: `Settings`, `Raster`,
//! `rasterize`, `render_mesh` and the f64 twin), [`fragments`] (PyTorch3D's), [`nvdiffrast`]
//! (nvdiffrast's primitives and texture sampling), [`convert`] (numpy arrays in and out) and
//! [`io`] (image files).
//!
//! [`Context`]: softvk::gpu::Context
//! [`Renderer`]: softvk::raster::gpu::Renderer
//! [`rasterize`]: soft::faces::rasterize
//! [`Camera::screen_space`]: softvk::camera::Camera::screen_space
//! [`render_mesh`]: soft::mesh::render_mesh
//! [`reference_rasterize`]: soft::faces::reference_rasterize
//! [`reference_rasterize_grad`]: soft::faces::reference_rasterize_grad
//! [`Raster`]: soft::raster::Raster
//! [`GpuScene::update_meshes`]: softvk::raster::gpu::GpuScene::update_meshes
//! [`GradBuffers::fits`]: softvk::raster::backward::GradBuffers::fits

use pyo3::prelude::*;

mod convert;
mod engine;
mod error;
mod fragments;
mod io;
mod nvdiffrast;
mod scene;
mod soft;

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<soft::settings::Settings>()?;
    m.add_class::<soft::raster::Raster>()?;
    m.add_function(wrap_pyfunction!(soft::faces::rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(soft::faces::reference_rasterize, m)?)?;
    m.add_function(wrap_pyfunction!(soft::faces::reference_rasterize_grad, m)?)?;
    m.add_function(wrap_pyfunction!(soft::mesh::render_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(engine::device_name, m)?)?;
    m.add_function(wrap_pyfunction!(scene::release_cached_scenes, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_exr, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_exr, m)?)?;
    m.add_function(wrap_pyfunction!(io::read_rgb, m)?)?;
    m.add_function(wrap_pyfunction!(io::write_png, m)?)?;
    m.add_function(wrap_pyfunction!(engine::is_forked_child, m)?)?;
    fragments::register(m)?;
    nvdiffrast::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
