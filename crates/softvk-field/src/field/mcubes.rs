//! The mesh of φ = 0.5 by marching cubes on the GPU: φ sampled on a `res³` lattice over the cube
//! (through [`Field::record_eval`]), per cell a case and a triangle count (`mc_cases`), an
//! exclusive scan ([`crate::primitives::Scan`]) for the offsets, and the triangles (`mc_emit`),
//! whose corners are identified by their lattice edge so that the host welds shared vertices
//! exactly. [`cpu`] is the twin.
//!
//! **Lattice.** Node `(x, y, z)`, `0 ≤ x, y, z < res`, at `c + h (2 (x, y, z) / (res − 1) − 1)`:
//! the cube's faces are lattice planes. A node is *inside* when φ > 0.5.
//!
//! **Case table.** Not the classic Lorensen–Cline/Bourke table: [`table`] derives one from a
//! rule, so that the mesh is closed and manifold wherever the surface stays inside the lattice,
//! by construction (the original Lorensen–Cline cases, built by complement symmetry, can resolve
//! an ambiguous face — two diagonal corners inside — differently in the two cells sharing it and
//! leave holes, Dürst 1988; a derived table also needs no 4 096 copied numbers). On each face of a
//! cell the surface's segments cut off the inside corners, and an ambiguous face always separates
//! its two inside corners; both cells sharing a face see the same corners and so make the same
//! segments. The segments of a case chain into closed loops around the cell; each loop is
//! triangulated without a diagonal between two crossings of one face (the neighbour could draw
//! the same diagonal, and that edge would have four triangles). Triangles are wound so that the
//! SPEC §1 normal `cross(v2 − v1, v0 − v1)` points out of the inside (towards φ < 0.5). A cell
//! makes at most 5 triangles, as with the classic table.
//!
//! **Vertices.** A crossing on the lattice edge from node a to node a + e_axis has the id
//! `3 a + axis` and lies at `p_a + t (p_b − p_a)`, `t = (0.5 − φ_a) / (φ_b − φ_a)`, computed the
//! same way by every cell that shares the edge. Vertices are numbered in order of first use by
//! the triangles (cells in index order, then table order), on the GPU path and in the twin alike.

use std::sync::Arc;

use std::collections::HashMap;
use std::sync::OnceLock;

use bytemuck::{Pod, Zeroable};

use super::{Cube, EVAL_BATCH, Field, check_binding_bytes, groups};
use crate::error::{Error, Result};
use crate::gpu::{Buffer, Context, Kernel, MemoryKind};
use crate::mesh::Mesh;
use crate::primitives::{Scan, ScanScratch};
use crate::specs;

/// The case table: for each of the 256 cases (bit k set when corner `k = x + 2y + 4z` of the
/// cell is inside) its triangles as triples of local edges. Local edge `e` runs along axis
/// `e / 4` from the corner whose other two coordinates are the bits of `e % 4` (lower axis first).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CaseTable {
    /// Triangles per case.
    pub counts: [u32; 256],
    /// Per case, `stride` local edges: 3 per triangle, unused entries 0.
    pub edges: Vec<u32>,
    /// Entries per case: 3 × the most triangles of any case.
    pub stride: usize,
}

impl CaseTable {
    /// The triangles of `case` as local-edge triples.
    pub fn triangles(&self, case: usize) -> impl Iterator<Item = [u32; 3]> + '_ {
        let base = case * self.stride;
        (0..self.counts[case] as usize).map(move |t| {
            let e = &self.edges[base + 3 * t..base + 3 * t + 3];
            [e[0], e[1], e[2]]
        })
    }

    /// The table as the kernels read it: 256 counts, then the edges.
    fn words(&self) -> Vec<u32> {
        let mut words = self.counts.to_vec();
        words.extend(&self.edges);
        words
    }
}

/// The two corners (`x + 2y + 4z`) of local edge `e`, lower first.
pub fn edge_corners(e: u32) -> (u32, u32) {
    let (axis, j) = (e / 4, e % 4);
    let lo = match axis {
        0 => ((j & 1) << 1) | ((j >> 1) << 2),
        1 => (j & 1) | ((j >> 1) << 2),
        _ => (j & 1) | ((j >> 1) << 1),
    };
    (lo, lo | (1 << axis))
}

