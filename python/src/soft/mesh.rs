//! `render_mesh`: meshes (vertices, shared faces, textures), cameras and lights from Python,
//! with the camera, the lighting and the face set-up run on the device.

use glam::DVec3;
use numpy::{PyReadonlyArray1, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use softvk::camera::{Camera, Projection};
use softvk::lighting::{Directional, Lighting};
use softvk::mesh::Mesh;
use softvk::raster::settings::ColorMode;

use crate::convert::{checked, texture_res, triples};
use crate::error::value_error;
use crate::soft::raster::{Raster, RasterKind, render};
use crate::soft::settings::Settings;

/// Lights from Python: `(ambient intensity, ambient colour, [(intensity, colour, direction)])`.
type PyLighting = (f64, [f64; 3], Vec<(f64, [f64; 3], [f64; 3])>);

/// A camera from Python: `('look_at', eye, at, up, viewing_angle_or_None, scale)` (perspective
/// with the viewing angle in degrees, or orthographic with `scale` when the angle is `None`),
/// or `('projection', P (12 floats, rows), dist_coeffs (5), orig_size)`.
fn camera_from(item: &Bound<'_, PyAny>) -> PyResult<Camera> {
    let kind: String = item.get_item(0)?.extract()?;
    let vec3 = |i: usize| -> PyResult<DVec3> {
        let v: [f64; 3] = item.get_item(i)?.extract()?;
        Ok(DVec3::from(v))
    };
    match kind.as_str() {
        "look_at" => {
            let angle: Option<f64> = item.get_item(4)?.extract()?;
            let scale: f64 = item.get_item(5)?.extract()?;
            Ok(Camera {
                eye: vec3(1)?,
                at: vec3(2)?,
                up: vec3(3)?,
                projection: match angle {
                    Some(viewing_angle_deg) => Projection::Perspective { viewing_angle_deg },
                    None => Projection::Orthographic { scale },
                },
            })
        }
        "projection" => {
            let p: [f64; 12] = item.get_item(1)?.extract()?;
            let dist_coeffs: [f64; 5] = item.get_item(2)?.extract()?;
            let orig_size: f64 = item.get_item(3)?.extract()?;
            Ok(Camera {
                projection: Projection::Matrix {
                    p: [
                        [p[0], p[1], p[2], p[3]],
                        [p[4], p[5], p[6], p[7]],
                        [p[8], p[9], p[10], p[11]],
                    ],
                    dist_coeffs,
                    orig_size,
                },
                ..Camera::default()
            })
        }
        other => Err(value_error(format!(
            "camera kind must be 'look_at' or 'projection', got {other:?}"
        ))),
    }
}

/// `render_mesh(vertices, faces, textures, view_mesh, cameras, lighting, settings)`:
/// `vertices` `[B, V, 3]` float32 (world), `faces` `[F, 3]` int64 shared by the batch,
/// `textures` `[B, F, R², 3]` (surface) or `[B, V, 3]` (vertex) float32 before lighting;
/// view `i` shows mesh `view_mesh[i]` through `cameras[i]` (see [`camera_from`]); `lighting`
/// is `(ambient_intensity, ambient_color, [(intensity, color, direction), ...])`. Lighting,
/// camera and face set-up run in the engine. Returns `(images [views, H, W, 4], raster)`.
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_mesh<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArrayDyn<'py, f32>,
    faces: PyReadonlyArrayDyn<'py, i64>,
    textures: PyReadonlyArrayDyn<'py, f32>,
    view_mesh: PyReadonlyArray1<'py, i64>,
    cameras: Vec<Bound<'py, PyAny>>,
    lighting: PyLighting,
    settings: &Settings,
) -> PyResult<(Bound<'py, PyAny>, Raster)> {
    let (verts, vshape) = checked("vertices", &vertices, &[None, None, Some(3)])?;
    let (batch, nv) = (vshape[0], vshape[1]);
    let (face_idx, fshape) = checked("faces", &faces, &[None, Some(3)])?;
    let nf = fshape[0];
    let mode = settings.raster.color_mode;
    let (tex, tshape) = match mode {
        ColorMode::Surface => checked(
            "textures",
            &textures,
            &[Some(batch), Some(nf), None, Some(3)],
        )?,
        ColorMode::Vertex => checked("textures", &textures, &[Some(batch), Some(nv), Some(3)])?,
    };
    let res = match mode {
        ColorMode::Surface => texture_res(tshape[2])?,
        ColorMode::Vertex => 1,
    };
    let view_mesh = view_mesh
        .as_slice()
        .map_err(|_| value_error("view_mesh is not contiguous".into()))?;
    if view_mesh.len() != cameras.len() {
        return Err(value_error(format!(
            "{} cameras for {} views",
            cameras.len(),
            view_mesh.len()
        )));
    }
    let mut views = Vec::with_capacity(cameras.len());
    for (&m, camera) in view_mesh.iter().zip(&cameras) {
        let m = usize::try_from(m)
            .ok()
            .filter(|&m| m < batch)
            .ok_or_else(|| value_error(format!("a view shows mesh {m} of a batch of {batch}")))?;
        views.push((m, camera_from(camera)?));
    }
    let mut face_list = Vec::with_capacity(nf);
    for f in face_idx.chunks_exact(3) {
        let mut idx = [0u32; 3];
        for (k, &i) in f.iter().enumerate() {
            idx[k] = u32::try_from(i)
                .ok()
                .filter(|&i| (i as usize) < nv)
                .ok_or_else(|| {
                    value_error(format!("face index {i} is outside the {nv} vertices"))
                })?;
        }
        face_list.push(idx);
    }
    let colors_per_mesh = tex.len() / 3 / batch.max(1);
    let meshes: Vec<Mesh> = (0..batch)
        .map(|b| {
            let colors = triples(&tex[b * 3 * colors_per_mesh..(b + 1) * 3 * colors_per_mesh]);
            let (textures, vertex_colors) = match mode {
                ColorMode::Surface => (colors, None),
                ColorMode::Vertex => (vec![[1.0; 3]; nf], Some(colors)),
            };
            Mesh {
                positions: triples(&verts[b * 3 * nv..(b + 1) * 3 * nv]),
                faces: face_list.clone(),
                texture_res: res,
                textures,
                vertex_colors,
            }
        })
        .collect();
    let (ambient, ambient_color, directionals) = lighting;
    let lighting = Lighting {
        ambient_intensity: ambient,
        ambient_color,
        directionals: directionals
            .into_iter()
            .map(|(intensity, color, direction)| Directional {
                intensity,
                color,
                direction,
            })
            .collect(),
    };
    let n_views = views.len();
    if meshes.is_empty() || nf == 0 || n_views == 0 {
        return Err(value_error(format!(
            "nothing to render: {batch} meshes of {nf} faces, {n_views} views"
        )));
    }
    let kind = RasterKind::Mesh {
        batch,
        vertices: nv,
        colors: colors_per_mesh,
        views: n_views,
    };
    render(py, settings, &meshes, &views, &lighting, kind)
}
