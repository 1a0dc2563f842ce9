//! Evaluation tools, on the CPU (the field's φ at voxel centres is evaluated on the GPU by
//! [`field_occupancy`], or by the twin through [`occupancy_from_fn`]): occupancy grids of a
//! closed mesh (by parity, [`voxelize_mesh`], or by winding number,
//! [`voxelize_mesh_winding`]), of a field, and of the visual hull of silhouettes
//! ([`visual_hull`]), and their 3D IoU ([`iou`]).
//!
//! **Voxels.** A `res³` grid over a [`Cube`]: voxel `(i, j, k)`, index `i + res (j + res k)`,
//! centred at `c − h + h (2 (i, j, k) + 1) / res` (cell centres, unlike the corner lattices of the
//! grid field and of marching cubes).

use glam::DVec3;

use super::{Cube, EVAL_BATCH, Field};
use crate::camera::{Camera, Projection};
use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::io::Silhouettes;

/// Which voxels of a `res³` grid over a cube are inside.
#[derive(Clone, Debug, PartialEq)]
pub struct Occupancy {
    /// Voxels per axis.
    pub res: u32,
    /// The cube the grid covers.
    pub cube: Cube,
    /// `res³` flags, index `i + res (j + res k)`.
    pub inside: Vec<bool>,
}

impl Occupancy {
    /// All voxels outside.
    pub fn empty(cube: Cube, res: u32) -> Occupancy {
        Occupancy {
            res,
            cube,
            inside: vec![false; (res as usize).pow(3)],
        }
    }

    /// The centre of voxel `(i, j, k)`.
    pub fn center(&self, ijk: [u32; 3]) -> [f64; 3] {
        voxel_center(&self.cube, self.res, ijk)
    }

    /// Voxels inside.
    pub fn count(&self) -> usize {
        self.inside.iter().filter(|&&b| b).count()
    }

    /// Volume of the voxels inside.
    pub fn volume(&self) -> f64 {
        self.count() as f64 * (2.0 * self.cube.half / f64::from(self.res)).powi(3)
    }

    /// Whether voxel `(i, j, k)` is inside.
    pub fn get(&self, ijk: [u32; 3]) -> bool {
        let r = self.res as usize;
        self.inside[ijk[0] as usize + r * (ijk[1] as usize + r * ijk[2] as usize)]
    }
}

/// The centre of voxel `ijk` of a `res³` grid over `cube`.
pub fn voxel_center(cube: &Cube, res: u32, ijk: [u32; 3]) -> [f64; 3] {
    std::array::from_fn(|k| {
        cube.center[k] - cube.half + cube.half * (2.0 * f64::from(ijk[k]) + 1.0) / f64::from(res)
    })
}

fn check_res(res: u32) -> Result<()> {
    if !(1..=1024).contains(&res) {
        return Err(Error::Input(format!(
            "occupancy grid of {res} voxels per axis: need 1..=1024"
        )));
    }
    Ok(())
}

/// Occupancy from a predicate on voxel centres (an analytic shape, the twin field's φ > 0.5).
pub fn occupancy_from_fn(cube: &Cube, res: u32, inside: impl Fn([f64; 3]) -> bool) -> Occupancy {
    let mut occ = Occupancy::empty(*cube, res);
    let r = res as usize;
    for k in 0..res {
        for j in 0..res {
            for i in 0..res {
                occ.inside[i as usize + r * (j as usize + r * k as usize)] =
                    inside(voxel_center(cube, res, [i, j, k]));
            }
        }
    }
    occ
}

/// The voxels whose centre has φ > 0.5, φ evaluated on the GPU (in batches of [`EVAL_BATCH`]).
pub fn field_occupancy(ctx: &Context, field: &Field, cube: &Cube, res: u32) -> Result<Occupancy> {
    check_res(res)?;
    cube.validate()?;
    let mut occ = Occupancy::empty(*cube, res);
    let r = res as usize;
    let points: Vec<[f32; 4]> = (0..r * r * r)
        .map(|v| {
            let ijk = [v % r, (v / r) % r, v / (r * r)].map(|x| x as u32);
            let c = voxel_center(cube, res, ijk);
            [c[0] as f32, c[1] as f32, c[2] as f32, 1.0]
        })
        .collect();
    for (b, chunk) in points.chunks(EVAL_BATCH as usize).enumerate() {
        let phi = field.eval(ctx, chunk)?;
        let base = b * EVAL_BATCH as usize;
        for (v, &f) in phi.iter().enumerate() {
            occ.inside[base + v] = f > 0.5;
        }
    }
    Ok(occ)
}

