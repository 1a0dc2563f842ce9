//! Triangle meshes as the soft rasterizer consumes them: positions, triangles and SoftRas-style
//! per-face R×R textures (or per-vertex colours), loaded from OBJ/MTL or generated for tests.
//!
//! This module holds the [`Mesh`], the invariants every renderer relies on
//! ([`Mesh::validate`]) and what can be wrong with a mesh ([`MeshError`]). Its stages sit
//! beside it, each in its own file:
//! - `obj`: the OBJ loader behind [`Mesh::load_obj`], SoftRas's `load_obj.py` in file order;
//! - `mtl`: the MTL files an OBJ names, read for tobj and checked before it would panic;
//! - `texture`: `map_Kd` images sampled into per-face texels ([`texel_center_barycentric`]);
//! - `generate`: meshes made in memory ([`Mesh::icosphere`], [`Mesh::cuboid`]) and midpoint
//!   subdivision ([`Mesh::subdivided`], [`subdivide_faces`]).
//!
//! What can be wrong with a mesh ([`MeshError`], [`Location`]) is defined in softvk-gpu's
//! `error::mesh`, beside the error type that wraps it, and re-exported here; apart from it this
//! module imports nothing of softvk.

mod generate;
mod mtl;
mod obj;
mod texture;

use std::path::Path;

use glam::DVec3;

use crate::error::mesh::shown;
pub use crate::error::mesh::{Location, MAX_TEXTURE_RES, MeshError};

pub use generate::subdivide_faces;
pub use texture::texel_center_barycentric;

/// Largest accepted `map_Kd` image, in pixels (8192²): a texture is decoded whole, at 12 bytes
/// a pixel, before it is sampled into per-face texels.
pub const MAX_TEXTURE_PIXELS: u64 = 1 << 26;

/// Largest icosphere subdivision level ([`Mesh::icosphere`] clamps to it): 7 gives 327 680 faces.
pub const MAX_ICOSPHERE_SUBDIVISIONS: u32 = 7;

/// A triangle mesh with SoftRas per-face textures.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// World-space vertex positions, in file order.
    pub positions: Vec<[f32; 3]>,
    /// Triangles as indices into `positions`. Winding: the SPEC §1 normal
    /// `normalize(cross(v2 - v1, v0 - v1))` points to the side the face is seen from.
    pub faces: Vec<[u32; 3]>,
    /// Texture resolution R: each face has R×R texels (R = 1 is a flat colour per face).
    pub texture_res: u32,
    /// `faces.len() * R * R` texels, face-major. Within a face, texel `i = w_y * R + w_x` in
    /// SoftRas order: texels with `w_x + w_y < R` are the lower triangles of the R×R grid over
    /// barycentric (w0, w1), the others the upper triangles (see [`texel_center_barycentric`]).
    pub textures: Vec<[f32; 3]>,
    /// Per-vertex colours for vertex colour mode; `None` means white.
    pub vertex_colors: Option<Vec<[f32; 3]>>,
}

impl Mesh {
    /// A mesh with flat white textures at resolution `texture_res`, validated.
    pub fn new(
        positions: Vec<[f32; 3]>,
        faces: Vec<[u32; 3]>,
        texture_res: u32,
    ) -> Result<Mesh, MeshError> {
        check_texture_res(texture_res)?;
        let texels = faces.len() * (texture_res * texture_res) as usize;
        let mesh = Mesh {
            positions,
            faces,
            texture_res,
            textures: vec![[1.0; 3]; texels],
            vertex_colors: None,
        };
        mesh.validate()?;
        Ok(mesh)
    }

