//! Meshes made in memory (the icosphere and the cuboid the tests and benchmarks draw) and
//! midpoint subdivision, which the icosphere shares with [`Mesh::subdivided`].

use std::collections::HashMap;

use glam::DVec3;

use super::{MAX_ICOSPHERE_SUBDIVISIONS, Mesh, MeshError};

impl Mesh {
    /// Unit-radius icosphere: the icosahedron subdivided `subdivisions` times (clamped to
    /// [`MAX_ICOSPHERE_SUBDIVISIONS`]), every face wound so its SPEC normal points outward.
    /// Flat white texture, R = 1. `20·4^s` faces, `10·4^s + 2` vertices.
    pub fn icosphere(subdivisions: u32) -> Mesh {
        let t = (1.0 + 5.0f64.sqrt()) / 2.0;
        let mut positions: Vec<DVec3> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .iter()
        .map(|&p| DVec3::from(p).normalize())
        .collect();
        let mut faces: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions.min(MAX_ICOSPHERE_SUBDIVISIONS) {
            // In f64, each midpoint pushed back onto the unit sphere.
            faces = subdivide_faces(&faces, |a, b| {
                positions.push((positions[a as usize] + positions[b as usize]).normalize());
                Ok::<u32, std::convert::Infallible>((positions.len() - 1) as u32)
            })
            .unwrap_or_else(|never| match never {});
        }
        white_mesh(positions, faces)
    }

    /// Midpoint subdivision: every triangle `(a, b, c)` becomes `(a, ab, ca)`, `(b, bc, ab)`,
    /// `(c, ca, bc)`, `(ab, bc, ca)`, each wound as its parent and lying in its plane
    /// ([`subdivide_faces`], which the icosphere uses too).
    ///
    /// Faces that share an edge share its midpoint (one new vertex per undirected edge,
    /// appended in order of first use), so a watertight mesh stays watertight. Midpoints are
    /// correctly rounded; per-vertex colours are averaged at them. Children copy their parent's
    /// texels (exact for R = 1; for R > 1 each child shows the whole parent texture).
    pub fn subdivided(&self) -> Result<Mesh, MeshError> {
        self.validate()?;
        let mut positions = self.positions.clone();
        let mut colors = self.vertex_colors.clone();
        let faces = subdivide_faces(&self.faces, |a, b| {
            let m = u32::try_from(positions.len()).map_err(|_| MeshError::TooManyVertices)?;
            let mid = |p: &[[f32; 3]]| {
                let (p, q) = (p[a as usize], p[b as usize]);
                // f32 + f32 is exact in f64, so this is the correctly rounded midpoint.
                [0, 1, 2].map(|k| ((f64::from(p[k]) + f64::from(q[k])) / 2.0) as f32)
            };
            positions.push(mid(&positions));
            if let Some(c) = colors.as_mut() {
                c.push(mid(c));
            }
            Ok::<u32, MeshError>(m)
        })?;
        let r2 = (self.texture_res * self.texture_res) as usize;
        let textures = self
            .textures
            .chunks_exact(r2)
            .flat_map(|parent| std::iter::repeat_n(parent, 4).flatten().copied())
            .collect();
        let out = Mesh {
            positions,
            faces,
            texture_res: self.texture_res,
            textures,
            vertex_colors: colors,
        };
        out.validate()?;
        Ok(out)
    }

    /// Axis-aligned box centred at the origin with the given half extents: 8 vertices,
    /// 12 faces wound outward. Flat white texture, R = 1.
    pub fn cuboid(half_extents: [f32; 3]) -> Mesh {
        let h = DVec3::new(
            f64::from(half_extents[0]),
            f64::from(half_extents[1]),
            f64::from(half_extents[2]),
        );
        // Vertex i has coordinate sign bits (x, y, z) = (i & 1, i & 2, i & 4).
        let positions: Vec<DVec3> = (0..8)
            .map(|i| {
                let s = |bit: u32| if i & bit != 0 { 1.0 } else { -1.0 };
                DVec3::new(s(1) * h.x, s(2) * h.y, s(4) * h.z)
            })
            .collect();
        // Quads listed counter-clockwise as seen from outside; fanned into two triangles.
        let quads = [
            [0, 4, 6, 2], // -x
            [1, 3, 7, 5], // +x
            [0, 1, 5, 4], // -y
            [2, 6, 7, 3], // +y
            [0, 2, 3, 1], // -z
            [4, 5, 7, 6], // +z
        ];
        let faces = quads
            .iter()
            .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
            .collect();
        white_mesh(positions, faces)
    }
}