/// The local edge joining two corners that differ in one coordinate.
fn edge_between(a: u32, b: u32) -> u32 {
    let (lo, hi) = (a.min(b), a.max(b));
    let axis = (hi ^ lo).trailing_zeros();
    let others: Vec<u32> = (0..3)
        .filter(|&k| k != axis)
        .map(|k| (lo >> k) & 1)
        .collect();
    4 * axis + others[0] + 2 * others[1]
}

/// Whether two local edges lie on a common face of the cell.
fn share_face(e1: u32, e2: u32) -> bool {
    let (a1, a2) = (e1 / 4, e2 / 4);
    let (c1, c2) = (edge_corners(e1).0, edge_corners(e2).0);
    (0..3).any(|b| b != a1 && b != a2 && (c1 >> b & 1) == (c2 >> b & 1))
}

/// Triangles of a loop of crossings, without a diagonal between two crossings of one cell face:
/// the neighbour sharing that face could draw the same diagonal, and the edge would then have
/// four triangles. Loop edges on a face are the face's segments, which the neighbour shares
/// with the opposite orientation, as a closed surface needs. Fans first (from the first start
/// that works), otherwise any such triangulation (found by a search over ears).
fn triangulate(lp: &[u32]) -> Vec<[u32; 3]> {
    let m = lp.len();
    for s in 0..m {
        if (2..m - 1).all(|k| !share_face(lp[s], lp[(s + k) % m])) {
            return (1..m - 1)
                .map(|k| [lp[s], lp[(s + k) % m], lp[(s + k + 1) % m]])
                .collect();
        }
    }
    fn search(poly: &[u32], out: &mut Vec<[u32; 3]>) -> bool {
        let m = poly.len();
        if m == 3 {
            out.push([poly[0], poly[1], poly[2]]);
            return true;
        }
        // Cut the ear at vertex i: the new edge (i − 1, i + 1) must be allowed.
        for i in 0..m {
            let (a, b, c) = (poly[(i + m - 1) % m], poly[i], poly[(i + 1) % m]);
            if share_face(a, c) {
                continue;
            }
            let rest: Vec<u32> = (0..m).filter(|&k| k != i).map(|k| poly[k]).collect();
            let mark = out.len();
            out.push([a, b, c]);
            if search(&rest, out) {
                return true;
            }
            out.truncate(mark);
        }
        false
    }
    let mut out = Vec::new();
    assert!(
        search(lp, &mut out),
        "no face-safe triangulation of the loop {lp:?}"
    );
    out
}

/// The case table, derived once (see the module doc).
pub fn table() -> &'static CaseTable {
    static TABLE: OnceLock<CaseTable> = OnceLock::new();
    TABLE.get_or_init(build_table)
}

fn build_table() -> CaseTable {
    // The 6 faces, corners in counter-clockwise order seen from outside the cell (a right-hand
    // turn about the outward normal): about +e_a the cycle runs e_b → e_c, with (a, b, c) cyclic.
    let mut faces = Vec::new();
    for a in 0..3u32 {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        for side in 0..2u32 {
            let corner = |u: u32, v: u32| (side << a) | (u << b) | (v << c);
            let mut cycle = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
            if side == 0 {
                cycle.reverse();
            }
            faces.push(cycle);
        }
    }
    let mut per_case: Vec<Vec<[u32; 3]>> = Vec::with_capacity(256);
    for case in 0..256u32 {
        let inside = |c: u32| case & (1 << c) != 0;
        // next[e] = the crossing that the segment starting at crossing e ends at.
        let mut next = [u32::MAX; 12];
        for cycle in &faces {
            // Crossings in counter-clockwise order: (edge, entering the inside?).
            let crossings: Vec<(u32, bool)> = (0..4)
                .filter(|&i| inside(cycle[i]) != inside(cycle[(i + 1) % 4]))
                .map(|i| {
                    let (c0, c1) = (cycle[i], cycle[(i + 1) % 4]);
                    (edge_between(c0, c1), inside(c1))
                })
                .collect();
            // Each leaving crossing B closes the inside arc that began at the entering crossing
            // just before it: the segment B → A has the inside on its left. On an ambiguous face
            // this separates the two inside corners.
            let m = crossings.len();
            for i in 0..m {
                let (b, entering) = crossings[i];
                if !entering {
                    let (a, a_entering) = crossings[(i + m - 1) % m];
                    debug_assert!(a_entering);
                    next[b as usize] = a;
                }
            }
        }
        let mut used = [false; 12];
        let mut tris = Vec::new();
        for start in 0..12u32 {
            if next[start as usize] == u32::MAX || used[start as usize] {
                continue;
            }
            let mut lp = Vec::new();
            let mut e = start;
            while !used[e as usize] {
                used[e as usize] = true;
                lp.push(e);
                e = next[e as usize];
            }
            // The loop as traced has its normal towards the inside; reversed, out of it.
            lp.reverse();
            tris.extend(triangulate(&lp));
        }
        per_case.push(tris);
    }
    let max = per_case.iter().map(Vec::len).max().unwrap_or(0);
    let stride = 3 * max;
    let mut counts = [0u32; 256];
    let mut edges = vec![0u32; 256 * stride];
    for (case, tris) in per_case.iter().enumerate() {
        counts[case] = tris.len() as u32;
        for (t, tri) in tris.iter().enumerate() {
            edges[case * stride + 3 * t..case * stride + 3 * t + 3].copy_from_slice(tri);
        }
    }
    CaseTable {
        counts,
        edges,
        stride,
    }
}

