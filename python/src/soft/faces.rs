//! SoftRas's `soft_rasterize` on faces already in screen space ([`FaceInputs`]): [`rasterize`]
//! on the engine, rendered with the identity camera and no lighting, and its f64 CPU twin
//! [`reference_rasterize`] / [`reference_rasterize_grad`], the tests' oracle and what
//! `soft_rasterize` computes for float64 tensors.

use glam::DVec3;
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::PyTuple;
use softvk::camera::Camera;
use softvk::lighting::Lighting;
use softvk::mesh::Mesh;
use softvk::raster::settings::ColorMode;
use softvk::raster::{reference, reference_grad};

use crate::convert::{checked, images_array, texture_res, triples};
use crate::error::{to_py, value_error};
use crate::soft::raster::{Raster, RasterKind, render};
use crate::soft::settings::Settings;

/// SoftRas's `face_vertices` `[B, F, 3, 3]` and `textures` (`[B, F, R², 3]` surface, `[B, F, 3,
/// 3]` vertex), checked: one mesh a batch element, three vertices a face (face `j` = vertices
/// `3j, 3j + 1, 3j + 2`).
struct FaceInputs<'a, T> {
    vertices: &'a [T],
    textures: &'a [T],
    batch: usize,
    faces: usize,
    /// Colours a face: R² texels, or 3 corners.
    per_face: usize,
    texture_res: u32,
    mode: ColorMode,
}

impl<'a, T: numpy::Element + Copy> FaceInputs<'a, T> {
    fn new(
        face_vertices: &'a PyReadonlyArrayDyn<'_, T>,
        textures: &'a PyReadonlyArrayDyn<'_, T>,
        mode: ColorMode,
    ) -> PyResult<Self> {
        let (vertices, shape) = checked(
            "face_vertices",
            face_vertices,
            &[None, None, Some(3), Some(3)],
        )?;
        let (batch, faces) = (shape[0], shape[1]);
        let (textures, tshape) = checked(
            "textures",
            textures,
            &[Some(batch), Some(faces), None, Some(3)],
        )?;
        let per_face = tshape[2];
        let texture_res = match mode {
            ColorMode::Surface => texture_res(per_face)?,
            ColorMode::Vertex if per_face == 3 => 1,
            ColorMode::Vertex => {
                return Err(value_error(format!(
                    "vertex textures need 3 colours a face, got {per_face}"
                )));
            }
        };
        if batch == 0 || faces == 0 {
            return Err(value_error(format!(
                "nothing to render: {batch} meshes of {faces} faces"
            )));
        }
        Ok(FaceInputs {
            vertices,
            textures,
            batch,
            faces,
            per_face,
            texture_res,
            mode,
        })
    }

    fn face_list(&self) -> Vec<[u32; 3]> {
        (0..self.faces as u32)
            .map(|j| [3 * j, 3 * j + 1, 3 * j + 2])
            .collect()
    }

    /// Batch element `b`: its vertex positions, and its colours as (texels, vertex colours).
    #[allow(clippy::type_complexity)]
    fn mesh_parts(&self, b: usize, white: T) -> (Vec<[T; 3]>, Vec<[T; 3]>, Option<Vec<[T; 3]>>) {
        let (v, t) = (9 * self.faces, 3 * self.per_face * self.faces);
        let positions = triples(&self.vertices[b * v..(b + 1) * v]);
        let colors = triples(&self.textures[b * t..(b + 1) * t]);
        match self.mode {
            ColorMode::Surface => (positions, colors, None),
            ColorMode::Vertex => (positions, vec![[white; 3]; self.faces], Some(colors)),
        }
    }
}

impl FaceInputs<'_, f32> {
    fn meshes(&self) -> Vec<Mesh> {
        let faces = self.face_list();
        (0..self.batch)
            .map(|b| {
                let (positions, textures, vertex_colors) = self.mesh_parts(b, 1.0);
                Mesh {
                    positions,
                    faces: faces.clone(),
                    texture_res: self.texture_res,
                    textures,
                    vertex_colors,
                }
            })
            .collect()
    }
}

impl FaceInputs<'_, f64> {
    fn meshes_f64(&self) -> Vec<reference::MeshF64> {
        let faces = self.face_list();
        (0..self.batch)
            .map(|b| {
                let (positions, textures, vertex_colors) = self.mesh_parts(b, 1.0);
                reference::MeshF64 {
                    positions: positions.into_iter().map(DVec3::from).collect(),
                    faces: faces.clone(),
                    texture_res: self.texture_res,
                    textures,
                    vertex_colors,
                }
            })
            .collect()
    }
}