/// The topology of one midpoint subdivision: each face `(a, b, c)` becomes `(a, ab, ca)`,
/// `(b, bc, ab)`, `(c, ca, bc)`, `(ab, bc, ca)`, and `new_vertex(a, b)` makes the midpoint of
/// each undirected edge once, on its first use (faces in order, edges ab, bc, ca), returning its
/// index. The one subdivision of the crate: [`Mesh::subdivided`] and [`Mesh::icosphere`] differ
/// only in how they place a midpoint.
pub fn subdivide_faces<E>(
    faces: &[[u32; 3]],
    mut new_vertex: impl FnMut(u32, u32) -> std::result::Result<u32, E>,
) -> std::result::Result<Vec<[u32; 3]>, E> {
    let mut midpoints: HashMap<(u32, u32), u32> = HashMap::with_capacity(faces.len() * 3 / 2);
    let mut midpoint = |a: u32, b: u32| -> std::result::Result<u32, E> {
        let key = (a.min(b), a.max(b));
        if let Some(&m) = midpoints.get(&key) {
            return Ok(m);
        }
        let m = new_vertex(a, b)?;
        midpoints.insert(key, m);
        Ok(m)
    };
    let mut next = Vec::with_capacity(faces.len() * 4);
    for &[a, b, c] in faces {
        let ab = midpoint(a, b)?;
        let bc = midpoint(b, c)?;
        let ca = midpoint(c, a)?;
        // Same winding as the parent in each child keeps the normals outward.
        next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
    }
    Ok(next)
}