/// A welded triangle mesh of φ = 0.5.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Isosurface {
    /// Vertex positions, in order of first use.
    pub positions: Vec<[f32; 3]>,
    /// Triangles, wound with the normal out of the inside.
    pub faces: Vec<[u32; 3]>,
    /// Per vertex, its lattice edge id `3 · node + axis`.
    pub edge_ids: Vec<u32>,
}

impl Isosurface {
    /// True when φ never crosses 0.5 on the lattice.
    pub fn is_empty(&self) -> bool {
        self.faces.is_empty()
    }

    /// As a [`Mesh`] (flat white textures). [`Error::Input`] when empty (a mesh needs faces).
    pub fn to_mesh(&self) -> Result<Mesh> {
        if self.is_empty() {
            return Err(Error::Input(
                "marching cubes: the field has no surface (φ never crosses 0.5 on the lattice)"
                    .into(),
            ));
        }
        Ok(Mesh::new(self.positions.clone(), self.faces.clone(), 1)?)
    }

    /// Writes the mesh as OBJ ([`crate::io::write_obj`]: atomic, exact `f32`s).
    /// [`Error::Input`] when empty.
    pub fn write_obj(&self, path: &std::path::Path) -> Result<()> {
        if self.is_empty() {
            return Err(Error::Input(format!(
                "marching cubes: no surface to write to {} (φ never crosses 0.5)",
                path.display()
            )));
        }
        crate::io::write_obj(path, &self.positions, &self.faces)
    }

    /// Signed volume `Σ v0 · (v1 × v2) / 6` (positive for a closed mesh wound outwards).
    pub fn volume(&self) -> f64 {
        mesh_volume(&self.positions, &self.faces)
    }

    /// True when every edge is used by exactly two faces, once in each direction: a closed,
    /// consistently oriented surface.
    pub fn is_closed(&self) -> bool {
        let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
        for f in &self.faces {
            for k in 0..3 {
                *directed.entry((f[k], f[(k + 1) % 3])).or_default() += 1;
            }
        }
        directed
            .iter()
            .all(|(&(a, b), &n)| n == 1 && directed.get(&(b, a)) == Some(&1))
    }
}

/// Signed volume of a triangle mesh, `Σ v0 · (v1 × v2) / 6`.
pub fn mesh_volume(positions: &[[f32; 3]], faces: &[[u32; 3]]) -> f64 {
    faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| glam::DVec3::from(positions[i as usize].map(f64::from)));
            a.dot(b.cross(c)) / 6.0
        })
        .sum()
}

/// Welds triangle corners by lattice edge id, numbering vertices in order of first use.
fn weld(corner_ids: &[u32], corner_points: &[[f64; 3]]) -> Result<Isosurface> {
    let mut index: HashMap<u32, u32> = HashMap::new();
    let mut out = Isosurface::default();
    for (tri_ids, tri_points) in corner_ids
        .chunks_exact(3)
        .zip(corner_points.chunks_exact(3))
    {
        let mut face = [0u32; 3];
        for k in 0..3 {
            face[k] = *index.entry(tri_ids[k]).or_insert_with(|| {
                out.positions.push(tri_points[k].map(|c| c as f32));
                out.edge_ids.push(tri_ids[k]);
                (out.positions.len() - 1) as u32
            });
        }
        out.faces.push(face);
    }
    if let Some(v) = out
        .positions
        .iter()
        .position(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(Error::Input(format!(
            "marching cubes: vertex {v} on lattice edge {} is not finite (φ is NaN there)",
            out.edge_ids[v]
        )));
    }
    Ok(out)
}