/// A voxelized mesh and how well its rays closed.
#[derive(Clone, Debug, PartialEq)]
pub struct Voxelization {
    /// The voxels inside.
    pub occupancy: Occupancy,
    /// Rays (one per voxel row along x) that crossed the surface an odd number of times: 0 for a
    /// closed mesh; otherwise the mesh has holes and those rows are unreliable.
    pub odd_rays: usize,
}

/// [`Error::Input`] unless `res`, `cube` and the mesh can be voxelized: every face indexes a
/// vertex, every vertex is finite.
fn check_mesh(positions: &[[f32; 3]], faces: &[[u32; 3]], cube: &Cube, res: u32) -> Result<()> {
    check_res(res)?;
    cube.validate()?;
    if let Some(f) = faces
        .iter()
        .position(|f| f.iter().any(|&i| i as usize >= positions.len()))
    {
        return Err(Error::Input(format!(
            "voxelize: face {f} indexes past the {} vertices",
            positions.len()
        )));
    }
    if positions.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::Input("voxelize: a vertex is not finite".into()));
    }
    Ok(())
}

/// Orientation of `p` against the segment `lo → hi` (`lo < hi` lexicographically), never 0:
/// an exact zero is resolved by the symbolic perturbation `p + (ε, ε²)`, so a point on an edge
/// or a vertex is inside exactly one of the triangles around it.
fn orient_canonical(lo: [f64; 2], hi: [f64; 2], p: [f64; 2]) -> f64 {
    let o = (hi[0] - lo[0]) * (p[1] - lo[1]) - (hi[1] - lo[1]) * (p[0] - lo[0]);
    if o != 0.0 {
        o.signum()
    } else if hi[1] != lo[1] {
        -(hi[1] - lo[1]).signum()
    } else {
        (hi[0] - lo[0]).signum()
    }
}

/// The side of `p` from the directed edge `a → b`, computed from the edge's canonical direction
/// so that the two triangles sharing the edge see exactly opposite signs.
fn edge_side(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> f64 {
    if (a[0], a[1]) <= (b[0], b[1]) {
        orient_canonical(a, b, p)
    } else {
        -orient_canonical(b, a, p)
    }
}

/// Voxelizes a closed triangle mesh: a voxel is inside when a ray from its centre along −x
/// crosses the surface an odd number of times (parity), counted per row of voxels along x. The
/// point-in-triangle test of each ray against the triangles projected on the yz plane is exact
/// about shared edges and vertices (canonical edge orientation and a symbolic perturbation), so a
/// ray through an edge or a vertex counts one crossing, not zero or two.
pub fn voxelize_mesh(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    cube: &Cube,
    res: u32,
) -> Result<Voxelization> {
    check_mesh(positions, faces, cube, res)?;
    let r = res as usize;
    let mut rows = row_crossings(positions, faces, cube, res);
    let mut occ = Occupancy::empty(*cube, res);
    let mut odd_rays = 0;
    for (row, xs) in rows.iter_mut().enumerate() {
        if xs.is_empty() {
            continue;
        }
        xs.sort_by(|a, b| a.0.total_cmp(&b.0));
        if xs.len() % 2 == 1 {
            odd_rays += 1;
        }
        let mut c = 0;
        for i in 0..r {
            let x = row_centre(cube, res, i);
            while c < xs.len() && xs[c].0 < x {
                c += 1;
            }
            occ.inside[i + r * row] = c % 2 == 1;
        }
    }
    Ok(Voxelization {
        occupancy: occ,
        odd_rays,
    })
}

/// Voxelizes a closed, consistently oriented triangle mesh by its winding number: a voxel is
/// inside when the winding number of the surface about its centre is at least 0.5 in magnitude.
/// Unlike [`voxelize_mesh`]'s parity, a region the surface encloses twice (a fold of a deformed
/// sphere that overlaps the rest of it, two overlapping closed parts) stays inside, and an
/// inside-out mesh (winding number −1 within) is inside too.
///
/// For a closed surface whose faces are consistently oriented (every edge used once in each
/// direction) the winding number at a point is the signed count of the surface's crossings
/// along any ray from it: so it is counted as [`voxelize_mesh`] counts parity, along −x per row
/// of voxel centres (the same exact crossing test, so a ray through an edge or a vertex counts
/// once), each crossing counting −1 or +1 by the sign of its triangle's normal's x, summed in
/// order along the row: the cost of parity. Whichever way the faces turn (outward or inward),
/// inside is where the count is not 0. For a mesh with holes or inconsistently oriented faces
/// the count along −x is not a winding number (another ray direction would count otherwise),
/// so such a mesh is refused with [`Error::Input`] (checked on the faces: every directed edge
/// once, its reverse once) rather than voxelized by an accident of the axis.
pub fn voxelize_mesh_winding(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    cube: &Cube,
    res: u32,
) -> Result<Occupancy> {
    check_mesh(positions, faces, cube, res)?;
    if let Some(e) = unpaired_edge(faces) {
        return Err(Error::Input(format!(
            "winding-number voxelization needs a closed, consistently oriented mesh: the edge \
             {} → {} is not used exactly once in each direction",
            e[0], e[1]
        )));
    }
    let r = res as usize;
    let mut rows = row_crossings(positions, faces, cube, res);
    let mut occ = Occupancy::empty(*cube, res);
    for (row, xs) in rows.iter_mut().enumerate() {
        if xs.is_empty() {
            continue;
        }
        xs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut c, mut winding) = (0, 0i64);
        for i in 0..r {
            let x = row_centre(cube, res, i);
            while c < xs.len() && xs[c].0 < x {
                // Entering along +x through a face that looks along −x (normal x < 0).
                winding -= xs[c].1 as i64;
                c += 1;
            }
            occ.inside[i + r * row] = winding != 0;
        }
    }
    Ok(occ)
}

