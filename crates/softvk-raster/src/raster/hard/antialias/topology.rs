//! The edge adjacency (nvdiffrast's topology hash): for each undirected edge, the first two
//! distinct opposite vertices, and the lookup that decides whether an edge has a neighbour.

use std::collections::HashMap;

use super::EDGE_ENDS;
/// Edge adjacency by vertex index: for each undirected edge, up to two opposite vertices.
///
/// nvdiffrast's is a GPU hash table; this one keeps the same information in a `HashMap` and
/// answers the same questions (see the module docs, "Topology").
#[derive(Clone, Debug, Default)]
pub struct TopologyHash {
    /// How many triangles it was built from, to catch a hash passed with another mesh.
    triangle_count: usize,
    /// Sorted vertex pair → the first two distinct opposite vertices, in triangle order.
    opposites: HashMap<(u32, u32), [Option<u32>; 2]>,
}

impl TopologyHash {
    /// Builds the adjacency of `tri` (vertex indices; triangles with a repeated index are left
    /// out, as nvdiffrast leaves them out).
    pub fn new(tri: &[[u32; 3]]) -> Self {
        let mut opposites: HashMap<(u32, u32), [Option<u32>; 2]> = HashMap::new();
        for t in tri {
            if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
                continue;
            }
            for (own, &(i, j)) in EDGE_ENDS.iter().enumerate() {
                let slots = opposites.entry(edge_key(t[i], t[j])).or_default();
                let own = t[own];
                // The first opposite vertex takes slot 0; a second, different one slot 1; any
                // later one is dropped (in nvdiffrast: whichever loses the atomic race).
                match slots[0] {
                    None => slots[0] = Some(own),
                    Some(first) if first != own && slots[1].is_none() => slots[1] = Some(own),
                    _ => {}
                }
            }
        }
        TopologyHash {
            triangle_count: tri.len(),
            opposites,
        }
    }

    /// The number of triangles the hash was built from.
    pub fn triangle_count(&self) -> usize {
        self.triangle_count
    }

    /// The vertex across edge `(a, b)` from the triangle whose third vertex is `own`, or `None`
    /// when nvdiffrast finds none (and so treats the edge as a silhouette edge).
    pub fn opposite_vertex(&self, a: u32, b: u32, own: u32) -> Option<u32> {
        if a == b {
            return None;
        }
        let slots = self.opposites.get(&edge_key(a, b))?;
        if slots[0] == Some(own) {
            slots[1]
        } else if slots[1] == Some(own) {
            slots[0]
        } else {
            None
        }
    }
}

/// nvdiffrast's `antialias_construct_topology_hash`: the adjacency of a triangle array that
/// stays constant, to pass to [`antialias`](super::antialias) and
/// [`antialias_backward`](super::antialias_backward) instead of rebuilding it.
pub fn antialias_construct_topology_hash(tri: &[[u32; 3]]) -> TopologyHash {
    TopologyHash::new(tri)
}

/// The undirected edge's key: its two vertex indices, smaller first.
fn edge_key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}