/// Push constants of `field_lattice.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct LatticePush {
    cube: [f32; 4],
    res: u32,
    base: u32,
    n: u32,
    pad: u32,
}

/// Push constants of `mc_cases.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct CasesPush {
    res: u32,
    cells: u32,
}

/// Push constants of `mc_emit.comp`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct EmitPush {
    cube: [f32; 4],
    res: u32,
    cells: u32,
    stride: u32,
    pad: u32,
}

/// Marching cubes' kernels and case table on the GPU.
pub struct MarchingCubes {
    lattice: Arc<Kernel>,
    cases: Arc<Kernel>,
    emit: Arc<Kernel>,
    scan: Scan,
    table: Buffer,
}

impl MarchingCubes {
    /// Builds the kernels and uploads the case table.
    pub fn new(ctx: &Context) -> Result<Self> {
        Ok(Self {
            lattice: ctx.kernel(&specs::FIELD_LATTICE, &[])?,
            cases: ctx.kernel(&specs::MC_CASES, &[])?,
            emit: ctx.kernel(&specs::MC_EMIT, &[])?,
            scan: Scan::new(ctx)?,
            table: ctx.upload_buffer("marching cubes case table", &table().words())?,
        })
    }

    fn check_res(ctx: &Context, res: u32) -> Result<(u64, u64)> {
        if !(2..=1024).contains(&res) {
            return Err(Error::Input(format!(
                "marching cubes lattice of {res} nodes per axis: need 2..=1024"
            )));
        }
        let nodes = u64::from(res).pow(3);
        check_binding_bytes(ctx, &format!("marching cubes at {res}³"), 4 * nodes)?;
        Ok((nodes, u64::from(res - 1).pow(3)))
    }

    /// Records φ of every lattice node into `phi` (`res³` floats), in batches of
    /// [`EVAL_BATCH`] nodes through `points` (16 · min(res³, EVAL_BATCH) bytes).
    fn record_lattice(
        &self,
        rec: &mut crate::gpu::Recorder<'_>,
        field: &Field,
        res: u32,
        points: &Buffer,
        phi: &Buffer,
    ) -> Result<()> {
        let nodes = res.pow(3);
        for base in (0..nodes).step_by(EVAL_BATCH as usize) {
            let n = EVAL_BATCH.min(nodes - base);
            rec.dispatch(
                &self.lattice,
                &specs::FieldLatticeBindings {
                    points: points.whole(),
                }
                .for_kernel(&self.lattice)?,
                &LatticePush {
                    cube: field.cube().to_f32(),
                    res,
                    base,
                    n,
                    pad: 0,
                },
                n.div_ceil(64),
            )?;
            field.record_eval(
                rec,
                points.whole(),
                n,
                phi.range(4 * u64::from(base), 4 * u64::from(n)),
            )?;
        }
        Ok(())
    }

    /// φ of `field` at the `res³` lattice nodes, read back (for the twin, and for inspection).
    pub fn lattice_phi(&self, ctx: &Context, field: &Field, res: u32) -> Result<Vec<f32>> {
        let (nodes, _) = Self::check_res(ctx, res)?;
        let points = ctx.create_buffer(
            "marching cubes lattice points",
            16 * nodes.min(u64::from(EVAL_BATCH)),
            MemoryKind::Device,
        )?;
        let phi = ctx.create_buffer("marching cubes phi", 4 * nodes, MemoryKind::Device)?;
        ctx.submit_and_wait(|rec| self.record_lattice(rec, field, res, &points, &phi))?;
        ctx.read_buffer(&phi, 0, nodes as usize)
    }