    /// SoftRas's `load_obj(normalization=True)`: moves the bounding box's lower corner to the
    /// origin, divides by the largest coordinate then (so the longest side spans [0, 1]),
    /// doubles, and centres each axis: the longest side spans [-1, 1], the others are centred
    /// in it. Computed in f64. An error, with the mesh unchanged, when every vertex is at one
    /// point (nothing to scale) or a coordinate is not finite.
    pub fn normalize(&mut self) -> Result<(), MeshError> {
        check_finite(&self.positions, |_| Location::default())?;
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in &self.positions {
            let p = DVec3::from(p.map(f64::from));
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let extent = (hi - lo).max_element();
        if extent.is_nan() || extent <= 0.0 {
            return Err(MeshError::NoExtent {
                vertices: self.positions.len(),
            });
        }
        let scale = 2.0 / extent;
        let centre = (hi - lo) * scale / 2.0;
        for p in &mut self.positions {
            let q = (DVec3::from(p.map(f64::from)) - lo) * scale - centre;
            *p = q.to_array().map(|c| c as f32);
        }
        Ok(())
    }

    /// Number of triangles.
    pub fn face_count(&self) -> usize {
        self.faces.len()
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Checks every invariant the renderers rely on, so that bad input is an error and never a
    /// panic or a NaN image.
    pub fn validate(&self) -> Result<(), MeshError> {
        validate_parts(
            &self.positions,
            &self.faces,
            self.texture_res,
            self.textures.len(),
            self.vertex_colors.as_ref().map(Vec::len),
        )
    }

    /// Loads an OBJ (and its MTL and `map_Kd` texture) as SoftRas's `load_obj(load_texture=True)`
    /// does, sampling textures into `texture_res`² texels per face.
    ///
    /// A missing MTL file is not an error (SoftRas only reads it when asked for textures, and
    /// OBJ exporters often name one that was never shipped): its faces are white. A missing
    /// texture image is not an error either: its material's faces take the material's `Kd`, or
    /// white. Each missing file is said once, as one line `softvk: warning: ...` on stderr.
    /// An MTL or texture that exists but does not parse or decode is an error. `v x y z r g b`
    /// lines give [`Mesh::vertex_colors`] when every `v` line has a colour.
    pub fn load_obj(path: &Path, texture_res: u32) -> Result<Mesh, MeshError> {
        obj::load_obj_warning(path, texture_res, &mut |warning| {
            eprintln!("softvk: warning: {warning}");
        })
    }
}

pub(crate) fn check_texture_res(res: u32) -> Result<(), MeshError> {
    if res == 0 || res > MAX_TEXTURE_RES {
        return Err(MeshError::TextureRes(res));
    }
    Ok(())
}

/// A vertex position in whichever precision a mesh holds it: f32 in a [`Mesh`], f64 in the
/// copy the f64 twins compute in. What [`validate_parts`] asks of it.
pub(crate) trait Position {
    /// Every coordinate is finite.
    fn is_finite(&self) -> bool;
}

impl Position for [f32; 3] {
    fn is_finite(&self) -> bool {
        self.iter().all(|c| c.is_finite())
    }
}

impl Position for DVec3 {
    fn is_finite(&self) -> bool {
        DVec3::is_finite(*self)
    }
}

/// The checks of [`Mesh::validate`], on a mesh's parts: one implementation for a mesh in any
/// precision, so that every copy of a mesh fails on the same input with the same message.
/// `texels` and `vertex_colors` are the lengths of the texel and vertex colour arrays.
pub(crate) fn validate_parts<P: Position>(
    positions: &[P],
    faces: &[[u32; 3]],
    texture_res: u32,
    texels: usize,
    vertex_colors: Option<usize>,
) -> Result<(), MeshError> {
    check_texture_res(texture_res)?;
    check_finite(positions, |_| Location::default())?;
    if faces.is_empty() {
        return Err(MeshError::NoFaces {
            at: Location::default(),
        });
    }
    let n = positions.len();
    for (face, f) in faces.iter().enumerate() {
        if let Some(&bad) = f.iter().find(|&&i| i as usize >= n) {
            return Err(MeshError::FaceIndexOutOfRange {
                face,
                index: i64::from(bad),
                vertex_count: n,
                at: Location::default(),
            });
        }
    }
    let r2 = (texture_res * texture_res) as usize;
    if texels != faces.len() * r2 {
        return Err(MeshError::TextureCount {
            actual: texels,
            expected: faces.len() * r2,
            faces: faces.len(),
            res: texture_res,
        });
    }
    if let Some(colors) = vertex_colors
        && colors != n
    {
        return Err(MeshError::VertexColorCount {
            actual: colors,
            expected: n,
        });
    }
    Ok(())
}

fn check_finite<P: Position>(
    positions: &[P],
    at: impl Fn(usize) -> Location,
) -> Result<(), MeshError> {
    match positions.iter().position(|p| !p.is_finite()) {
        Some(vertex) => Err(MeshError::NonFiniteVertex {
            vertex,
            at: at(vertex),
        }),
        None => Ok(()),
    }
}

impl Mesh {
    /// Whether the mesh is closed with consistently wound faces: every directed edge appears
    /// once, and its reverse too (each edge shared by exactly two faces that wind it opposite).
    pub fn is_closed_and_consistent(&self) -> bool {
        let mut directed = std::collections::HashSet::new();
        for &[a, b, c] in &self.faces {
            for e in [(a, b), (b, c), (c, a)] {
                if !directed.insert(e) {
                    return false;
                }
            }
        }
        directed.iter().all(|&(a, b)| directed.contains(&(b, a)))
    }
}

#[cfg(test)]
mod tests {

    use super::*;

    /// SoftRas's normalization: the longest side spans [-1, 1], every axis is centred, the
    /// proportions stay; a mesh at one point is an error that leaves it unchanged.
    #[test]
    fn normalize_centres_and_scales_the_longest_side_to_two() {
        let mut mesh = Mesh::cuboid([0.125, 0.0625, 0.03125]);
        for p in &mut mesh.positions {
            *p = [p[0] + 3.0, p[1] - 1.0, p[2] + 0.5];
        }
        mesh.normalize().unwrap();
        let axis = |k: usize| {
            let c = mesh.positions.iter().map(|p| p[k]);
            (
                c.clone().fold(f32::INFINITY, f32::min),
                c.fold(f32::NEG_INFINITY, f32::max),
            )
        };
        assert_eq!(axis(0), (-1.0, 1.0));
        assert_eq!(axis(1), (-0.5, 0.5));
        assert_eq!(axis(2), (-0.25, 0.25));

        let mut point = Mesh::cuboid([0.0, 0.0, 0.0]);
        let before = point.positions.clone();
        let err = point.normalize().unwrap_err();
        assert!(err.to_string().contains("one point"), "{err}");
        assert_eq!(point.positions, before);
    }

    #[test]
    fn validate_catches_bad_texel_and_colour_counts() {
        let mut mesh = Mesh::cuboid([1.0; 3]);
        mesh.textures.pop();
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::TextureCount { expected: 12, .. })
        ));
        let mut mesh = Mesh::cuboid([1.0; 3]);
        mesh.vertex_colors = Some(vec![[1.0; 3]; 7]);
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::VertexColorCount { expected: 8, .. })
        ));
        let mut mesh = Mesh::cuboid([1.0; 3]);
        mesh.positions[5][1] = f32::INFINITY;
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::NonFiniteVertex { vertex: 5, .. })
        ));
    }
}
