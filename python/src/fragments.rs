//! PyTorch3D's rasterizer (`softvk.pytorch3d`): the fragment kernels' forward and backward on
//! arrays, and their f64 twin for float64 tensors. Faces arrive packed and projected, as
//! PyTorch3D's `rasterize_meshes` hands them to its C++: `face_verts [F, 3, 3]`, each mesh's
//! `(first face, face count)`, and for faces cut by the near plane the other half of each.

use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use softvk::raster::fragments::gpu::{FragmentPlan, HostFragments};
use softvk::raster::fragments::{self, FragmentSettings};

use super::{checked, engine_fragments, value_error, with_engine};

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
    let n = meshes.len() * s.height as usize * s.width as usize * s.faces_per_pixel;
    let mut pix_to_face = vec![0i64; n];
    let mut zbuf = vec![0f32; n];
    let mut dists = vec![0f32; n];
    let mut bary = vec![0f32; 3 * n];
    with_engine(py, |engine| {
        let plan = FragmentPlan::new(&engine.ctx, fshape[0], &meshes, &s)?;
        let mut cell = engine_fragments(engine)?;
        let raster = cell.as_mut().expect("made by engine_fragments");
        raster.rasterize_into(
            &engine.ctx,
            &plan,
            &fv,
            nb.as_deref(),
            HostFragments {
                pix_to_face: &mut pix_to_face,
                zbuf: &mut zbuf,
                dists: &mut dists,
                bary_coords: &mut bary,
            },
        )
    })?;
    let dims = shape(meshes.len(), &s);
    let [a, b, c, d] = dims;
    Ok((
        pix_to_face.into_pyarray(py).reshape(dims)?.into_any(),
        zbuf.into_pyarray(py).reshape(dims)?.into_any(),
        bary.into_pyarray(py).reshape([a, b, c, d, 3])?.into_any(),
        dists.into_pyarray(py).reshape(dims)?.into_any(),
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

fn check_meshes(meshes: &[(usize, usize)], faces: usize) -> PyResult<()> {
    let mut end = 0;
    for &(first, count) in meshes {
        if first < end || first.saturating_add(count) > faces {
            return Err(value_error(format!(
                "mesh faces [{first}, {}) overlap another mesh's or pass the {faces} faces",
                first.saturating_add(count)
            )));
        }
        end = first + count;
    }
    Ok(())
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
    check_meshes(&meshes, fshape[0])?;
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
    check_meshes(&meshes, fshape[0])?;
    let dims = shape(meshes.len(), &s);
    let p2f = upstream("pix_to_face", &pix_to_face, dims, None)?;
    if let Some(bad) = p2f.iter().find(|&&f| f < -1 || f >= fshape[0] as i64) {
        return Err(value_error(format!(
            "pix_to_face holds {bad}, not a face of {}",
            fshape[0]
        )));
    }
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
    m.add_function(wrap_pyfunction!(rasterize_fragments, m)?)?;
    m.add_function(wrap_pyfunction!(rasterize_fragments_grad, m)?)?;
    m.add_function(wrap_pyfunction!(reference_fragments, m)?)?;
    m.add_function(wrap_pyfunction!(reference_fragments_grad, m)?)?;
    m.add_function(wrap_pyfunction!(fragments_time_passes, m)?)?;
    m.add_function(wrap_pyfunction!(fragments_pass_times, m)?)?;
    Ok(())
}