/// `rasterize(face_vertices, textures, settings) -> (images, raster)`: SoftRas's
/// `soft_rasterize`. `face_vertices` `[B, F, 3, 3]` float32 in screen space (x, y, depth);
/// `textures` `[B, F, R², 3]` (surface) or `[B, F, 3, 3]` (vertex), float32, not lit. Returns
/// the RGBA images `[B, H, W, 4]` (row 0 at the top) and the [`Raster`] that differentiates
/// them.
#[pyfunction]
pub(crate) fn rasterize<'py>(
    py: Python<'py>,
    face_vertices: PyReadonlyArrayDyn<'py, f32>,
    textures: PyReadonlyArrayDyn<'py, f32>,
    settings: &Settings,
) -> PyResult<(Bound<'py, PyAny>, Raster)> {
    let inputs = FaceInputs::new(&face_vertices, &textures, settings.raster.color_mode)?;
    let (batch, faces, per_face) = (inputs.batch, inputs.faces, inputs.per_face);
    let meshes = inputs.meshes();
    let views: Vec<(usize, Camera)> = (0..batch).map(|b| (b, Camera::screen_space())).collect();
    let kind = RasterKind::Faces {
        batch,
        faces,
        per_face,
    };
    render(py, settings, &meshes, &views, &Lighting::unlit(), kind)
}

/// `reference_rasterize(face_vertices, textures, settings)`: the f64 CPU twin of
/// [`rasterize`] (float64 arrays in and out): the oracle softvk's kernels are tested against.
#[pyfunction]
pub(crate) fn reference_rasterize<'py>(
    py: Python<'py>,
    face_vertices: PyReadonlyArrayDyn<'py, f64>,
    textures: PyReadonlyArrayDyn<'py, f64>,
    settings: &Settings,
) -> PyResult<Bound<'py, PyAny>> {
    let inputs = FaceInputs::new(&face_vertices, &textures, settings.raster.color_mode)?;
    let (batch, s) = (inputs.batch, settings.raster);
    let meshes = inputs.meshes_f64();
    let images = py.detach(|| -> PyResult<Vec<f64>> {
        let mut out = Vec::with_capacity(batch * (s.width * s.height) as usize * 4);
        for mesh in &meshes {
            let image =
                reference::render_f64(mesh, &Camera::screen_space(), &Lighting::unlit(), &s)
                    .map_err(|e| to_py(e.into()))?;
            out.extend(image.into_iter().flatten());
        }
        Ok(out)
    })?;
    images_array(py, images, (batch, s.height as usize, s.width as usize))
}

/// `reference_rasterize_grad(face_vertices, textures, settings, grad_images)`: the f64 CPU
/// twin's backward of [`reference_rasterize`] (float64 throughout): dL/d(face vertices)
/// `[B, F, 3, 3]` and dL/d(textures) (their shape) given dL/d(images) `[B, H, W, 4]`. With
/// [`reference_rasterize`] it is what `soft_rasterize` computes for float64 tensors, as SoftRas's
/// kernels compute doubles in double (`torch.autograd.gradcheck`).
#[pyfunction]
pub(crate) fn reference_rasterize_grad<'py>(
    py: Python<'py>,
    face_vertices: PyReadonlyArrayDyn<'py, f64>,
    textures: PyReadonlyArrayDyn<'py, f64>,
    settings: &Settings,
    grad_images: PyReadonlyArrayDyn<'py, f64>,
) -> PyResult<Bound<'py, PyTuple>> {
    let inputs = FaceInputs::new(&face_vertices, &textures, settings.raster.color_mode)?;
    let (batch, faces, per_face, s) =
        (inputs.batch, inputs.faces, inputs.per_face, settings.raster);
    let (height, width) = (s.height as usize, s.width as usize);
    let (d_image, _) = checked(
        "grad_images",
        &grad_images,
        &[Some(batch), Some(height), Some(width), Some(4)],
    )?;
    let d_image: &[[f64; 4]] = bytemuck::cast_slice(d_image);
    let meshes = inputs.meshes_f64();
    let (positions, colors) = py.detach(|| -> PyResult<(Vec<f64>, Vec<f64>)> {
        let (mut positions, mut colors) = (Vec::new(), Vec::new());
        for (b, mesh) in meshes.iter().enumerate() {
            let upstream = &d_image[b * height * width..(b + 1) * height * width];
            let g = reference_grad::grad_f64(
                mesh,
                &[Camera::screen_space()],
                &Lighting::unlit(),
                &s,
                upstream,
            )
            .map_err(|e| to_py(e.into()))?;
            positions.extend(g.positions.into_iter().flatten());
            colors.extend(g.colors.into_iter().flatten());
        }
        Ok((positions, colors))
    })?;
    let d_pos = positions
        .into_pyarray(py)
        .reshape([batch, faces, 3, 3])?
        .into_any();
    let d_tex = colors
        .into_pyarray(py)
        .reshape([batch, faces, per_face, 3])?
        .into_any();
    PyTuple::new(py, [d_pos, d_tex])
}