    /// The welded mesh of φ = 0.5 on a `res³` lattice over the field's cube. Two submits: the
    /// lattice, cases and scan; then (once the triangle count is known) the triangles.
    pub fn extract(&self, ctx: &Context, field: &Field, res: u32) -> Result<Isosurface> {
        let (nodes, cells) = Self::check_res(ctx, res)?;
        let points = ctx.create_buffer(
            "marching cubes lattice points",
            16 * nodes.min(u64::from(EVAL_BATCH)),
            MemoryKind::Device,
        )?;
        let phi = ctx.create_buffer("marching cubes phi", 4 * nodes, MemoryKind::Device)?;
        let offsets = ctx.create_buffer("marching cubes offsets", 4 * cells, MemoryKind::Device)?;
        let scratch = ScanScratch::new(ctx, cells)?;
        let cases_push = CasesPush {
            res,
            cells: cells as u32,
        };
        ctx.submit_and_wait(|rec| {
            self.record_lattice(rec, field, res, &points, &phi)?;
            rec.dispatch(
                &self.cases,
                &specs::McCasesBindings {
                    phi: phi.whole(),
                    table: self.table.whole(),
                    counts: offsets.whole(),
                }
                .for_kernel(&self.cases)?,
                &cases_push,
                groups(cells, 64)?,
            )?;
            let range = offsets.range(0, 4 * cells);
            self.scan.record(rec, &scratch, range, range, cells)
        })?;
        let triangles = u64::from(ctx.read_buffer::<u32>(scratch.total(), 0, 1)?[0]);
        if triangles == 0 {
            return Ok(Isosurface::default());
        }
        check_binding_bytes(
            ctx,
            &format!("marching cubes' {triangles} triangles"),
            48 * triangles,
        )?;
        let tri_edges = ctx.create_buffer(
            "marching cubes triangle edges",
            12 * triangles,
            MemoryKind::Device,
        )?;
        let tri_points = ctx.create_buffer(
            "marching cubes triangle points",
            48 * triangles,
            MemoryKind::Device,
        )?;
        ctx.submit_and_wait(|rec| {
            rec.dispatch(
                &self.emit,
                &specs::McEmitBindings {
                    phi: phi.whole(),
                    table: self.table.whole(),
                    offsets: offsets.whole(),
                    tri_edges: tri_edges.whole(),
                    tri_points: tri_points.whole(),
                }
                .for_kernel(&self.emit)?,
                &EmitPush {
                    cube: field.cube().to_f32(),
                    res,
                    cells: cells as u32,
                    stride: table().stride as u32,
                    pad: 0,
                },
                groups(cells, 64)?,
            )
        })?;
        let ids: Vec<u32> = ctx.read_buffer(&tri_edges, 0, 3 * triangles as usize)?;
        let pts: Vec<[f32; 4]> = ctx.read_buffer(&tri_points, 0, 3 * triangles as usize)?;
        let pts: Vec<[f64; 3]> = pts
            .iter()
            .map(|p| [p[0], p[1], p[2]].map(f64::from))
            .collect();
        weld(&ids, &pts)
    }
}

/// CPU twin.
pub mod cpu {
    use super::{Cube, Isosurface, edge_corners, table, weld};
    use crate::error::Result;
    use crate::field::{FieldKind, cpu as field_cpu};

    /// The position of lattice node `q` (`lattice_point` in `field_lattice.glsl`).
    pub fn lattice_point(cube: &Cube, res: u32, q: [u32; 3]) -> [f64; 3] {
        let r1 = f64::from(res - 1);
        std::array::from_fn(|k| cube.center[k] + cube.half * (2.0 * f64::from(q[k]) / r1 - 1.0))
    }

    /// φ of the twin field at every lattice node, index `x + res (y + res z)`.
    pub fn lattice_phi(kind: &FieldKind, cube: &Cube, params: &[f64], res: u32) -> Vec<f64> {
        let mut phi = Vec::with_capacity((res as usize).pow(3));
        for z in 0..res {
            for y in 0..res {
                for x in 0..res {
                    let p = lattice_point(cube, res, [x, y, z]);
                    phi.push(field_cpu::eval(kind, cube, params, p));
                }
            }
        }
        phi
    }

