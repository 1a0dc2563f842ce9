//! Lambertian lighting in world space, applied to colours before projection, as SoftRas's
//! `lighting.py`, `ambient_lighting.py`, `directional_lighting.py` and `vertex_normals.py`:
//! `L = I_a c_a + Σ_l I_l c_l max(0, n · d_l)`, multiplying per-face texels (surface mode, face
//! normals) or per-vertex colours (vertex mode, vertex normals).
//!
//! SoftRas does not normalize the light direction (`relu(sum(normals * direction))`), so a
//! longer direction vector means a brighter light; this twin keeps that.

use glam::DVec3;

use crate::mesh::Mesh;

/// SoftRas `F.normalize(.., eps=1e-6)`: a zero-area face gets a zero normal, not NaN.
pub const NORMAL_EPS: f64 = 1e-6;

/// The mesh's positions in f64, the precision every lighting computation runs in.
pub fn positions_f64(mesh: &Mesh) -> Vec<DVec3> {
    mesh.positions
        .iter()
        .map(|p| DVec3::from(p.map(f64::from)))
        .collect()
}

/// Un-normalized face normal `cross(v2 - v1, v0 - v1)` (twice the area, SPEC §1 orientation).
pub fn face_normal_raw(positions: &[DVec3], face: [u32; 3]) -> DVec3 {
    let [a, b, c] = face.map(|i| positions[i as usize]);
    (c - b).cross(a - b)
}

/// Unit face normals `normalize(cross(v2 - v1, v0 - v1))`, one per face.
pub fn face_normals(mesh: &Mesh) -> Vec<DVec3> {
    face_normals_of(&positions_f64(mesh), &mesh.faces)
}

/// [`face_normals`] of f64 positions.
pub fn face_normals_of(positions: &[DVec3], faces: &[[u32; 3]]) -> Vec<DVec3> {
    faces
        .iter()
        .map(|&f| {
            let n = face_normal_raw(positions, f);
            n / n.length().max(NORMAL_EPS)
        })
        .collect()
}

/// Un-normalized vertex normals: the sum of the un-normalized (area-weighted) normals of the
/// incident faces, added in face order.
pub fn vertex_normal_sums(positions: &[DVec3], faces: &[[u32; 3]]) -> Vec<DVec3> {
    let mut sum = vec![DVec3::ZERO; positions.len()];
    for &f in faces {
        let n = face_normal_raw(positions, f);
        for i in f {
            sum[i as usize] += n;
        }
    }
    sum
}

/// Unit vertex normals: the normalized sum of the un-normalized (area-weighted) normals of the
/// incident faces. An unused vertex gets a zero normal.
pub fn vertex_normals(mesh: &Mesh) -> Vec<DVec3> {
    vertex_normals_of(&positions_f64(mesh), &mesh.faces)
}

/// [`vertex_normals`] of f64 positions.
pub fn vertex_normals_of(positions: &[DVec3], faces: &[[u32; 3]]) -> Vec<DVec3> {
    vertex_normal_sums(positions, faces)
        .iter()
        .map(|n| *n / n.length().max(NORMAL_EPS))
        .collect()
}

/// One directional light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Directional {
    /// Intensity `I_l`.
    pub intensity: f64,
    /// Colour `c_l`.
    pub color: [f64; 3],
    /// Direction `d_l` (towards the light), used as given: not normalized, as SoftRas.
    pub direction: [f64; 3],
}

impl Default for Directional {
    /// SoftRas: intensity 0.5, white, from +y.
    fn default() -> Self {
        Directional {
            intensity: 0.5,
            color: [1.0; 3],
            direction: [0.0, 1.0, 0.0],
        }
    }
}

/// Ambient plus directional lights.
#[derive(Clone, Debug, PartialEq)]
pub struct Lighting {
    /// Ambient intensity `I_a`.
    pub ambient_intensity: f64,
    /// Ambient colour `c_a`.
    pub ambient_color: [f64; 3],
    /// Directional lights.
    pub directionals: Vec<Directional>,
}

impl Default for Lighting {
    /// SoftRas `SoftRenderer` defaults: ambient 0.5 white, one directional 0.5 white from +y.
    fn default() -> Self {
        Lighting {
            ambient_intensity: 0.5,
            ambient_color: [1.0; 3],
            directionals: vec![Directional::default()],
        }
    }
}

impl Lighting {
    /// No light effect at all: ambient 1, white, no directionals (colours pass unchanged).
    pub fn unlit() -> Lighting {
        Lighting {
            ambient_intensity: 1.0,
            ambient_color: [1.0; 3],
            directionals: Vec::new(),
        }
    }

    /// The RGB light factor `L` for a (unit) normal.
    pub fn light(&self, normal: DVec3) -> [f64; 3] {
        let mut l = self.ambient_color.map(|c| self.ambient_intensity * c);
        for d in &self.directionals {
            let cosine = normal.dot(DVec3::from(d.direction)).max(0.0);
            for (k, lk) in l.iter_mut().enumerate() {
                *lk += d.intensity * d.color[k] * cosine;
            }
        }
        l
    }

    /// Surface mode: every texel of face f times `L(face normal f)`; `F * R²` colours in the
    /// mesh's texel order.
    pub fn apply_surface(&self, mesh: &Mesh) -> Vec<[f64; 3]> {
        let texels: Vec<[f64; 3]> = mesh.textures.iter().map(|t| t.map(f64::from)).collect();
        self.apply_surface_of(&positions_f64(mesh), &mesh.faces, mesh.texture_res, &texels)
    }

