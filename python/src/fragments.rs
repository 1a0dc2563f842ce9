//! PyTorch3D's rasterizer (`softvk.pytorch3d`): the fragment kernels' forward and backward on
//! arrays, and their f64 twin for float64 tensors. Faces arrive packed and projected, as
//! PyTorch3D's `rasterize_meshes` hands them to its C++: `face_verts [F, 3, 3]`, each mesh's
//! `(first face, face count)`, and for faces cut by the near plane the other half of each.

use std::sync::Mutex;

use numpy::ndarray::{ArrayView, IxDyn};
use numpy::{Element, IntoPyArray, PyArray, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use softvk::gpu::{Buffer, MemoryKind};
use softvk::raster::fragments::gpu::{FragmentPlan, SlotParts};
use softvk::raster::fragments::{self, FragmentSettings};

use crate::convert::checked;
use crate::engine::{engine_fragments, forked, with_engine};
use crate::error::{to_py, value_error};

/// Host-visible output buffers of earlier forwards whose arrays Python has dropped, kept for the
/// next forward: on a CPU device a fresh buffer costs a page fault per page at its first write,
/// and copying the outputs into fresh arrays would cost that and the copy.
static POOL: Mutex<Vec<Buffer>> = Mutex::new(Vec::new());

/// Spare buffers kept at most.
const POOL_KEEP: usize = 4;

/// The memory of one forward's output arrays: the buffer the device wrote them into. The arrays
/// are views of it with this object as their base; when the last is dropped, the buffer goes
/// back to [`POOL`].
#[pyclass(module = "softvk._native", frozen)]
pub struct FragmentMemory {
    buffer: Mutex<Option<Buffer>>,
}

impl Drop for FragmentMemory {
    fn drop(&mut self) {
        let buffer = self
            .buffer
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        if let Some(buffer) = buffer {
            if forked().is_some() {
                // A forked child must not free its parent's device memory.
                std::mem::forget(buffer);
                return;
            }
            let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
            pool.push(buffer);
            if pool.len() > POOL_KEEP {
                // Keep the largest ones.
                pool.sort_by_key(|b| std::cmp::Reverse(b.size()));
                pool.truncate(POOL_KEEP);
            }
        }
    }
}

/// Frees the spare output buffers (`release_cached_scenes`).
pub fn release_pool() {
    POOL.lock().unwrap_or_else(|e| e.into_inner()).clear();
}

/// A spare buffer of at least `bytes` (the smallest that fits), or none.
fn pooled(bytes: u64) -> Option<Buffer> {
    let mut pool = POOL.lock().unwrap_or_else(|e| e.into_inner());
    let best = pool
        .iter()
        .enumerate()
        .filter(|(_, b)| b.size() >= bytes)
        .min_by_key(|(_, b)| b.size())
        .map(|(i, _)| i)?;
    Some(pool.swap_remove(best))
}

/// A numpy array of `shape` viewing `memory`'s buffer from byte `at`.
fn view<'py, T: Element>(
    memory: &Bound<'py, FragmentMemory>,
    at: u64,
    shape: &[usize],
) -> PyResult<Bound<'py, PyAny>> {
    let guard = memory
        .get()
        .buffer
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    let buffer = guard.as_ref().expect("a forward's memory holds its buffer");
    let bytes = buffer
        .mapped()
        .ok_or_else(|| value_error("fragment outputs are not host-mapped".into()))?;
    let len: usize = shape.iter().product();
    let end = at as usize + len * std::mem::size_of::<T>();
    assert!(end <= bytes.len(), "fragment output view past its buffer");
    let ptr = bytes[at as usize..].as_ptr().cast::<T>();
    assert!(ptr.is_aligned(), "fragment output view misaligned");
    // SAFETY: `ptr` points at `len` initialized, aligned `T`s inside the buffer's mapping
    // (checked above), which stays mapped and unchanged while `memory` lives: the buffer is
    // returned to the pool only when `memory` is dropped, and `memory` is the array's base.
    let array = unsafe { ArrayView::from_shape_ptr(IxDyn(shape), ptr) };
    // SAFETY: as above; the array keeps `memory` alive.
    let py_array =
        unsafe { PyArray::<T, IxDyn>::borrow_from_array(&array, memory.clone().into_any()) };
    Ok(py_array.into_any())
}

