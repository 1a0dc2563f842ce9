//! The process's one engine: a [`Context`] and a [`Renderer`], with PyTorch3D's and
//! nvdiffrast's kernels made on their first use, and the rules of its use. It is made on the
//! first call from the environment (`SOFTVK_DEVICE`, `SOFTVK_VALIDATION`, ...) and used by one
//! call at a time ([`with_engine`]: calls queue on its lock, the GIL released while the device
//! works); a forked child never touches its parent's engine ([`forked`]) and gets a clear error
//! instead. `device_name` and `is_forked_child` are its Python face.

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Mutex, MutexGuard};

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use softvk::gpu::{Context, ContextOptions};
use softvk::raster::fragments::gpu::FragmentRasterizer;
use softvk::raster::gpu::Renderer;
use softvk::raster::hard::gpu::HardRasterizer;
use softvk::raster::hard::gpu::texture::TextureSampler;

use crate::error::to_py;

/// The process's engine, made on first use.
pub(crate) struct Engine {
    pub(crate) ctx: Context,
    pub(crate) renderer: Renderer,
    /// PyTorch3D's rasterizer, made on its first use.
    fragments: Mutex<Option<FragmentRasterizer>>,
    /// nvdiffrast's primitives, made on their first use.
    pub(crate) hard: Mutex<Option<HardRasterizer>>,
    /// nvdiffrast's texture sampling, made on its first use.
    pub(crate) texture: Mutex<Option<TextureSampler>>,
}

/// The engine's fragment rasterizer, made on first use.
pub(crate) fn engine_fragments(
    engine: &Engine,
) -> softvk::Result<MutexGuard<'_, Option<FragmentRasterizer>>> {
    let mut cell = engine.fragments.lock().unwrap_or_else(|e| e.into_inner());
    if cell.is_none() {
        *cell = Some(FragmentRasterizer::new(&engine.ctx)?);
    }
    Ok(cell)
}

static ENGINE: Mutex<Option<Engine>> = Mutex::new(None);

/// The process that made [`ENGINE`] (0: none yet). Read before the lock: a child forked while
/// another thread held the lock would wait on it forever.
static OWNER: AtomicU32 = AtomicU32::new(0);

pub(crate) fn forked_error(owner: u32) -> PyErr {
    PyRuntimeError::new_err(format!(
        "softvk: this process ({}) was forked from process {owner}, which had already opened the \
         Vulkan device; a device cannot be used across fork(). Make the first softvk call in \
         the child instead (for a DataLoader, render in the main process or use \
         multiprocessing_context='spawn'; torchrun's ranks are separate processes already)",
        std::process::id()
    ))
}

/// Whether this process is a fork of the one that made the engine.
pub(crate) fn forked() -> Option<u32> {
    let owner = OWNER.load(Ordering::Acquire);
    (owner != 0 && owner != std::process::id()).then_some(owner)
}

/// The engine, made on first use: the lock held for the whole call.
fn engine() -> PyResult<MutexGuard<'static, Option<Engine>>> {
    if let Some(owner) = forked() {
        return Err(forked_error(owner));
    }
    let mut guard = ENGINE.lock().map_err(|_| {
        PyRuntimeError::new_err("softvk: a previous call panicked inside the engine")
    })?;
    if guard.is_none() {
        let ctx = Context::new(&ContextOptions::from_env()).map_err(to_py)?;
        let renderer = Renderer::new(&ctx).map_err(to_py)?;
        *guard = Some(Engine {
            ctx,
            renderer,
            fragments: Mutex::new(None),
            hard: Mutex::new(None),
            texture: Mutex::new(None),
        });
        OWNER.store(std::process::id(), Ordering::Release);
    }
    Ok(guard)
}

/// Runs `f` on the engine with the GIL released, then checks the validation layer's log.
pub(crate) fn with_engine<T: Send>(
    py: Python<'_>,
    f: impl FnOnce(&Engine) -> softvk::Result<T> + Send,
) -> PyResult<T> {
    py.detach(|| {
        let guard = engine()?;
        let engine = guard.as_ref().expect("engine() made it");
        let out = f(engine).map_err(to_py)?;
        engine.ctx.check_validation().map_err(to_py)?;
        Ok(out)
    })
}

/// The name of the Vulkan device softvk renders on (opening it if need be).
#[pyfunction]
pub(crate) fn device_name(py: Python<'_>) -> PyResult<String> {
    with_engine(py, |engine| Ok(engine.ctx.info().name.clone()))
}

/// Whether this process is a fork of the one that opened the device (then every call fails).
#[pyfunction]
pub(crate) fn is_forked_child() -> bool {
    forked().is_some()
}