/// A directed edge of `faces` that is not matched by exactly one use of it and one of its
/// reverse (`None` for a closed, consistently oriented mesh).
fn unpaired_edge(faces: &[[u32; 3]]) -> Option<[u32; 2]> {
    let mut edges: Vec<(u32, u32, bool)> = faces
        .iter()
        .flat_map(|f| [(f[0], f[1]), (f[1], f[2]), (f[2], f[0])])
        .map(|(a, b)| (a.min(b), a.max(b), a < b))
        .collect();
    edges.sort_unstable();
    let mut i = 0;
    while i < edges.len() {
        let (a, b, _) = edges[i];
        let same = edges[i..]
            .iter()
            .take_while(|e| (e.0, e.1) == (a, b))
            .count();
        // Sorted, a pair is (reverse, forward): exactly one of each.
        if same != 2 || edges[i].2 || !edges[i + 1].2 || a == b {
            let forward = edges[i].2;
            return Some(if forward { [a, b] } else { [b, a] });
        }
        i += same;
    }
    None
}

/// The x of voxel centre `i` of a row.
fn row_centre(cube: &Cube, res: u32, i: usize) -> f64 {
    cube.min()[0] + 2.0 * cube.half / f64::from(res) * (i as f64 + 0.5)
}

/// Per row `(j, k)` of voxel centres along x (index `j + res k`), where the ray through the
/// row crosses each triangle: its x, and the sign of the triangle's normal's x (±1, from the
/// same exact orientation test that decides the crossing).
fn row_crossings(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    cube: &Cube,
    res: u32,
) -> Vec<Vec<(f64, f64)>> {
    let r = res as usize;
    let step = 2.0 * cube.half / f64::from(res);
    let origin = cube.min();
    // Row (j, k): the ray at voxel centres y_j, z_k.
    let mut rows: Vec<Vec<(f64, f64)>> = vec![Vec::new(); r * r];
    let centre = |axis: usize, i: usize| origin[axis] + step * (i as f64 + 0.5);
    // Inclusive index range of voxel centres within [lo, hi] along `axis`.
    let span = |axis: usize, lo: f64, hi: f64| {
        let a = ((lo - origin[axis]) / step - 0.5).ceil().max(0.0);
        let b = ((hi - origin[axis]) / step - 0.5)
            .floor()
            .min(r as f64 - 1.0);
        (a as usize, b as isize)
    };
    for f in faces {
        let v = f.map(|i| positions[i as usize].map(f64::from));
        let yz = v.map(|p| [p[1], p[2]]);
        let (ymin, ymax) = (
            yz.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min),
            yz.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max),
        );
        let (zmin, zmax) = (
            yz.iter().map(|p| p[1]).fold(f64::INFINITY, f64::min),
            yz.iter().map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max),
        );
        let (j0, j1) = span(1, ymin, ymax);
        let (k0, k1) = span(2, zmin, zmax);
        for k in k0 as isize..=k1 {
            for j in j0 as isize..=j1 {
                let p = [centre(1, j as usize), centre(2, k as usize)];
                let s = [
                    edge_side(yz[0], yz[1], p),
                    edge_side(yz[1], yz[2], p),
                    edge_side(yz[2], yz[0], p),
                ];
                if s[0] != s[1] || s[1] != s[2] {
                    continue;
                }
                // Barycentrics from the (signed) sub-areas; the x of the crossing.
                let area = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
                    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
                };
                let w = [
                    area(yz[1], yz[2], p),
                    area(yz[2], yz[0], p),
                    area(yz[0], yz[1], p),
                ];
                let total = w[0] + w[1] + w[2];
                let x = if total != 0.0 {
                    (w[0] * v[0][0] + w[1] * v[1][0] + w[2] * v[2][0]) / total
                } else {
                    (v[0][0] + v[1][0] + v[2][0]) / 3.0
                };
                // All three sides agree: s[0] is the (perturbed) orientation of the projected
                // triangle, counter-clockwise in yz when its normal's x is positive.
                rows[j as usize + r * k as usize].push((x, s[0]));
            }
        }
    }
    rows
}