    /// [`Lighting::apply_surface`] of f64 positions and texels (`F * R²`, face-major).
    pub fn apply_surface_of(
        &self,
        positions: &[DVec3],
        faces: &[[u32; 3]],
        texture_res: u32,
        texels: &[[f64; 3]],
    ) -> Vec<[f64; 3]> {
        let r2 = (texture_res * texture_res) as usize;
        let lights: Vec<[f64; 3]> = face_normals_of(positions, faces)
            .iter()
            .map(|&n| self.light(n))
            .collect();
        texels
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let l = lights[i / r2];
                std::array::from_fn(|k| t[k] * l[k])
            })
            .collect()
    }

    /// Vertex mode: every vertex colour (white when the mesh has none) times
    /// `L(vertex normal)`; one colour per vertex.
    pub fn apply_vertex(&self, mesh: &Mesh) -> Vec<[f64; 3]> {
        let colors: Option<Vec<[f64; 3]>> = mesh
            .vertex_colors
            .as_ref()
            .map(|cs| cs.iter().map(|c| c.map(f64::from)).collect());
        self.apply_vertex_of(&positions_f64(mesh), &mesh.faces, colors.as_deref())
    }

    /// [`Lighting::apply_vertex`] of f64 positions and colours (`None`: white).
    pub fn apply_vertex_of(
        &self,
        positions: &[DVec3],
        faces: &[[u32; 3]],
        colors: Option<&[[f64; 3]]>,
    ) -> Vec<[f64; 3]> {
        vertex_normals_of(positions, faces)
            .iter()
            .enumerate()
            .map(|(v, &n)| {
                let l = self.light(n);
                let c = colors.map_or([1.0; 3], |cs| cs[v]);
                std::array::from_fn(|k| c[k] * l[k])
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn triangle(p: [[f32; 3]; 3]) -> Mesh {
        Mesh::new(p.to_vec(), vec![[0, 1, 2]], 2).unwrap()
    }

    #[test]
    fn face_normal_follows_spec_winding() {
        // Counter-clockwise in the xy plane seen from +z: normal +z.
        let m = triangle([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let n = face_normals(&m)[0];
        assert!((n - DVec3::Z).length() < 1e-15);
    }

    #[test]
    fn vertex_normals_weight_faces_by_area() {
        // Two faces sharing vertex 0: a big one facing +z and a small one facing +x.
        let m = Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [0.0, 2.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            vec![[0, 1, 2], [0, 3, 4]],
            1,
        )
        .unwrap();
        let n = vertex_normals(&m)[0];
        // Raw normals: (0,0,4) and (1,0,0); their sum normalized.
        let expected = DVec3::new(1.0, 0.0, 4.0).normalize();
        assert!((n - expected).length() < 1e-15);
        assert!((vertex_normals(&m)[1] - DVec3::Z).length() < 1e-15);
    }

    #[test]
    fn default_light_is_half_ambient_plus_half_cosine() {
        let l = Lighting::default();
        assert_eq!(l.light(DVec3::Y), [1.0; 3]);
        assert_eq!(l.light(DVec3::Z), [0.5; 3]);
        assert_eq!(l.light(-DVec3::Y), [0.5; 3]);
        let n = DVec3::new(0.0, 0.6, 0.8);
        assert!((l.light(n)[0] - 0.8).abs() < 1e-15);
    }

    #[test]
    fn light_direction_is_not_normalized_as_in_softras() {
        let l = Lighting {
            directionals: vec![Directional {
                direction: [0.0, 2.0, 0.0],
                ..Directional::default()
            }],
            ..Lighting::default()
        };
        assert_eq!(l.light(DVec3::Y), [1.5; 3]);
    }

    #[test]
    fn surface_mode_multiplies_each_faces_texels() {
        // Face normal +z; light from +z with a coloured ambient.
        let mut m = triangle([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        m.textures = vec![
            [0.2, 0.4, 0.8],
            [1.0, 1.0, 1.0],
            [0.5, 0.5, 0.5],
            [0.0, 1.0, 0.0],
        ];
        let l = Lighting {
            ambient_intensity: 0.25,
            ambient_color: [1.0, 0.0, 1.0],
            directionals: vec![Directional {
                intensity: 0.5,
                color: [1.0, 1.0, 0.0],
                direction: [0.0, 0.0, 1.0],
            }],
        };
        let lit = l.apply_surface(&m);
        let factor = [0.75, 0.5, 0.25];
        for (t, c) in m.textures.iter().zip(&lit) {
            for k in 0..3 {
                assert!((c[k] - f64::from(t[k]) * factor[k]).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn vertex_mode_uses_vertex_normals_and_colours() {
        let mut m = triangle([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]);
        // Normal of this face: cross(v2 - v1, v0 - v1) = cross((-1,0,-1), (-1,0,0)) = (0,1,0).
        m.vertex_colors = Some(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.5]]);
        let lit = Lighting::default().apply_vertex(&m);
        assert_eq!(lit, vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.5]]);
        m.vertex_colors = None;
        assert_eq!(Lighting::default().apply_vertex(&m), vec![[1.0; 3]; 3]);
    }
}