/// `(height, width, blur_radius, faces_per_pixel, perspective_correct, clip_barycentric_coords,
/// cull_backfaces)`: PyTorch3D's rasterization arguments that change the result.
type PySettings = (u32, u32, f64, usize, bool, bool, bool);

fn settings(s: PySettings) -> FragmentSettings {
    FragmentSettings {
        height: s.0,
        width: s.1,
        blur_radius: s.2,
        faces_per_pixel: s.3,
        perspective_correct: s.4,
        clip_barycentric_coords: s.5,
        cull_backfaces: s.6,
    }
}

/// The four output arrays, `[N, H, W, K]` (and `[N, H, W, K, 3]`).
type Outputs<'py> = (
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
    Bound<'py, PyAny>,
);

fn shape(meshes: usize, s: &FragmentSettings) -> [usize; 4] {
    [
        meshes,
        s.height as usize,
        s.width as usize,
        s.faces_per_pixel,
    ]
}

fn neighbor_list(
    neighbors: &Option<PyReadonlyArrayDyn<'_, i64>>,
    faces: usize,
) -> PyResult<Option<Vec<i64>>> {
    neighbors
        .as_ref()
        .map(|a| checked("neighbors", a, &[Some(faces)]).map(|(d, _)| d.to_vec()))
        .transpose()
}

/// `rasterize_fragments(face_verts, meshes, neighbors, settings)`: PyTorch3D's `rasterize_meshes` on the
/// device: `(pix_to_face int64, zbuf, bary_coords, dists)` as `[N, H, W, K]` arrays (the
/// barycentrics `[N, H, W, K, 3]`).
#[pyfunction]
pub fn rasterize_fragments<'py>(
    py: Python<'py>,
    face_verts: PyReadonlyArrayDyn<'py, f32>,
    meshes: Vec<(usize, usize)>,
    neighbors: Option<PyReadonlyArrayDyn<'py, i64>>,
    settings_in: PySettings,
) -> PyResult<Outputs<'py>> {
    let (fv, fshape) = checked("face_verts", &face_verts, &[None, Some(3), Some(3)])?;
    let s = settings(settings_in);
    let nb = neighbor_list(&neighbors, fshape[0])?;
    let fv = fv.to_vec();
    let buffer = with_engine(py, |engine| {
        let plan = FragmentPlan::new(&engine.ctx, fshape[0], &meshes, &s)?;
        let bytes = SlotParts::new(plan.slots()).total;
        let buffer = match pooled(bytes) {
            Some(b) => b,
            None => engine
                .ctx
                .create_buffer("fragments", bytes, MemoryKind::Readback)?,
        };
        let mut cell = engine_fragments(engine)?;
        let raster = cell.as_mut().expect("made by engine_fragments");
        match raster.rasterize_to(&engine.ctx, &plan, &fv, nb.as_deref(), &buffer) {
            Ok(()) => Ok((buffer, plan.slots())),
            Err(e) => {
                POOL.lock().unwrap_or_else(|e| e.into_inner()).push(buffer);
                Err(e)
            }
        }
    })?;
    let (buffer, slots) = buffer;
    let memory = Bound::new(
        py,
        FragmentMemory {
            buffer: Mutex::new(Some(buffer)),
        },
    )?;
    let [p, z, d, b] = SlotParts::new(slots).at;
    let dims = shape(meshes.len(), &s);
    let mut bary_dims = dims.to_vec();
    bary_dims.push(3);
    Ok((
        view::<i64>(&memory, p, &dims)?,
        view::<f32>(&memory, z, &dims)?,
        view::<f32>(&memory, b, &bary_dims)?,
        view::<f32>(&memory, d, &dims)?,
    ))
}

