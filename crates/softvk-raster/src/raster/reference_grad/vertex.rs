//! Step 4 of the f64 backward, per vertex: the per-corner gradients summed per vertex in a fixed
//! order ([`VertexFaces`]), and the lighting's backward ([`lighting_grad_surface`],
//! [`lighting_grad_vertex`]) from lit to raw colours and, through the normals, to positions.

use glam::DVec3;

use super::{add3, dot3, normalize_eps_grad};
use crate::lighting::{Lighting, NORMAL_EPS, face_normal_raw, vertex_normal_sums};

/// The (face, corner) slots incident to each vertex, in face order (CSR): the fixed order in
/// which per-corner gradients are summed per vertex.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VertexFaces {
    /// `offsets[v]..offsets[v + 1]` index `slots` for vertex v.
    pub offsets: Vec<u32>,
    /// Slot `3 f + c`: corner c of face f.
    pub slots: Vec<u32>,
}

impl VertexFaces {
    /// Counts, scans, scatters.
    pub fn new(faces: &[[u32; 3]], vertex_count: usize) -> VertexFaces {
        let mut offsets = vec![0u32; vertex_count + 1];
        for f in faces {
            for &v in f {
                offsets[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            offsets[v + 1] += offsets[v];
        }
        let mut next = offsets.clone();
        let mut slots = vec![0u32; 3 * faces.len()];
        for (fi, f) in faces.iter().enumerate() {
            for (c, &v) in f.iter().enumerate() {
                slots[next[v as usize] as usize] = (3 * fi + c) as u32;
                next[v as usize] += 1;
            }
        }
        VertexFaces { offsets, slots }
    }

    /// Per vertex, the sum of its slots of `per_corner` (`3 F` values).
    pub fn gather(&self, per_corner: &[[f64; 3]]) -> Vec<[f64; 3]> {
        (0..self.offsets.len() - 1)
            .map(|v| {
                let mut acc = [0.0; 3];
                for &slot in &self.slots[self.offsets[v] as usize..self.offsets[v + 1] as usize] {
                    add3(&mut acc, per_corner[slot as usize]);
                }
                acc
            })
            .collect()
    }
}

/// dL/d(unit normal) from dL/d(light factor L) of `L = I_a c_a + Σ_l I_l c_l max(0, n · d_l)`.
pub fn light_grad(lighting: &Lighting, normal: DVec3, d_light: [f64; 3]) -> DVec3 {
    let mut g = DVec3::ZERO;
    for l in &lighting.directionals {
        let dir = DVec3::from(l.direction);
        if normal.dot(dir) > 0.0 {
            g += dir * (l.intensity * dot3(l.color, d_light));
        }
    }
    g
}

/// dL/d(corners) of the raw face normal `cross(v2 − v1, v0 − v1)` given dL/d(it).
fn face_normal_raw_grad(positions: &[DVec3], face: [u32; 3], g: DVec3) -> [[f64; 3]; 3] {
    let [p0, p1, p2] = face.map(|i| positions[i as usize]);
    let (a, b) = (p2 - p1, p0 - p1);
    let (g_a, g_b) = (b.cross(g), g.cross(a));
    [g_b.to_array(), (-g_a - g_b).to_array(), g_a.to_array()]
}

/// Surface-mode lighting backward, per face: from dL/d(lit texels) (`F·R²`) to dL/d(raw
/// texels) and, through the face normal, dL/d(world position) per (face, corner) slot.
pub fn lighting_grad_surface(
    lighting: &Lighting,
    positions: &[DVec3],
    faces: &[[u32; 3]],
    texture_res: u32,
    textures: &[[f64; 3]],
    d_lit: &[[f64; 3]],
) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let r2 = (texture_res * texture_res) as usize;
    let mut d_textures = vec![[0.0; 3]; textures.len()];
    let mut corners = vec![[0.0; 3]; 3 * faces.len()];
    for (f, &face) in faces.iter().enumerate() {
        let raw = face_normal_raw(positions, face);
        let n = raw / raw.length().max(NORMAL_EPS);
        let light = lighting.light(n);
        let mut d_light = [0.0; 3];
        for t in f * r2..(f + 1) * r2 {
            for k in 0..3 {
                d_textures[t][k] = d_lit[t][k] * light[k];
                d_light[k] += d_lit[t][k] * textures[t][k];
            }
        }
        let d_raw = normalize_eps_grad(raw, NORMAL_EPS, light_grad(lighting, n, d_light));
        corners[3 * f..3 * f + 3].copy_from_slice(&face_normal_raw_grad(positions, face, d_raw));
    }
    (d_textures, corners)
}

/// Vertex-mode lighting backward: per vertex, from dL/d(lit colour) to dL/d(raw colour) and
/// dL/d(vertex normal sum); then per face, the sum's share of each incident face's raw normal
/// to dL/d(world position) per (face, corner) slot.
pub fn lighting_grad_vertex(
    lighting: &Lighting,
    positions: &[DVec3],
    faces: &[[u32; 3]],
    vertex_colors: Option<&[[f64; 3]]>,
    d_lit: &[[f64; 3]],
) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
    let sums = vertex_normal_sums(positions, faces);
    let mut d_colors = vec![[0.0; 3]; positions.len()];
    let mut d_sums = vec![DVec3::ZERO; positions.len()];
    for (v, &sum) in sums.iter().enumerate() {
        let n = sum / sum.length().max(NORMAL_EPS);
        let light = lighting.light(n);
        let c = vertex_colors.map_or([1.0; 3], |cs| cs[v]);
        let mut d_light = [0.0; 3];
        for k in 0..3 {
            d_colors[v][k] = d_lit[v][k] * light[k];
            d_light[k] = d_lit[v][k] * c[k];
        }
        d_sums[v] = normalize_eps_grad(sum, NORMAL_EPS, light_grad(lighting, n, d_light));
    }
    let mut corners = vec![[0.0; 3]; 3 * faces.len()];
    for (f, &face) in faces.iter().enumerate() {
        let d_raw = face.iter().map(|&v| d_sums[v as usize]).sum::<DVec3>();
        corners[3 * f..3 * f + 3].copy_from_slice(&face_normal_raw_grad(positions, face, d_raw));
    }
    (d_colors, corners)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertex_faces_lists_corners_in_face_order() {
        let adj = VertexFaces::new(&[[0, 1, 2], [2, 1, 3], [3, 0, 2]], 5);
        assert_eq!(adj.offsets, vec![0, 2, 4, 7, 9, 9]);
        assert_eq!(adj.slots, vec![0, 7, 1, 4, 2, 3, 8, 5, 6]);
        let per_corner: Vec<[f64; 3]> = (0..9).map(|i| [f64::from(i), 0.0, 1.0]).collect();
        let g = adj.gather(&per_corner);
        assert_eq!(g[2], [2.0 + 3.0 + 8.0, 0.0, 3.0]);
        assert_eq!(g[4], [0.0; 3]);
    }
}
