//! SoftRas's `FlattenLoss`: for each edge (v0, v1) shared by two faces with opposite vertices
//! v2, v3, the cosine between the perpendiculars from the edge line to v2 and to v3 (−1 when the
//! two faces are coplanar), and `loss = Σ_edges (cos + 1)²`, with SoftRas's epsilons (1e-6):
//!
//! ```text
//! a = v1 − v0; b1 = v2 − v0; al2 = |a|²; al1 = sqrt(al2 + eps); b1l1 = sqrt(|b1|² + eps)
//! ab1 = a·b1; cos1 = ab1 / (al1 b1l1 + eps); sin1 = sqrt(1 − cos1² + eps)
//! cb1 = b1 − a ab1 / (al2 + eps); cb1l1 = b1l1 sin1      (the same for b2 = v3 − v0)
//! cos = cb1·cb2 / (cb1l1 cb2l1 + eps)
//! ```
//!
//! **The edge set.** SoftRas builds its edges from the (0,1) and (1,2) corners of each face only
//! (`np.sort(concatenate(faces[:, 0:2], faces[:, 1:3]))`), so an edge that is the (2,0) edge of
//! both its faces is silently left out. softvk uses *every* edge shared by exactly two faces:
//! a regularizer that skips an arbitrary, ordering-dependent subset of the dihedral angles is a
//! bug, not a convention. On SoftRas's own templates (`sphere_642.obj`, `sphere_1352.obj`) the
//! two sets are identical (every edge is a (0,1) or (1,2) edge of some face: 1920 and 4050
//! edges), so SoftRas's weight (0.0003 in `demo_deform.py`) carries over unchanged; a test
//! checks this on `sphere_1352.obj`. On other meshes SoftRas's set can be much smaller: it
//! covers 6431 of the 8784 edges of `spot_triangulated.obj` and 25 of the 30 of the icosahedron
//! ([`crate::mesh::Mesh::icosphere`]`(0)`). There softvk's loss is the complete, larger one: a
//! weight tuned with SoftRas on such a mesh corresponds here to roughly that weight times the
//! covered fraction (0.73 for spot). Like SoftRas, the edge is `(min, max)`, v2 comes from the
//! first face in face order and v3 from the second; the term is symmetric under both swaps up
//! to rounding. An edge of one face (an open boundary) has no term; an edge of three or more
//! faces is an [`Error::Input`]. (SoftRas's own builder breaks on both: its v2/v3 lists come
//! out misaligned.)
//!
//! The GPU side (`flatten_edges.comp` per edge, `flatten_gather.comp` per vertex, driven by
//! [`super::Regularizers`]) writes each edge's four vertex gradients at the edge's own slots
//! (`4 edge + role`) and gathers them per vertex through [`FlattenEdges`]'s CSR, in ascending
//! slot order: no atomics.

use std::collections::BTreeMap;

use bytemuck::{Pod, Zeroable};

use super::laplacian::check_faces;
use crate::error::{Error, Result};

/// SoftRas's epsilon.
pub const FLATTEN_EPS: f64 = 1e-6;

/// Push constants of `flatten_edges.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct EdgesPush {
    pub edge_count: u32,
}

/// The flatten loss's edges and the per-vertex CSR of their gradient slots.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FlattenEdges {
    /// `[v0, v1, v2, v3]` per edge: the edge `v0 < v1`, v2 opposite in its first face (in face
    /// order), v3 in its second. Sorted by `(v0, v1)`.
    pub quads: Vec<[u32; 4]>,
    /// `vertex_count + 1` offsets into `vertex_slots`.
    pub vertex_offsets: Vec<u32>,
    /// Per vertex, the slots `4 · edge + role` (role 0..4 as in `quads`) that move it, ascending.
    pub vertex_slots: Vec<u32>,
}