/// The upstream gradients' checks: `[N, H, W, K]` (and `[.., 3]`), C-contiguous.
fn upstream<'a, T: numpy::Element>(
    name: &str,
    a: &'a PyReadonlyArrayDyn<'_, T>,
    dims: [usize; 4],
    last: Option<usize>,
) -> PyResult<&'a [T]> {
    let mut want: Vec<Option<usize>> = dims.iter().map(|&d| Some(d)).collect();
    if let Some(l) = last {
        want.push(Some(l));
    }
    checked(name, a, &want).map(|(d, _)| d)
}

/// `rasterize_fragments_grad(face_verts, meshes, pix_to_face, grad_zbuf, grad_bary, grad_dists,
/// settings)`: the backward of [`rasterize_fragments`] to `face_verts`, `[F, 3, 3]`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn rasterize_fragments_grad<'py>(
    py: Python<'py>,
    face_verts: PyReadonlyArrayDyn<'py, f32>,
    meshes: Vec<(usize, usize)>,
    pix_to_face: PyReadonlyArrayDyn<'py, i64>,
    grad_zbuf: PyReadonlyArrayDyn<'py, f32>,
    grad_bary: PyReadonlyArrayDyn<'py, f32>,
    grad_dists: PyReadonlyArrayDyn<'py, f32>,
    settings_in: PySettings,
) -> PyResult<Bound<'py, PyAny>> {
    let (fv, fshape) = checked("face_verts", &face_verts, &[None, Some(3), Some(3)])?;
    let s = settings(settings_in);
    let dims = shape(meshes.len(), &s);
    let p2f = upstream("pix_to_face", &pix_to_face, dims, None)?.to_vec();
    let gz = upstream("grad_zbuf", &grad_zbuf, dims, None)?.to_vec();
    let gb = upstream("grad_bary", &grad_bary, dims, Some(3))?.to_vec();
    let gd = upstream("grad_dists", &grad_dists, dims, None)?.to_vec();
    let fv = fv.to_vec();
    let mut grad = vec![0f32; fv.len()];
    with_engine(py, |engine| {
        let plan = FragmentPlan::new(&engine.ctx, fshape[0], &meshes, &s)?;
        let mut cell = engine_fragments(engine)?;
        let raster = cell.as_mut().expect("made by engine_fragments");
        raster.rasterize_grad_into(&engine.ctx, &plan, &fv, &p2f, &gz, &gb, &gd, &mut grad)
    })?;
    Ok(grad.into_pyarray(py).reshape([fshape[0], 3, 3])?.into_any())
}

fn faces64(fv: &[f64]) -> Vec<[[f64; 3]; 3]> {
    fv.chunks_exact(9)
        .map(|c| [[c[0], c[1], c[2]], [c[3], c[4], c[5]], [c[6], c[7], c[8]]])
        .collect()
}

/// `reference_fragments(...)`: as [`rasterize_fragments`], by the f64 twin (float64 arrays out; what
/// `softvk.pytorch3d` runs for float64 tensors).
#[pyfunction]
pub fn reference_fragments<'py>(
    py: Python<'py>,
    face_verts: PyReadonlyArrayDyn<'py, f64>,
    meshes: Vec<(usize, usize)>,
    neighbors: Option<PyReadonlyArrayDyn<'py, i64>>,
    settings_in: PySettings,
) -> PyResult<Outputs<'py>> {
    let (fv, fshape) = checked("face_verts", &face_verts, &[None, Some(3), Some(3)])?;
    let s = settings(settings_in);
    fragments::check_meshes(fshape[0], &meshes).map_err(to_py)?;
    fragments::check_finite(fv).map_err(to_py)?;
    let nb = neighbor_list(&neighbors, fshape[0])?;
    let fv = faces64(fv);
    let out = py.detach(|| fragments::rasterize(&fv, &meshes, nb.as_deref(), &s));
    let dims = shape(meshes.len(), &s);
    let [a, b, c, d] = dims;
    Ok((
        out.pix_to_face.into_pyarray(py).reshape(dims)?.into_any(),
        out.zbuf.into_pyarray(py).reshape(dims)?.into_any(),
        out.bary_coords
            .into_flattened()
            .into_pyarray(py)
            .reshape([a, b, c, d, 3])?
            .into_any(),
        out.dists.into_pyarray(py).reshape(dims)?.into_any(),
    ))
}