/// Voxelizes a triangle mesh as SoftRas's evaluation does (`srf.voxelization`, after Neural
/// Mesh Renderer): the voxels the surface passes through, plus every voxel the outside cannot
/// reach through 6-connected free voxels. Unlike [`voxelize_mesh`]'s parity it needs no closed or
/// non-self-intersecting mesh: a crumpled prediction whose folds overlap stays solid, and a sheet
/// thinner than a voxel still marks its voxels.
///
/// In voxel units (voxel `i` spans `[i, i + 1)` on each axis), the surface voxels are
/// - for each axis and each lattice line parallel to it through integer coordinates `(a, b)`
///   (`0 ..= res`), where the line crosses a triangle (barycentrics ≥ 0, inclusive) at `t`:
///   the four voxels `(a − 1 | a, b − 1 | b, ⌊t⌋)` around the line;
/// - the voxels holding a vertex.
///
/// The free voxels on the grid's faces are outside; outside spreads to free neighbours.
/// (SoftRas's kernels cover lines `0 .. res`; the line at `res` marks voxels only on the grid's
/// last layer, so the two agree inside the grid.)
pub fn voxelize_mesh_conservative(
    positions: &[[f32; 3]],
    faces: &[[u32; 3]],
    cube: &Cube,
    res: u32,
) -> Result<Occupancy> {
    check_mesh(positions, faces, cube, res)?;
    let r = res as i64;
    let step = 2.0 * cube.half / f64::from(res);
    let origin = cube.min();
    let to_grid = |p: &[f32; 3]| -> [f64; 3] {
        std::array::from_fn(|k| (f64::from(p[k]) - origin[k]) / step)
    };
    let index = |v: [i64; 3]| -> Option<usize> {
        v.iter()
            .all(|&c| (0..r).contains(&c))
            .then(|| (v[0] + r * (v[1] + r * v[2])) as usize)
    };
    let mut solid = vec![false; (r * r * r) as usize];
    for f in faces {
        let v = f.map(|i| to_grid(&positions[i as usize]));
        for p in &v {
            if let Some(i) = index(p.map(|c| c.floor() as i64)) {
                solid[i] = true;
            }
        }
        // The lines along axis `z`, over the lattice of the other two (`x`, `y`).
        for (x, y, z) in [(1, 2, 0), (0, 2, 1), (0, 1, 2)] {
            let d1 = [v[1][x] - v[0][x], v[1][y] - v[0][y], v[1][z] - v[0][z]];
            let d2 = [v[2][x] - v[0][x], v[2][y] - v[0][y], v[2][z] - v[0][z]];
            let det = d1[0] * d2[1] - d2[0] * d1[1];
            if det == 0.0 {
                continue;
            }
            let lo = |k: usize| v.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
            let hi = |k: usize| v.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
            let (a0, a1) = (
                lo(x).ceil().max(0.0) as i64,
                hi(x).floor().min(r as f64) as i64,
            );
            let (b0, b1) = (
                lo(y).ceil().max(0.0) as i64,
                hi(y).floor().min(r as f64) as i64,
            );
            for b in b0..=b1 {
                for a in a0..=a1 {
                    let (pa, pb) = (a as f64 - v[0][x], b as f64 - v[0][y]);
                    let t1 = (d2[1] * pa - d2[0] * pb) / det;
                    let t2 = (-d1[1] * pa + d1[0] * pb) / det;
                    if t1 < 0.0 || t2 < 0.0 || t1 + t2 > 1.0 {
                        continue;
                    }
                    let c = (v[0][z] + t1 * d1[2] + t2 * d2[2]).floor() as i64;
                    for (da, db) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let mut cell = [0i64; 3];
                        cell[x] = a - da;
                        cell[y] = b - db;
                        cell[z] = c;
                        if let Some(i) = index(cell) {
                            solid[i] = true;
                        }
                    }
                }
            }
        }
    }
    // Outside: free voxels connected to the grid's faces.
    let mut outside = vec![false; solid.len()];
    let mut stack: Vec<[i64; 3]> = Vec::new();
    for k in 0..r {
        for j in 0..r {
            for i in 0..r {
                let on_face = [i, j, k].iter().any(|&c| c == 0 || c == r - 1);
                let n = index([i, j, k]).expect("in the grid");
                if on_face && !solid[n] {
                    outside[n] = true;
                    stack.push([i, j, k]);
                }
            }
        }
    }
    while let Some(c) = stack.pop() {
        for axis in 0..3 {
            for d in [-1, 1] {
                let mut nb = c;
                nb[axis] += d;
                if let Some(n) = index(nb) {
                    if !solid[n] && !outside[n] {
                        outside[n] = true;
                        stack.push(nb);
                    }
                }
            }
        }
    }
    let mut occ = Occupancy::empty(*cube, res);
    for (o, out) in occ.inside.iter_mut().zip(&outside) {
        *o = !out;
    }
    Ok(occ)
}