impl FlattenEdges {
    /// Every edge of `faces` shared by exactly two faces. Out-of-range indices, faces repeating a
    /// vertex and edges of more than two faces are [`Error::Input`].
    pub fn from_faces(faces: &[[u32; 3]], vertex_count: usize) -> Result<Self> {
        check_faces(faces, vertex_count)?;
        // (v0, v1) → [(face, opposite vertex)] in face order.
        let mut edges: BTreeMap<(u32, u32), Vec<(usize, u32)>> = BTreeMap::new();
        for (i, f) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b, opposite) = (f[k], f[(k + 1) % 3], f[(k + 2) % 3]);
                edges
                    .entry((a.min(b), a.max(b)))
                    .or_default()
                    .push((i, opposite));
            }
        }
        let mut quads = Vec::new();
        for ((v0, v1), users) in &edges {
            match users.as_slice() {
                [_] => {} // an open boundary: no dihedral angle
                [(_, v2), (_, v3)] => quads.push([*v0, *v1, *v2, *v3]),
                more => {
                    let faces: Vec<usize> = more.iter().map(|&(f, _)| f).collect();
                    return Err(Error::Input(format!(
                        "edge ({v0}, {v1}) is shared by {} faces {faces:?}; the flatten loss \
                         needs each edge in at most two faces",
                        more.len()
                    )));
                }
            }
        }
        let slot_count = u32::try_from(4 * quads.len())
            .map_err(|_| Error::Limit("the flatten loss has more than 2^30 edges".into()))?;
        let mut counts = vec![0u32; vertex_count + 1];
        for q in &quads {
            for &v in q {
                counts[v as usize + 1] += 1;
            }
        }
        for i in 0..vertex_count {
            counts[i + 1] += counts[i];
        }
        let vertex_offsets = counts;
        let mut fill = vertex_offsets.clone();
        let mut vertex_slots = vec![0u32; slot_count as usize];
        // Slots are visited in ascending order, so each vertex's list comes out ascending.
        for slot in 0..slot_count {
            let v = quads[(slot / 4) as usize][(slot % 4) as usize] as usize;
            vertex_slots[fill[v] as usize] = slot;
            fill[v] += 1;
        }
        Ok(Self {
            quads,
            vertex_offsets,
            vertex_slots,
        })
    }

    /// Number of edges with a term.
    pub fn edge_count(&self) -> usize {
        self.quads.len()
    }
}

/// CPU twin, in f64, line for line like `flatten_edges.comp` and `flatten_gather.comp`.
pub mod cpu {
    use super::{FLATTEN_EPS as EPS, FlattenEdges};

    type V3 = [f64; 3];