/// `reference_fragments_grad(...)`: as [`rasterize_fragments_grad`], by the f64 twin.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn reference_fragments_grad<'py>(
    py: Python<'py>,
    face_verts: PyReadonlyArrayDyn<'py, f64>,
    meshes: Vec<(usize, usize)>,
    pix_to_face: PyReadonlyArrayDyn<'py, i64>,
    grad_zbuf: PyReadonlyArrayDyn<'py, f64>,
    grad_bary: PyReadonlyArrayDyn<'py, f64>,
    grad_dists: PyReadonlyArrayDyn<'py, f64>,
    settings_in: PySettings,
) -> PyResult<Bound<'py, PyAny>> {
    let (fv, fshape) = checked("face_verts", &face_verts, &[None, Some(3), Some(3)])?;
    let s = settings(settings_in);
    fragments::check_meshes(fshape[0], &meshes).map_err(to_py)?;
    fragments::check_finite(fv).map_err(to_py)?;
    let dims = shape(meshes.len(), &s);
    let p2f = upstream("pix_to_face", &pix_to_face, dims, None)?;
    fragments::check_pix_to_face(p2f, fshape[0]).map_err(to_py)?;
    let gz = upstream("grad_zbuf", &grad_zbuf, dims, None)?;
    let gb: Vec<[f64; 3]> = upstream("grad_bary", &grad_bary, dims, Some(3))?
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    let gd = upstream("grad_dists", &grad_dists, dims, None)?;
    let fv = faces64(fv);
    let grad = fragments::rasterize_grad(&fv, p2f, gz, &gb, gd, &s);
    let flat: Vec<f64> = grad.into_iter().flatten().flatten().collect();
    Ok(flat.into_pyarray(py).reshape([fshape[0], 3, 3])?.into_any())
}

/// `fragments_time_passes()`: from now on, the fragment rasterizer times its passes with GPU
/// timestamps (benchmarks read them with [`fragments_pass_times`]).
#[pyfunction]
pub fn fragments_time_passes(py: Python<'_>) -> PyResult<()> {
    with_engine(py, |engine| {
        let mut cell = engine_fragments(engine)?;
        cell.as_mut()
            .expect("made by engine_fragments")
            .time_passes(&engine.ctx)
    })
}

/// `fragments_pass_times()`: `(name, depth, ms)` of every pass timed since the last call.
#[pyfunction]
pub fn fragments_pass_times(py: Python<'_>) -> PyResult<Vec<(String, u32, f64)>> {
    with_engine(py, |engine| {
        let mut cell = engine_fragments(engine)?;
        Ok(cell
            .as_mut()
            .expect("made by engine_fragments")
            .take_timings()
            .into_iter()
            .map(|t| (t.name, t.depth, t.ms))
            .collect())
    })
}

/// Registers the functions on the native module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<FragmentMemory>()?;
    m.add_function(wrap_pyfunction!(rasterize_fragments, m)?)?;
    m.add_function(wrap_pyfunction!(rasterize_fragments_grad, m)?)?;
    m.add_function(wrap_pyfunction!(reference_fragments, m)?)?;
    m.add_function(wrap_pyfunction!(reference_fragments_grad, m)?)?;
    m.add_function(wrap_pyfunction!(fragments_time_passes, m)?)?;
    m.add_function(wrap_pyfunction!(fragments_pass_times, m)?)?;
    Ok(())
}