/// The pixel `(col, row)` whose centre is nearest to screen point `(x_s, y_s)` (the inverse of
/// [`crate::camera::pixel_center`]), or `None` outside the image.
pub fn screen_to_pixel(x_s: f64, y_s: f64, width: u32, height: u32) -> Option<(u32, u32)> {
    let (w, h) = (f64::from(width), f64::from(height));
    let s = w.min(h);
    let col = ((x_s * s + w - 1.0) / 2.0 + 0.5).floor();
    let up = ((y_s * s + h - 1.0) / 2.0 + 0.5).floor(); // H − 1 − row
    let row = h - 1.0 - up;
    if col >= 0.0 && col < w && row >= 0.0 && row < h {
        Some((col as u32, row as u32))
    } else {
        None
    }
}

/// The visual hull: a voxel is inside iff its centre projects (with the project's [`Camera`],
/// as the renderer projects) into a pixel whose silhouette value is > 0.5 in every view. A
/// centre that projects outside an image, or behind a perspective camera, is outside.
///
/// The silhouettes are sampled at pixel centres (the nearest pixel), so near a contour the hull
/// can lose up to half a pixel's footprint: it contains the object up to that margin, not
/// exactly.
pub fn visual_hull(
    silhouettes: &Silhouettes,
    cameras: &[Camera],
    cube: &Cube,
    res: u32,
) -> Result<Occupancy> {
    check_res(res)?;
    cube.validate()?;
    if cameras.len() != silhouettes.views() {
        return Err(Error::Input(format!(
            "visual hull: {} cameras for {} silhouettes",
            cameras.len(),
            silhouettes.views()
        )));
    }
    let (w, h) = (silhouettes.width, silhouettes.height);
    Ok(occupancy_from_fn(cube, res, |p| {
        cameras.iter().enumerate().all(|(v, cam)| {
            let [x, y, z] = cam.to_screen(DVec3::from(p));
            if matches!(cam.projection, Projection::Perspective { .. }) && z <= 0.0 {
                return false;
            }
            screen_to_pixel(x, y, w, h)
                .is_some_and(|(c, r)| silhouettes.mask(v)[(r * w + c) as usize] > 0.5)
        })
    }))
}