    fn sub(a: V3, b: V3) -> V3 {
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }
    fn add(a: V3, b: V3) -> V3 {
        [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
    }
    fn scale(a: V3, s: f64) -> V3 {
        [a[0] * s, a[1] * s, a[2] * s]
    }
    fn dot(a: V3, b: V3) -> f64 {
        (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]
    }

    /// One side's forward state (the shader's `Side`).
    struct Side {
        b: V3,
        bl1: f64,
        ab: f64,
        cosk: f64,
        sink: f64,
        s: f64,
        cb: V3,
        cbl1: f64,
    }

    fn side_forward(a: V3, al1: f64, al2: f64, b: V3) -> Side {
        let bl1 = (dot(b, b) + EPS).sqrt();
        let ab = dot(a, b);
        let cosk = ab / (al1 * bl1 + EPS);
        let sink = (1.0 - cosk * cosk + EPS).sqrt();
        let s = ab / (al2 + EPS);
        let cb = sub(b, scale(a, s));
        Side {
            b,
            bl1,
            ab,
            cosk,
            sink,
            s,
            cb,
            cbl1: bl1 * sink,
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn side_backward(
        r: &Side,
        a: V3,
        al1: f64,
        al2: f64,
        g_cb: V3,
        g_cbl1: f64,
        g_a: &mut V3,
        g_al2: &mut f64,
    ) -> V3 {
        let mut g_bl1 = g_cbl1 * r.sink;
        let g_sin = g_cbl1 * r.bl1;
        let g_cos = -g_sin * r.cosk / r.sink;
        let mut g_b = g_cb;
        let g_c = scale(g_cb, -1.0);
        *g_a = add(*g_a, scale(g_c, r.s));
        let g_s = dot(g_c, a);
        let d2 = al2 + EPS;
        let mut g_ab = g_s / d2;
        *g_al2 -= g_s * r.ab / (d2 * d2);
        let d = al1 * r.bl1 + EPS;
        g_ab += g_cos / d;
        let g_d = -g_cos * r.ab / (d * d);
        let g_al1 = g_d * r.bl1;
        g_bl1 += g_d * al1;
        *g_al2 += g_al1 / (2.0 * al1);
        g_b = add(g_b, scale(r.b, g_bl1 / r.bl1));
        *g_a = add(*g_a, scale(r.b, g_ab));
        g_b = add(g_b, scale(a, g_ab));
        g_b
    }

    /// The term `(cos + 1)²` of one edge `[v0, v1, v2, v3]` and its gradient wrt each vertex.
    pub fn edge_loss_grad(v: [V3; 4]) -> (f64, [V3; 4]) {
        let a = sub(v[1], v[0]);
        let al2 = dot(a, a);
        let al1 = (al2 + EPS).sqrt();
        let s1 = side_forward(a, al1, al2, sub(v[2], v[0]));
        let s2 = side_forward(a, al1, al2, sub(v[3], v[0]));
        let num = dot(s1.cb, s2.cb);
        let den = s1.cbl1 * s2.cbl1 + EPS;
        let c = num / den;
        let loss = (c + 1.0) * (c + 1.0);

        let g_c = 2.0 * (c + 1.0);
        let g_num = g_c / den;
        let g_den = -g_c * num / (den * den);
        let mut g_a = [0.0; 3];
        let mut g_al2 = 0.0;
        let g_b1 = side_backward(
            &s1,
            a,
            al1,
            al2,
            scale(s2.cb, g_num),
            s2.cbl1 * g_den,
            &mut g_a,
            &mut g_al2,
        );
        let g_b2 = side_backward(
            &s2,
            a,
            al1,
            al2,
            scale(s1.cb, g_num),
            s1.cbl1 * g_den,
            &mut g_a,
            &mut g_al2,
        );
        g_a = add(g_a, scale(a, 2.0 * g_al2));
        let g_v0 = scale(add(add(g_a, g_b1), g_b2), -1.0);
        (loss, [g_v0, g_a, g_b1, g_b2])
    }

    /// `(Σ_edges (cos + 1)², gradient)` for packed positions `x` (3 per vertex); the gradient is
    /// gathered per vertex in ascending slot order, as on the GPU.
    pub fn loss_and_grad(edges: &FlattenEdges, x: &[f64]) -> (f64, Vec<f64>) {
        let vertex_count = edges.vertex_offsets.len() - 1;
        assert_eq!(x.len(), 3 * vertex_count, "3 coordinates per vertex");
        let p = |v: u32| {
            let i = 3 * v as usize;
            [x[i], x[i + 1], x[i + 2]]
        };
        let mut loss = 0.0;
        let mut slots = Vec::with_capacity(4 * edges.quads.len());
        for q in &edges.quads {
            let (l, g) = edge_loss_grad([p(q[0]), p(q[1]), p(q[2]), p(q[3])]);
            loss += l;
            slots.extend_from_slice(&g);
        }
        let mut grad = vec![0.0; 3 * vertex_count];
        for v in 0..vertex_count {
            let range = edges.vertex_offsets[v] as usize..edges.vertex_offsets[v + 1] as usize;
            let s = edges.vertex_slots[range]
                .iter()
                .fold([0.0; 3], |acc, &slot| add(acc, slots[slot as usize]));
            grad[3 * v..3 * v + 3].copy_from_slice(&s);
        }
        (loss, grad)
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use super::*;
    use crate::fit::test_support::{assert_grad_matches_fd, jittered_icosphere};
    use crate::mesh::Mesh;
    use crate::specs;

    /// SoftRas's edge set: the sorted (0,1) and (1,2) corner pairs of every face.
    fn softras_edge_pairs(faces: &[[u32; 3]]) -> BTreeSet<(u32, u32)> {
        faces
            .iter()
            .flat_map(|f| [(f[0], f[1]), (f[1], f[2])])
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect()
    }

    #[test]
    fn push_constant_struct_matches_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<EdgesPush>() as u32,
            specs::FLATTEN_EDGES.push_constant_size
        );
        assert_eq!(specs::FLATTEN_EDGES.bindings.len(), 4);
        assert_eq!(specs::FLATTEN_GATHER.bindings.len(), 4);
    }

    #[test]
    fn closed_mesh_has_every_edge_once_with_both_opposite_vertices() {
        let (x, faces) = jittered_icosphere(2, 0.0, 1);
        let edges = FlattenEdges::from_faces(&faces, x.len() / 3).unwrap();
        assert_eq!(edges.edge_count(), 3 * faces.len() / 2);
        for q in &edges.quads {
            assert!(q[0] < q[1]);
            let has = |f: &[u32; 3], v: u32| f.contains(&v);
            let shared: Vec<&[u32; 3]> = faces
                .iter()
                .filter(|f| has(f, q[0]) && has(f, q[1]))
                .collect();
            assert_eq!(shared.len(), 2);
            assert!(has(shared[0], q[2]) && has(shared[1], q[3]), "{q:?}");
        }
        // Every vertex's slots: ascending, and pointing back at it.
        for v in 0..x.len() / 3 {
            let s = &edges.vertex_slots
                [edges.vertex_offsets[v] as usize..edges.vertex_offsets[v + 1] as usize];
            assert!(s.windows(2).all(|w| w[0] < w[1]));
            for &slot in s {
                assert_eq!(edges.quads[slot as usize / 4][slot as usize % 4], v as u32);
            }
        }
    }

    #[test]
    fn softras_edge_set_is_complete_on_its_template_sphere_but_not_on_spot() {
        let path = softvk_testing::assets_dir().join("sphere_1352.obj");
        let mesh = Mesh::load_obj(&path, 1).unwrap();
        let edges = FlattenEdges::from_faces(&mesh.faces, mesh.vertex_count()).unwrap();
        let ours: BTreeSet<(u32, u32)> = edges.quads.iter().map(|q| (q[0], q[1])).collect();
        assert_eq!(ours.len(), 4050);
        assert_eq!(softras_edge_pairs(&mesh.faces), ours);
        // ...while elsewhere SoftRas's quirk misses edges (see the module docs).
        for (mesh, all, softras) in [
            (Mesh::icosphere(0), 30, 25),
            (
                Mesh::load_obj(
                    &softvk_testing::assets_dir().join("spot_triangulated.obj"),
                    1,
                )
                .unwrap(),
                8784,
                6431,
            ),
        ] {
            let edges = FlattenEdges::from_faces(&mesh.faces, mesh.vertex_count()).unwrap();
            assert_eq!(edges.edge_count(), all);
            let quirk = softras_edge_pairs(&mesh.faces);
            assert_eq!(quirk.len(), softras);
            assert!(
                quirk
                    .iter()
                    .all(|e| edges.quads.iter().any(|q| (q[0], q[1]) == *e))
            );
        }
    }

    #[test]
    fn boundary_edges_have_no_term_and_non_manifold_edges_are_errors() {
        // Two triangles sharing (0, 2): one interior edge, four boundary edges.
        let edges = FlattenEdges::from_faces(&[[0, 1, 2], [0, 2, 3]], 4).unwrap();
        assert_eq!(edges.quads, vec![[0, 2, 1, 3]]);
        match FlattenEdges::from_faces(&[[0, 1, 2], [0, 2, 3], [2, 0, 4]], 5) {
            Err(Error::Input(m)) => assert!(m.contains("edge (0, 2)"), "{m}"),
            other => panic!("expected an input error, got {other:?}"),
        }
    }

    #[test]
    fn flat_pair_has_zero_loss_and_folded_pair_the_most() {
        let flat = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 1.0, 0.0],
            [0.5, -1.0, 0.0],
        ];
        let (l, _) = cpu::edge_loss_grad(flat);
        assert!(l < 1e-10, "{l}");
        // v3 folded back onto v2's side: cos ≈ 0.995, the term ≈ 4.
        let folded = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.5, 1.0, 0.0],
            [0.5, 1.0, 0.1],
        ];
        let (l, _) = cpu::edge_loss_grad(folded);
        assert!((l - 4.0).abs() < 0.05, "{l}");
    }

    #[test]
    fn flatten_twin_gradient_matches_central_differences() {
        let (x, faces) = jittered_icosphere(1, 0.05, 5);
        let edges = FlattenEdges::from_faces(&faces, x.len() / 3).unwrap();
        let (loss, grad) = cpu::loss_and_grad(&edges, &x);
        assert!(loss > 0.0);
        assert_grad_matches_fd(&x, &grad, 1e-6, |x| cpu::loss_and_grad(&edges, x).0);
    }
}
