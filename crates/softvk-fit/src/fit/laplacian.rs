//! SoftRas's `LaplacianLoss` (uniform weights): row i of L is `x_i − mean_{j ∈ N(i)} x_j`, N(i)
//! the vertices sharing an edge of a face with i (each once), and `loss = Σ_i |(L x)_i|²` with
//! gradient `2 Lᵀ L x`.
//!
//! SoftRas builds a dense V×V matrix and divides each row by its degree; a vertex no face uses
//! then gets a 0/0 row (NaN). Here such a vertex has a zero row: it is not part of the surface,
//! so nothing smooths it and it contributes nothing.
//!
//! The GPU side (`laplacian_apply.comp`, `laplacian_grad.comp`, driven by
//! [`super::Regularizers`]) walks the [`Adjacency`] CSR built here once.

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};

/// Push constants of `laplacian_apply.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct ApplyPush {
    pub vertex_count: u32,
}

/// Push constants of `laplacian_grad.comp` (and `flatten_gather.comp`).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct WeightedPush {
    pub vertex_count: u32,
    pub weight: f32,
    pub accumulate: u32,
    pub pad: u32,
}

/// Vertex adjacency by face edges, as CSR: the neighbours of vertex i are
/// `neighbours[offsets[i] .. offsets[i + 1]]`, ascending, each once.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Adjacency {
    /// `vertex_count + 1` offsets into `neighbours`.
    pub offsets: Vec<u32>,
    /// Neighbour indices.
    pub neighbours: Vec<u32>,
}

impl Adjacency {
    /// The adjacency of `faces` over `vertex_count` vertices. A face index out of range or a
    /// face that repeats a vertex is [`Error::Input`].
    pub fn from_faces(faces: &[[u32; 3]], vertex_count: usize) -> Result<Self> {
        check_faces(faces, vertex_count)?;
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); vertex_count];
        for f in faces {
            for (a, b) in [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])] {
                lists[a as usize].push(b);
                lists[b as usize].push(a);
            }
        }
        let mut offsets = Vec::with_capacity(vertex_count + 1);
        let mut neighbours = Vec::new();
        offsets.push(0);
        for mut list in lists {
            list.sort_unstable();
            list.dedup();
            neighbours.extend_from_slice(&list);
            offsets.push(u32::try_from(neighbours.len()).map_err(|_| {
                Error::Limit("the Laplacian's adjacency has more than 2^32 entries".into())
            })?);
        }
        Ok(Self {
            offsets,
            neighbours,
        })
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.offsets.len() - 1
    }

    /// The neighbours of vertex `i`.
    pub fn of(&self, i: usize) -> &[u32] {
        &self.neighbours[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

/// Every face index in range and no face repeating a vertex.
pub(crate) fn check_faces(faces: &[[u32; 3]], vertex_count: usize) -> Result<()> {
    for (i, f) in faces.iter().enumerate() {
        if let Some(&bad) = f.iter().find(|&&v| v as usize >= vertex_count) {
            return Err(Error::Input(format!(
                "face {i} uses vertex {bad}, but the mesh has {vertex_count} vertices"
            )));
        }
        if f[0] == f[1] || f[1] == f[2] || f[2] == f[0] {
            return Err(Error::Input(format!(
                "face {i} {f:?} repeats a vertex; the regularizers need proper triangles"
            )));
        }
    }
    Ok(())
}

/// CPU twin, in f64, loop for loop like the kernels.
pub mod cpu {
    use super::Adjacency;

    /// `(Σ_i |(L x)_i|², 2 Lᵀ L x)` for packed positions `x` (3 per vertex).
    pub fn loss_and_grad(adjacency: &Adjacency, x: &[f64]) -> (f64, Vec<f64>) {
        let n = adjacency.vertex_count();
        assert_eq!(x.len(), 3 * n, "3 coordinates per vertex");
        let mut y = vec![0.0; 3 * n];
        let mut loss = 0.0;
        for i in 0..n {
            let nb = adjacency.of(i);
            if nb.is_empty() {
                continue;
            }
            for c in 0..3 {
                let s: f64 = nb.iter().map(|&j| x[3 * j as usize + c]).sum();
                y[3 * i + c] = x[3 * i + c] - s / nb.len() as f64;
                loss += y[3 * i + c] * y[3 * i + c];
            }
        }
        let mut grad = vec![0.0; 3 * n];
        for i in 0..n {
            for c in 0..3 {
                let s: f64 = adjacency
                    .of(i)
                    .iter()
                    .map(|&j| y[3 * j as usize + c] / adjacency.of(j as usize).len() as f64)
                    .sum();
                grad[3 * i + c] = 2.0 * (y[3 * i + c] - s);
            }
        }
        (loss, grad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::test_support::{assert_grad_matches_fd, jittered_icosphere};
    use crate::specs;

    #[test]
    fn push_constant_structs_match_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<ApplyPush>() as u32,
            specs::LAPLACIAN_APPLY.push_constant_size
        );
        let weighted = std::mem::size_of::<WeightedPush>() as u32;
        assert_eq!(weighted, specs::LAPLACIAN_GRAD.push_constant_size);
        assert_eq!(weighted, specs::FLATTEN_GATHER.push_constant_size);
    }

    #[test]
    fn adjacency_is_symmetric_unique_and_sorted_on_an_icosphere() {
        let (x, faces) = jittered_icosphere(1, 0.0, 1);
        let adj = Adjacency::from_faces(&faces, x.len() / 3).unwrap();
        for i in 0..adj.vertex_count() {
            let nb = adj.of(i);
            assert!(nb.windows(2).all(|w| w[0] < w[1]), "vertex {i}: {nb:?}");
            assert!(nb.len() == 5 || nb.len() == 6, "icosphere valence");
            for &j in nb {
                assert!(adj.of(j as usize).contains(&(i as u32)));
            }
        }
    }

    #[test]
    fn laplacian_twin_gradient_matches_central_differences() {
        let (mut x, faces) = jittered_icosphere(1, 0.05, 3);
        // An extra isolated vertex: a zero row, no gradient.
        x.extend_from_slice(&[0.3, -0.2, 0.9]);
        let adj = Adjacency::from_faces(&faces, x.len() / 3).unwrap();
        let (loss, grad) = cpu::loss_and_grad(&adj, &x);
        assert!(loss > 0.0);
        assert_eq!(&grad[grad.len() - 3..], &[0.0; 3]);
        assert_grad_matches_fd(&x, &grad, 1e-6, |x| cpu::loss_and_grad(&adj, x).0);
    }

    #[test]
    fn bad_faces_are_input_errors() {
        for faces in [vec![[0, 1, 3]], vec![[0, 1, 1]]] {
            match Adjacency::from_faces(&faces, 3) {
                Err(Error::Input(message)) => assert!(message.contains("face 0"), "{message}"),
                other => panic!("expected an input error, got {other:?}"),
            }
        }
    }
}