fn white_mesh(positions: Vec<DVec3>, faces: Vec<[u32; 3]>) -> Mesh {
    let textures = vec![[1.0; 3]; faces.len()];
    Mesh {
        positions: positions
            .iter()
            .map(|p| [p.x as f32, p.y as f32, p.z as f32])
            .collect(),
        faces,
        texture_res: 1,
        textures,
        vertex_colors: None,
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use super::*;

    fn pos(m: &Mesh, i: u32) -> DVec3 {
        DVec3::from(m.positions[i as usize].map(f64::from))
    }

    fn face_normal(m: &Mesh, f: usize) -> DVec3 {
        let p = |i: u32| DVec3::from(m.positions[i as usize].map(f64::from));
        let [a, b, c] = m.faces[f];
        (p(c) - p(b)).cross(p(a) - p(b))
    }

    fn centroid(m: &Mesh, f: usize) -> DVec3 {
        let p = |i: u32| DVec3::from(m.positions[i as usize].map(f64::from));
        let [a, b, c] = m.faces[f];
        (p(a) + p(b) + p(c)) / 3.0
    }

    #[test]
    fn generators_are_closed_and_wound_outward() {
        for (mesh, v, f) in [
            (Mesh::icosphere(0), 12, 20),
            (Mesh::icosphere(2), 162, 320),
            (Mesh::cuboid([0.5, 1.0, 2.0]), 8, 12),
        ] {
            mesh.validate().unwrap();
            assert_eq!((mesh.vertex_count(), mesh.face_count()), (v, f));
            for face in 0..mesh.face_count() {
                let n = face_normal(&mesh, face);
                assert!(n.length() > 1e-6);
                assert!(
                    n.dot(centroid(&mesh, face)) > 0.0,
                    "face {face} of {v} points inward"
                );
            }
            // Closed: every edge is used once in each direction.
            let mut edges = HashMap::new();
            for &[a, b, c] in &mesh.faces {
                for e in [(a, b), (b, c), (c, a)] {
                    *edges.entry(e).or_insert(0) += 1;
                }
            }
            assert!(
                edges
                    .iter()
                    .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
            );
        }
        let sphere = Mesh::icosphere(3);
        for p in &sphere.positions {
            let r = p.iter().map(|c| f64::from(*c).powi(2)).sum::<f64>().sqrt();
            assert!((r - 1.0).abs() < 1e-6);
        }
    }

    /// Twice the signed area vector of face `f`, along the SPEC normal.
    fn area_vector(m: &Mesh, f: [u32; 3]) -> DVec3 {
        let [a, b, c] = f.map(|i| pos(m, i));
        (c - b).cross(a - b)
    }

    fn edge_count(m: &Mesh) -> usize {
        let mut edges = HashSet::new();
        for &[a, b, c] in &m.faces {
            for (p, q) in [(a, b), (b, c), (c, a)] {
                edges.insert((p.min(q), p.max(q)));
            }
        }
        edges.len()
    }

    #[test]
    fn subdivision_makes_four_faces_each_and_one_vertex_per_edge() {
        for mesh in [Mesh::cuboid([1.0, 2.0, 0.5]), Mesh::icosphere(1)] {
            let once = mesh.subdivided().unwrap();
            assert_eq!(once.face_count(), 4 * mesh.face_count());
            assert_eq!(once.vertex_count(), mesh.vertex_count() + edge_count(&mesh));
            assert_eq!(once.positions[..mesh.vertex_count()], mesh.positions[..]);
            let twice = once.subdivided().unwrap();
            assert_eq!(twice.face_count(), 16 * mesh.face_count());
        }
    }

    #[test]
    fn subdivision_keeps_a_closed_mesh_closed_and_consistently_wound() {
        let mut mesh = Mesh::icosphere(0);
        assert!(mesh.is_closed_and_consistent());
        for _ in 0..3 {
            mesh = mesh.subdivided().unwrap();
            assert!(mesh.is_closed_and_consistent());
            // Euler characteristic of a sphere: shared edges really share their midpoint.
            let chi =
                mesh.vertex_count() as i64 - edge_count(&mesh) as i64 + mesh.face_count() as i64;
            assert_eq!(chi, 2);
        }
    }

    #[test]
    fn subdivided_children_tile_their_parent_with_its_normal() {
        let mesh = Mesh::cuboid([1.0, 0.25, 3.0]);
        let sub = mesh.subdivided().unwrap();
        for (f, &parent) in mesh.faces.iter().enumerate() {
            let whole = area_vector(&mesh, parent);
            let children = &sub.faces[4 * f..4 * f + 4];
            let sum: DVec3 = children.iter().map(|&c| area_vector(&sub, c)).sum();
            assert!((sum - whole).length() <= 1e-6 * whole.length(), "face {f}");
            for &c in children {
                let child = area_vector(&sub, c);
                // Same plane, same side: a quarter of the parent's area vector.
                assert!((4.0 * child - whole).length() <= 1e-6 * whole.length());
            }
        }
    }

    #[test]
    fn subdivided_icosahedron_is_the_icosphere_before_projection() {
        // Mesh::icosphere makes the same midpoints in the same order, then puts them on the
        // unit sphere: same faces, and directions within f32 rounding.
        let sub = Mesh::icosphere(0).subdivided().unwrap();
        let ico = Mesh::icosphere(1);
        assert_eq!(sub.faces, ico.faces);
        for (p, q) in sub.positions.iter().zip(&ico.positions) {
            let p = DVec3::from(p.map(f64::from)).normalize();
            let q = DVec3::from(q.map(f64::from));
            assert!((p - q).length() < 1e-6);
        }
    }

    #[test]
    fn subdivision_copies_texels_and_averages_vertex_colors() {
        let mut mesh = Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [1, 3, 2]],
            2,
        )
        .unwrap();
        for (i, t) in mesh.textures.iter_mut().enumerate() {
            *t = [i as f32, 0.5, 1.0];
        }
        mesh.vertex_colors = Some(vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ]);
        let sub = mesh.subdivided().unwrap();
        assert_eq!(sub.texture_res, 2);
        for (f, child) in sub.textures.chunks_exact(4).enumerate() {
            assert_eq!(child, &mesh.textures[4 * (f / 4)..4 * (f / 4) + 4]);
        }
        let colors = sub.vertex_colors.as_ref().unwrap();
        assert_eq!(colors.len(), sub.vertex_count());
        // Face 0's middle child is (ab, bc, ca); its bc is the midpoint of the shared edge
        // (1, 2), which face 1's children use too, and holds the average of its ends.
        let bc = sub.faces[3][1] as usize;
        assert_eq!(sub.positions[bc], [0.5, 0.5, 0.0]);
        assert_eq!(colors[bc], [0.5, 0.5, 0.0]);
        assert!(sub.faces[4..].iter().flatten().any(|&i| i as usize == bc));
        assert_eq!(sub.vertex_count(), 4 + 5);
    }

    #[test]
    fn subdivision_rejects_an_invalid_mesh() {
        let mut mesh = Mesh::cuboid([1.0; 3]);
        mesh.faces[0][1] = 99;
        assert!(mesh.subdivided().is_err());
    }
}