/// The surface of the visual hull of `sil` seen from `cams`, on the marching-cubes lattice of
/// `res³` nodes over `cube`: the hull is sampled at the voxel centres of a cube grown by
/// `res / (res − 1)`, which are exactly that lattice's nodes.
pub fn visual_hull_surface(
    sil: &Silhouettes,
    cams: &[Camera],
    cube: &Cube,
    res: u32,
) -> Result<super::mcubes::Isosurface> {
    let grown = Cube::new(cube.center, cube.half * f64::from(res) / f64::from(res - 1))?;
    let hull = visual_hull(sil, cams, &grown, res)?;
    let phi: Vec<f64> = (0..res)
        .flat_map(|z| (0..res).flat_map(move |y| (0..res).map(move |x| [x, y, z])))
        .map(|q| if hull.get(q) { 1.0 } else { 0.0 })
        .collect();
    super::mcubes::cpu::extract(&phi, res, cube)
}

/// 3D IoU `|A ∩ B| / |A ∪ B|` of two occupancies of the same grid (1 when both are empty).
pub fn iou(a: &Occupancy, b: &Occupancy) -> Result<f64> {
    if a.res != b.res || a.cube != b.cube {
        return Err(Error::Input(format!(
            "IoU of occupancies on different grids ({}³ over {:?} and {}³ over {:?})",
            a.res, a.cube, b.res, b.cube
        )));
    }
    let (mut both, mut any) = (0usize, 0usize);
    for (&x, &y) in a.inside.iter().zip(&b.inside) {
        both += usize::from(x && y);
        any += usize::from(x || y);
    }
    Ok(if any == 0 {
        1.0
    } else {
        both as f64 / any as f64
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn screen_to_pixel_inverts_pixel_centers() {
        for (w, h) in [(4, 4), (5, 3), (2, 7)] {
            for r in 0..h {
                for c in 0..w {
                    let (x, y) = crate::camera::pixel_center(c, r, w, h);
                    assert_eq!(screen_to_pixel(x, y, w, h), Some((c, r)));
                }
            }
        }
        assert_eq!(screen_to_pixel(1.5, 0.0, 4, 4), None);
    }

    #[test]
    fn edge_sides_of_a_shared_edge_are_opposite_even_on_it() {
        let (a, b) = ([0.0, 0.0], [1.0, 1.0]);
        for p in [[0.5, 0.5], [0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [0.3, 0.1]] {
            assert_eq!(edge_side(a, b, p), -edge_side(b, a, p));
            assert_ne!(edge_side(a, b, p), 0.0);
        }
    }

    #[test]
    fn a_ray_through_a_shared_vertex_crosses_a_closed_fan_once() {
        // An octahedron with a vertex on the ray through voxel row (y, z) = (0, 0)... at res 1
        // the only ray is the cube's axis, which passes through two vertices of the octahedron.
        let positions = [
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ];
        let faces = [
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        let cube = Cube {
            center: [0.0; 3],
            half: 2.0,
        };
        // res 2: voxel centres at ±1 along y and z miss; res 1: the centre (0, 0, 0).
        let v = voxelize_mesh(&positions, &faces, &cube, 1).unwrap();
        assert_eq!(v.odd_rays, 0);
        assert_eq!(v.occupancy.count(), 1);
        let v = voxelize_mesh(&positions, &faces, &cube, 3).unwrap();
        assert_eq!(v.odd_rays, 0);
        // Centres at 0 and ±4/3: only the centre voxel is inside the octahedron.
        assert_eq!(v.occupancy.count(), 1);
        assert!(v.occupancy.get([1, 1, 1]));
    }

    fn shifted(m: &crate::mesh::Mesh, d: [f32; 3]) -> Vec<[f32; 3]> {
        m.positions
            .iter()
            .map(|p| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
            .collect()
    }

    #[test]
    fn conservative_voxelization_keeps_surface_voxels_and_fills_inside() {
        // A box over [−0.25, 0.25]³ on 10 voxels over [−1, 1]³: grid coordinates
        // [3.75, 6.25], so voxels 3..=6 on each axis are touched (4³ = 64) where parity
        // keeps the 2³ whose centres (±0.1) are inside.
        let m = crate::mesh::Mesh::cuboid([0.25; 3]);
        let cube = Cube {
            center: [0.0; 3],
            half: 1.0,
        };
        let c = voxelize_mesh_conservative(&m.positions, &m.faces, &cube, 10).unwrap();
        let p = voxelize_mesh(&m.positions, &m.faces, &cube, 10).unwrap();
        assert_eq!(p.occupancy.count(), 8);
        assert_eq!(c.count(), 64);
        for i in 0..10 {
            for j in 0..10 {
                for k in 0..10 {
                    let want = [i, j, k].iter().all(|c| (3..=6).contains(c));
                    assert_eq!(c.get([i, j, k]), want, "voxel {i} {j} {k}");
                }
            }
        }
    }

    #[test]
    fn conservative_voxelization_fills_where_a_mesh_overlaps_itself() {
        // Two boxes in one mesh, overlapping over x ∈ [−0.1, 0.1]: parity counts four crossings
        // through the overlap and leaves it empty; the flood fill keeps it.
        let m = crate::mesh::Mesh::cuboid([0.3; 3]);
        let mut positions = shifted(&m, [-0.2, 0.0, 0.0]);
        positions.extend(shifted(&m, [0.2, 0.0, 0.0]));
        let n = m.positions.len() as u32;
        let mut faces = m.faces.clone();
        faces.extend(m.faces.iter().map(|f| f.map(|i| i + n)));
        let cube = Cube {
            center: [0.0; 3],
            half: 1.0,
        };
        // res 20: voxel 10's centre is at x = 0.05, inside both boxes.
        let p = voxelize_mesh(&positions, &faces, &cube, 20).unwrap();
        let c = voxelize_mesh_conservative(&positions, &faces, &cube, 20).unwrap();
        assert!(!p.occupancy.get([10, 10, 10]));
        assert!(c.get([10, 10, 10]));
        assert!(c.get([6, 10, 10]) && c.get([13, 10, 10]));
        assert!(!c.get([2, 10, 10]) && !c.get([17, 10, 10]));
    }

    #[test]
    fn conservative_voxelization_keeps_a_sheet_thinner_than_a_voxel() {
        // One square at z = 0.05 (inside voxel layer 10 of 20 over [−1, 1]), spanning
        // x, y ∈ [−0.45, 0.45]: grid [5.5, 14.5], voxels 5..=14, one layer of 100; nothing is
        // enclosed. Parity sees an open surface and keeps nothing.
        let positions = [
            [-0.45, -0.45, 0.05],
            [0.45, -0.45, 0.05],
            [0.45, 0.45, 0.05],
            [-0.45, 0.45, 0.05],
        ];
        let faces = [[0, 1, 2], [0, 2, 3]];
        let cube = Cube {
            center: [0.0; 3],
            half: 1.0,
        };
        let c = voxelize_mesh_conservative(&positions, &faces, &cube, 20).unwrap();
        assert_eq!(c.count(), 100);
        assert!(c.get([5, 5, 10]) && c.get([14, 14, 10]) && !c.get([4, 10, 10]));
        assert_eq!(
            voxelize_mesh(&positions, &faces, &cube, 20)
                .unwrap()
                .occupancy
                .count(),
            0
        );
        let bad = [[f32::NAN, 0.0, 0.0], [0.0; 3], [1.0; 3]];
        assert!(matches!(
            voxelize_mesh_conservative(&bad, &[[0, 1, 2]], &cube, 20),
            Err(Error::Input(_))
        ));
        assert!(matches!(
            voxelize_mesh_conservative(&positions, &[[0, 1, 7]], &cube, 20),
            Err(Error::Input(_))
        ));
    }
}