    /// Marching cubes over the lattice values `phi` (`res³`, index `x + res (y + res z)`), cell
    /// for cell as `mc_cases` and `mc_emit`.
    pub fn extract(phi: &[f64], res: u32, cube: &Cube) -> Result<Isosurface> {
        let r = res as usize;
        assert_eq!(phi.len(), r * r * r, "res³ lattice values");
        let node = |q: [u32; 3]| q[0] as usize + r * (q[1] as usize + r * q[2] as usize);
        let t = table();
        let mut ids = Vec::new();
        let mut points = Vec::new();
        for z in 0..res - 1 {
            for y in 0..res - 1 {
                for x in 0..res - 1 {
                    let corner = |k: u32| [x + (k & 1), y + ((k >> 1) & 1), z + ((k >> 2) & 1)];
                    let case = (0..8)
                        .filter(|&k| phi[node(corner(k))] > 0.5)
                        .fold(0usize, |c, k| c | (1 << k));
                    for tri in t.triangles(case) {
                        for e in tri {
                            let (lo, hi) = edge_corners(e);
                            let (a, b) = (corner(lo), corner(hi));
                            let (fa, fb) = (phi[node(a)], phi[node(b)]);
                            let s = (0.5 - fa) / (fb - fa);
                            let (pa, pb) =
                                (lattice_point(cube, res, a), lattice_point(cube, res, b));
                            ids.push(3 * node(a) as u32 + e / 4);
                            points.push(std::array::from_fn(|k| pa[k] + s * (pb[k] - pa[k])));
                        }
                    }
                }
            }
        }
        weld(&ids, &points)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constant_structs_match_the_kernels_layout() {
        assert_eq!(
            std::mem::size_of::<LatticePush>() as u32,
            specs::FIELD_LATTICE.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<CasesPush>() as u32,
            specs::MC_CASES.push_constant_size
        );
        assert_eq!(
            std::mem::size_of::<EmitPush>() as u32,
            specs::MC_EMIT.push_constant_size
        );
        assert_eq!(specs::MC_EMIT.bindings.len(), 5);
    }

    #[test]
    fn local_edges_join_corners_one_axis_apart() {
        for e in 0..12 {
            let (lo, hi) = edge_corners(e);
            assert_eq!(hi ^ lo, 1 << (e / 4), "edge {e}");
            assert_eq!(edge_between(lo, hi), e);
            assert_eq!(edge_between(hi, lo), e);
        }
    }

    #[test]
    fn every_case_uses_each_crossing_edge_exactly_once() {
        let t = table();
        assert_eq!(t.counts[0], 0);
        assert_eq!(t.counts[255], 0);
        for case in 0..256usize {
            let mut seen = [0u32; 12];
            for tri in t.triangles(case) {
                for e in tri {
                    seen[e as usize] += 1;
                }
            }
            for e in 0..12u32 {
                let (lo, hi) = edge_corners(e);
                let crossing = (case >> lo & 1) != (case >> hi & 1);
                // A crossing is a vertex of one loop: used by (loop length − 2) fan triangles
                // through the loop's first vertex, 1 or 2 otherwise; never unused.
                assert_eq!(seen[e as usize] > 0, crossing, "case {case:#04x}, edge {e}");
            }
        }
        // One corner in: one triangle; the checkerboard of four corners: four triangles.
        assert_eq!(t.counts[0x01], 1);
        assert_eq!(t.counts[0x69], 4);
        assert_eq!(t.counts[0x96], 4);
        assert_eq!(t.stride, 15, "at most 5 triangles per cell");
    }

    #[test]
    fn no_triangle_edge_joins_two_crossings_of_a_face_unless_it_is_a_face_segment() {
        let t = table();
        for case in 0..256usize {
            let mut uses: HashMap<(u32, u32), u32> = HashMap::new();
            for tri in t.triangles(case) {
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    *uses.entry((a.min(b), a.max(b))).or_default() += 1;
                }
            }
            for (&(a, b), &n) in &uses {
                // An edge on a face is a segment: one triangle of this cell (the other is the
                // neighbour's). An interior diagonal: two triangles of this cell.
                if share_face(a, b) {
                    assert_eq!(
                        n, 1,
                        "case {case:#04x}: edge {a}–{b} on a face is a diagonal"
                    );
                } else {
                    assert_eq!(
                        n, 2,
                        "case {case:#04x}: interior edge {a}–{b} used {n} times"
                    );
                }
            }
        }
    }

    #[test]
    fn one_inside_corner_gives_a_triangle_facing_away_from_it() {
        // Corner 0 inside, φ linear: the triangle's normal points away from corner 0.
        let t = table();
        let tri: Vec<[u32; 3]> = t.triangles(1).collect();
        let mid = |e: u32| {
            let (lo, hi) = edge_corners(e);
            let p =
                |c: u32| glam::DVec3::new((c & 1) as f64, (c >> 1 & 1) as f64, (c >> 2 & 1) as f64);
            (p(lo) + p(hi)) / 2.0
        };
        let [a, b, c] = tri[0].map(mid);
        let n = (c - b).cross(a - b);
        assert!(n.dot(glam::DVec3::ONE) > 0.0, "normal {n}");
    }
}
