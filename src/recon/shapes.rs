//! Procedural ShapeNet-like objects for the reconstruction dataset: each category is a recipe of
//! parametric parts (boxes, tapered and sheared hexahedra, cylinders and cones) whose
//! proportions, styles and colours are drawn from a seeded SplitMix64 stream, so a seed gives
//! the same object on every platform.
//!
//! **Conventions** (ShapeNet's, as NMR renders it): +y up; an object's front (a chair's seat
//! edge, an airplane's nose, a car's bonnet) faces −z, towards the eye of view 0
//! (`eye_from_angles(d, el, 0)` lies on −z); its left–right axis is x. Each object is centred
//! (bounding-box centre at the origin) and scaled so its longest side is [`NORMALIZED_EXTENT`],
//! inside the unit cube [-0.5, 0.5]³.
//!
//! Every part is a closed, outward-wound triangle mesh on its own; parts overlap (a leg enters
//! the seat), so the object as a whole is a union of shells, not one closed surface: voxelize
//! per part and OR the occupancies ([`Shape::voxelize`]). Parts are at least [`MIN_THICKNESS`]
//! thick, more than the 1/31 spacing of the dataset's voxel centres, so no part falls between
//! voxel centres.

use glam::DVec3;

use crate::error::{Error, Result};
use crate::field::Cube;
use crate::field::voxel::{Occupancy, voxelize_mesh};
use crate::mesh::Mesh;
use crate::rng::SplitMix64;

/// The longest side of every normalized object (a hair under 1, so that no face lies exactly
/// on the voxel centres at ±0.5).
pub const NORMALIZED_EXTENT: f64 = 0.98;

/// The thinnest a part is made (before normalization, which scales by at most a little).
pub const MIN_THICKNESS: f64 = 0.045;

/// Segments around a cylinder or cone.
const SEGMENTS: u32 = 12;

/// An object category, with its ShapeNet synset id (the class id of the NMR/SoftRas files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Category {
    /// Airplane (`02691156`): airliner (swept wings, tail, optional engines), fighter (delta
    /// wings, one or two fins) or propeller plane (straight high or low wings).
    Airplane,
    /// Bench (`02828884`): long seat on slab or post legs with an optional slatted back, a
    /// picnic bench on A-frames, or an ottoman block.
    Bench,
    /// Cabinet (`02933112`): a body with doors or drawers and handles, optional feet.
    Cabinet,
    /// Car (`02958343`): sedan, van, pickup or sports car: body, cabin, four wheels.
    Car,
    /// Chair (`03001627`): four-legged (posts, round, splayed; tilted back, optional arms),
    /// office chair (column and five spokes), stool, or armchair with solid sides.
    Chair,
    /// Display (`03211117`): thin screen on a neck and a foot.
    Display,
    /// Lamp (`03636649`): desk lamp (straight or bent pole, conical shade), floor lamp, arc
    /// lamp, or table lamp on a vase.
    Lamp,
    /// Sofa (`04256520`): base, back, arms, cushions.
    Sofa,
    /// Table (`04379243`): rectangular or round top on four legs or a pedestal (optional
    /// shelf), coffee table, desk on side panels, or trestle table.
    Table,
}

impl Category {
    /// Every category, in synset order.
    pub const ALL: [Category; 9] = [
        Category::Airplane,
        Category::Bench,
        Category::Cabinet,
        Category::Car,
        Category::Chair,
        Category::Display,
        Category::Lamp,
        Category::Sofa,
        Category::Table,
    ];

    /// The lower-case name: `airplane`, `bench`, …
    pub fn name(self) -> &'static str {
        match self {
            Category::Airplane => "airplane",
            Category::Bench => "bench",
            Category::Cabinet => "cabinet",
            Category::Car => "car",
            Category::Chair => "chair",
            Category::Display => "display",
            Category::Lamp => "lamp",
            Category::Sofa => "sofa",
            Category::Table => "table",
        }
    }

    /// The ShapeNet synset id, which names the dataset files as SoftRas's `class_ids_map` does.
    pub fn synset(self) -> &'static str {
        match self {
            Category::Airplane => "02691156",
            Category::Bench => "02828884",
            Category::Cabinet => "02933112",
            Category::Car => "02958343",
            Category::Chair => "03001627",
            Category::Display => "03211117",
            Category::Lamp => "03636649",
            Category::Sofa => "04256520",
            Category::Table => "04379243",
        }
    }

    /// The category of a name or a synset id (case-insensitive name).
    pub fn parse(s: &str) -> Result<Category> {
        let t = s.trim().to_ascii_lowercase();
        Category::ALL
            .into_iter()
            .find(|c| c.name() == t || c.synset() == t)
            .ok_or_else(|| {
                Error::Input(format!(
                    "unknown category `{s}`; known: {}",
                    Category::ALL.map(|c| c.name()).join(", ")
                ))
            })
    }

    /// The category whose synset id is `id`, if any.
    pub fn from_synset(id: &str) -> Option<Category> {
        Category::ALL.into_iter().find(|c| c.synset() == id)
    }
}

impl std::fmt::Display for Category {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One closed part of an object: an outward-wound triangle mesh and its flat colour.
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Triangles, outward wound (SPEC §1 normal points out).
    pub faces: Vec<[u32; 3]>,
    /// Linear RGB in [0, 1].
    pub color: [f32; 3],
}

/// A generated object: its category and closed parts, normalized into the unit cube.
#[derive(Clone, Debug, PartialEq)]
pub struct Shape {
    /// What it is.
    pub category: Category,
    /// Its parts, each closed.
    pub parts: Vec<Part>,
}

impl Shape {
    /// All parts in one mesh (parts in order), per-face colours as R = 1 textures.
    pub fn mesh(&self) -> Result<Mesh> {
        let mut positions = Vec::new();
        let mut faces = Vec::new();
        let mut colors = Vec::new();
        for p in &self.parts {
            let base = positions.len() as u32;
            positions.extend_from_slice(&p.positions);
            faces.extend(p.faces.iter().map(|f| f.map(|i| i + base)));
            colors.extend(std::iter::repeat_n(p.color, p.faces.len()));
        }
        let mut mesh = Mesh::new(positions, faces, 1)?;
        mesh.textures = colors;
        Ok(mesh)
    }

    /// Triangles over all parts.
    pub fn face_count(&self) -> usize {
        self.parts.iter().map(|p| p.faces.len()).sum()
    }

    /// The axis-aligned bounding box (min, max) of every vertex.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in self.parts.iter().flat_map(|p| &p.positions) {
            for k in 0..3 {
                lo[k] = lo[k].min(f64::from(p[k]));
                hi[k] = hi[k].max(f64::from(p[k]));
            }
        }
        (lo, hi)
    }

    /// The voxels whose centre is inside some part: each part voxelized on its own by
    /// [`voxelize_mesh`] (parity along x; a part is closed) and the results OR-ed, since the
    /// union of overlapping shells is not a surface a parity test can read.
    pub fn voxelize(&self, cube: &Cube, res: u32) -> Result<Occupancy> {
        let mut occ = Occupancy::empty(*cube, res);
        for (i, p) in self.parts.iter().enumerate() {
            let v = voxelize_mesh(&p.positions, &p.faces, cube, res)?;
            if v.odd_rays != 0 {
                return Err(Error::Check(format!(
                    "{} part {i} is not closed: {} voxel rows crossed it an odd number of times",
                    self.category, v.odd_rays
                )));
            }
            for (o, x) in occ.inside.iter_mut().zip(&v.occupancy.inside) {
                *o |= *x;
            }
        }
        Ok(occ)
    }
}

/// The object of `category` drawn from `seed`: the same seed gives the same object, bit for bit.
pub fn generate(category: Category, seed: u64) -> Shape {
    let mut b = Builder {
        rng: SplitMix64(seed),
        parts: Vec::new(),
    };
    match category {
        Category::Airplane => airplane(&mut b),
        Category::Bench => bench(&mut b),
        Category::Cabinet => cabinet(&mut b),
        Category::Car => car(&mut b),
        Category::Chair => chair(&mut b),
        Category::Display => display(&mut b),
        Category::Lamp => lamp(&mut b),
        Category::Sofa => sofa(&mut b),
        Category::Table => table(&mut b),
    }
    b.finish(category)
}

/// Parts in f64 while an object is built.
struct RawPart {
    positions: Vec<DVec3>,
    faces: Vec<[u32; 3]>,
    color: [f32; 3],
}

struct Builder {
    rng: SplitMix64,
    parts: Vec<RawPart>,
}

impl Builder {
    /// Uniform in [lo, hi).
    fn u(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.rng.unit()
    }

    /// True with probability `p`.
    fn chance(&mut self, p: f64) -> bool {
        self.rng.unit() < p
    }

    /// A colour: random hue, moderate saturation, bright enough to see under the lights.
    fn color(&mut self) -> [f32; 3] {
        let h = self.u(0.0, 6.0);
        let s = self.u(0.25, 0.8);
        let v = self.u(0.45, 0.95);
        let c = v * s;
        let x = c * (1.0 - ((h % 2.0) - 1.0).abs());
        let (r, g, b) = match h as u32 {
            0 => (c, x, 0.0),
            1 => (x, c, 0.0),
            2 => (0.0, c, x),
            3 => (0.0, x, c),
            4 => (x, 0.0, c),
            _ => (c, 0.0, x),
        };
        let m = v - c;
        [(r + m) as f32, (g + m) as f32, (b + m) as f32]
    }

    /// A dark grey (tyres, screens).
    fn dark(&mut self) -> [f32; 3] {
        let v = self.u(0.08, 0.2) as f32;
        [v, v, v]
    }

    fn push(&mut self, (positions, faces): (Vec<DVec3>, Vec<[u32; 3]>), color: [f32; 3]) {
        self.parts.push(RawPart {
            positions,
            faces,
            color,
        });
    }

    /// An axis-aligned box from its min and max corners.
    fn cuboid(&mut self, lo: DVec3, hi: DVec3, color: [f32; 3]) {
        let hi = lo.max(hi);
        let lo2 = lo.min(hi);
        self.push(hexahedron(box_corners(lo2, hi)), color);
    }

    fn frustum(&mut self, p0: DVec3, p1: DVec3, r0: f64, r1: f64, color: [f32; 3]) {
        self.push(frustum(p0, p1, r0, r1, SEGMENTS), color);
    }

    /// Centres and scales every part together into the unit cube.
    fn finish(self, category: Category) -> Shape {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in self.parts.iter().flat_map(|p| &p.positions) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let centre = (lo + hi) / 2.0;
        let scale = NORMALIZED_EXTENT / (hi - lo).max_element();
        let parts = self
            .parts
            .into_iter()
            .map(|p| Part {
                positions: p
                    .positions
                    .iter()
                    .map(|&v| ((v - centre) * scale).as_vec3().to_array())
                    .collect(),
                faces: p.faces,
                color: p.color,
            })
            .collect();
        Shape { category, parts }
    }
}

/// The 8 corners of an axis-aligned box, corner `i` at (x, y, z) = bits (1, 2, 4) of `i`.
fn box_corners(lo: DVec3, hi: DVec3) -> [DVec3; 8] {
    std::array::from_fn(|i| {
        DVec3::new(
            if i & 1 != 0 { hi.x } else { lo.x },
            if i & 2 != 0 { hi.y } else { lo.y },
            if i & 4 != 0 { hi.z } else { lo.z },
        )
    })
}

/// A closed hexahedron from 8 corners indexed as [`box_corners`] (any convex-ish deformation of
/// a box: tapered, sheared, swept), quads split in two, wound outward.
fn hexahedron(c: [DVec3; 8]) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    // Quads counter-clockwise seen from outside for a positively oriented box (as
    // `Mesh::cuboid`).
    let quads = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    let faces = quads
        .iter()
        .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
        .collect();
    orient_outward(c.to_vec(), faces)
}

/// A closed cylinder or truncated cone from `p0` (radius `r0`) to `p1` (radius `r1`), `n`
/// segments, capped, wound outward.
fn frustum(p0: DVec3, p1: DVec3, r0: f64, r1: f64, n: u32) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let axis = (p1 - p0).normalize();
    let u = axis.any_orthonormal_vector();
    let v = axis.cross(u);
    let mut pos = Vec::with_capacity(2 * n as usize + 2);
    for (c, r) in [(p0, r0), (p1, r1)] {
        for k in 0..n {
            let t = std::f64::consts::TAU * f64::from(k) / f64::from(n);
            pos.push(c + r * (t.cos() * u + t.sin() * v));
        }
    }
    let (c0, c1) = (2 * n, 2 * n + 1);
    pos.push(p0);
    pos.push(p1);
    let mut faces = Vec::with_capacity(4 * n as usize);
    for k in 0..n {
        let k1 = (k + 1) % n;
        let (b0, b1, t0, t1) = (k, k1, n + k, n + k1);
        faces.push([b0, b1, t1]);
        faces.push([b0, t1, t0]);
        faces.push([c0, b1, b0]);
        faces.push([c1, t0, t1]);
    }
    orient_outward(pos, faces)
}

/// Flips every face when the closed mesh's signed volume is negative, so each primitive is
/// outward wound whichever way its corners were handed.
fn orient_outward(pos: Vec<DVec3>, mut faces: Vec<[u32; 3]>) -> (Vec<DVec3>, Vec<[u32; 3]>) {
    let vol: f64 = faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| pos[i as usize]);
            a.dot(b.cross(c))
        })
        .sum();
    if vol < 0.0 {
        for f in &mut faces {
            f.swap(1, 2);
        }
    }
    (pos, faces)
}

/// A box with its top face shifted by `shift` and scaled about its centre by `taper` (x, z):
/// a tilted chair back, a car cabin, a lamp shade's box cousin.
fn sheared_box(lo: DVec3, hi: DVec3, shift: DVec3, taper: [f64; 2]) -> [DVec3; 8] {
    let mut c = box_corners(lo, hi);
    let mid = (lo + hi) / 2.0;
    for (i, p) in c.iter_mut().enumerate() {
        if i & 2 != 0 {
            p.x = mid.x + (p.x - mid.x) * taper[0];
            p.z = mid.z + (p.z - mid.z) * taper[1];
            *p += shift;
        }
    }
    c
}

/// One of `n` styles, uniformly.
fn style(b: &mut Builder, n: u32) -> u32 {
    ((b.rng.unit() * f64::from(n)) as u32).min(n - 1)
}

// Each category draws one of several styles (ShapeNet's categories hold many kinds of object:
// stools and office chairs are chairs, pickups and vans are cars), so that a test object rarely
// has a near twin among a few dozen training objects.

fn chair(b: &mut Builder) {
    match style(b, 4) {
        0 => four_leg_chair(b),
        1 => office_chair(b),
        2 => stool(b),
        _ => armchair(b),
    }
}

fn table(b: &mut Builder) {
    match style(b, 4) {
        0 => leg_table(b),
        1 => coffee_table(b),
        2 => desk(b),
        _ => trestle_table(b),
    }
}

fn airplane(b: &mut Builder) {
    match style(b, 3) {
        0 => airliner(b),
        1 => fighter(b),
        _ => propeller_plane(b),
    }
}

fn car(b: &mut Builder) {
    match style(b, 4) {
        0 => sedan(b),
        1 => van(b),
        2 => pickup(b),
        _ => sports_car(b),
    }
}

fn lamp(b: &mut Builder) {
    match style(b, 4) {
        0 => desk_lamp(b),
        1 => floor_lamp(b),
        2 => arc_lamp(b),
        _ => vase_lamp(b),
    }
}

fn bench(b: &mut Builder) {
    match style(b, 3) {
        0 => leg_bench(b),
        1 => picnic_bench(b),
        _ => ottoman_bench(b),
    }
}

/// Office chair: seat and back on a column, five spokes with casters.
fn office_chair(b: &mut Builder) {
    let shell = b.color();
    let metal = b.dark();
    let w = b.u(0.4, 0.55) / 2.0;
    let d = b.u(0.38, 0.5) / 2.0;
    let h = b.u(0.4, 0.55);
    let t = b.u(0.06, 0.1);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), shell);
    let cr = b.u(0.025, 0.04);
    b.frustum(v(0.0, 0.06, 0.0), v(0.0, h + 0.01, 0.0), cr, cr, metal);
    let spoke = b.u(0.22, 0.3);
    let sr = MIN_THICKNESS / 2.0 * b.u(1.0, 1.4);
    let turn = b.u(0.0, 1.0);
    for k in 0..5 {
        let a = std::f64::consts::TAU * (f64::from(k) + turn) / 5.0;
        let end = v(spoke * a.cos(), 0.06, spoke * a.sin());
        b.frustum(v(0.0, 0.06, 0.0), end, sr, sr, metal);
        b.frustum(end - v(0.0, 0.06, 0.0), end, sr * 1.2, sr * 1.2, metal);
    }
    let bh = b.u(0.3, 0.55);
    let bt = b.u(0.05, 0.09);
    let back = sheared_box(
        v(-w * 0.9, h + t, d - bt),
        v(w * 0.9, h + t + bh, d),
        v(0.0, 0.0, b.u(0.02, 0.1)),
        [b.u(0.75, 1.0), 1.0],
    );
    b.push(hexahedron(back), shell);
    if b.chance(0.5) {
        let ah = b.u(0.15, 0.22);
        let aw = MIN_THICKNESS * 1.2;
        for sx in [-1.0, 1.0] {
            let x = sx * (w - aw / 2.0);
            b.cuboid(
                v(x - aw / 2.0, h + t, -aw / 2.0),
                v(x + aw / 2.0, h + t + ah, aw / 2.0),
                metal,
            );
            b.cuboid(
                v(x - aw, h + t + ah - aw, -d * 0.7),
                v(x + aw, h + t + ah, d * 0.5),
                metal,
            );
        }
    }
}

/// Stool: a round (or square) seat on three or four splayed legs, no back.
fn stool(b: &mut Builder) {
    let seat = b.color();
    let wood = if b.chance(0.5) { seat } else { b.color() };
    let r = b.u(0.14, 0.22);
    let h = b.u(0.45, 0.8);
    let t = b.u(MIN_THICKNESS, 0.08);
    if b.chance(0.6) {
        b.frustum(v(0.0, h, 0.0), v(0.0, h + t, 0.0), r, r, seat);
    } else {
        b.cuboid(v(-r, h, -r), v(r, h + t, r), seat);
    }
    let n = 3 + style(b, 2);
    let s = b.u(MIN_THICKNESS, 0.06) / 2.0;
    let splay = b.u(0.02, 0.12);
    let turn = b.u(0.0, 1.0);
    let ring = b.chance(0.5);
    let ry = h * b.u(0.25, 0.4);
    for k in 0..n {
        let a = std::f64::consts::TAU * (f64::from(k) + turn) / f64::from(n);
        let (c, sn) = (a.cos(), a.sin());
        let top = v(c * r * 0.65, h + t / 2.0, sn * r * 0.65);
        let foot = v(c * (r * 0.65 + splay), 0.0, sn * (r * 0.65 + splay));
        b.frustum(foot, top, s, s, wood);
        if ring {
            let f = ry / (h + t / 2.0);
            let p = foot + (top - foot) * f;
            let a2 = std::f64::consts::TAU * (f64::from(k) + 1.0 + turn) / f64::from(n);
            let q_foot = v(
                a2.cos() * (r * 0.65 + splay),
                0.0,
                a2.sin() * (r * 0.65 + splay),
            );
            let q_top = v(a2.cos() * r * 0.65, h + t / 2.0, a2.sin() * r * 0.65);
            let q = q_foot + (q_top - q_foot) * f;
            b.frustum(p, q, s, s, wood);
        }
    }
}

/// Armchair: a low, wide seat between solid sides that reach the floor, a solid back.
fn armchair(b: &mut Builder) {
    let cloth = b.color();
    let w = b.u(0.6, 0.85) / 2.0;
    let d = b.u(0.55, 0.75) / 2.0;
    let h = b.u(0.25, 0.38);
    let at = b.u(0.08, 0.14);
    let ah = h + b.u(0.12, 0.22);
    b.cuboid(v(-w + at, 0.05, -d), v(w - at, h, d), cloth);
    for sx in [-1.0, 1.0] {
        let x0 = sx * w;
        let x1 = x0 - sx * at;
        b.cuboid(v(x0.min(x1), 0.0, -d), v(x0.max(x1), ah, d), cloth);
    }
    let bt = b.u(0.1, 0.16);
    let bh = b.u(0.55, 0.8);
    let back = sheared_box(
        v(-w, 0.0, d - bt),
        v(w, bh, d),
        v(0.0, 0.0, b.u(0.0, 0.08)),
        [1.0, 1.0],
    );
    b.push(hexahedron(back), cloth);
    if b.chance(0.6) {
        let cushion = b.color();
        let ch = b.u(0.05, 0.1);
        b.cuboid(
            v(-w + at + 0.01, h - 0.01, -d - 0.01),
            v(w - at - 0.01, h + ch, d - bt),
            cushion,
        );
    }
}

/// Coffee table: low and wide, on four short legs or two slab ends, often a shelf.
fn coffee_table(b: &mut Builder) {
    let top_color = b.color();
    let leg_color = if b.chance(0.5) { top_color } else { b.color() };
    let w = b.u(0.75, 1.0) / 2.0;
    let d = b.u(0.4, 0.75) / 2.0;
    let h = b.u(0.22, 0.38);
    let t = b.u(MIN_THICKNESS, 0.09);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), top_color);
    let s = b.u(MIN_THICKNESS, 0.09) / 2.0;
    let inset = b.u(0.0, 0.08) + s;
    if b.chance(0.5) {
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (w - inset), 0.0, sz * (d - inset));
            b.cuboid(c - v(s, 0.0, s), c + v(s, h + t / 2.0, s), leg_color);
        }
    } else {
        for sx in [-1.0, 1.0] {
            let x = sx * (w - inset);
            b.cuboid(v(x - s, 0.0, -d), v(x + s, h + t / 2.0, d), leg_color);
        }
    }
    if b.chance(0.5) {
        let sh = b.u(0.04, h * 0.5);
        b.cuboid(
            v(-w + inset, sh, -d + inset * 0.5),
            v(w - inset, sh + MIN_THICKNESS, d - inset * 0.5),
            leg_color,
        );
    }
}

/// Desk: a top on two side panels, often a drawer pedestal and a modesty panel at the back.
fn desk(b: &mut Builder) {
    let top_color = b.color();
    let body = if b.chance(0.5) { top_color } else { b.color() };
    let w = b.u(0.8, 1.0) / 2.0;
    let d = b.u(0.4, 0.6) / 2.0;
    let h = b.u(0.55, 0.75);
    let t = b.u(MIN_THICKNESS, 0.06);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), top_color);
    let pt = b.u(MIN_THICKNESS, 0.07);
    let side = if b.chance(0.5) { -1.0 } else { 1.0 };
    let pedestal = b.chance(0.6);
    let pw = b.u(0.25, 0.4);
    for sx in [-1.0, 1.0] {
        let x0 = sx * w;
        let x1 = if pedestal && sx == side {
            x0 - sx * pw
        } else {
            x0 - sx * pt
        };
        b.cuboid(v(x0.min(x1), 0.0, -d), v(x0.max(x1), h + t / 2.0, d), body);
    }
    if b.chance(0.6) {
        let mh = h * b.u(0.3, 0.7);
        b.cuboid(v(-w + pt, h - mh, d - pt), v(w - pt, h + t / 2.0, d), body);
    }
}

/// Trestle table: a long top on two I-shaped ends (foot, post, cleat) joined by a stretcher.
fn trestle_table(b: &mut Builder) {
    let top_color = b.color();
    let wood = if b.chance(0.5) { top_color } else { b.color() };
    let w = b.u(0.8, 1.0) / 2.0;
    let d = b.u(0.35, 0.6) / 2.0;
    let h = b.u(0.5, 0.75);
    let t = b.u(MIN_THICKNESS, 0.08);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), top_color);
    let s = b.u(0.05, 0.1) / 2.0;
    let ft = b.u(MIN_THICKNESS, 0.07);
    let inset = b.u(0.08, 0.2);
    for sx in [-1.0, 1.0] {
        let x = sx * (w - inset);
        b.cuboid(v(x - s, 0.0, -d * 0.9), v(x + s, ft, d * 0.9), wood);
        b.cuboid(v(x - s, ft - 0.01, -s), v(x + s, h - ft + 0.01, s), wood);
        b.cuboid(
            v(x - s, h - ft, -d * 0.85),
            v(x + s, h + 0.005, d * 0.85),
            wood,
        );
    }
    let sy = h * b.u(0.3, 0.6);
    let st = MIN_THICKNESS / 2.0 * 1.2;
    b.cuboid(v(-w + inset, sy - st, -st), v(w - inset, sy + st, st), wood);
}

/// Fighter: a short, thick fuselage, delta wings, one or two fins.
fn fighter(b: &mut Builder) {
    let body = b.color();
    let wing_color = if b.chance(0.6) { body } else { b.color() };
    let len = b.u(0.8, 1.0);
    let r = b.u(0.06, 0.09);
    let z0 = -len / 2.0;
    let nose = b.u(0.15, 0.25);
    b.frustum(v(0.0, 0.0, z0 + nose), v(0.0, 0.0, -z0), r, r * 0.8, body);
    b.frustum(v(0.0, 0.0, z0 + nose), v(0.0, 0.0, z0), r, r * 0.15, body);
    let span = b.u(0.22, 0.34);
    let chord = b.u(0.35, 0.5);
    let wz = -z0 - chord - b.u(0.02, 0.1);
    let taper = b.u(0.08, 0.25);
    let sweep = chord * (1.0 - taper) * b.u(0.8, 1.0);
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(
                sx,
                wz,
                0.0,
                span,
                chord,
                taper,
                sweep,
                0.0,
                MIN_THICKNESS,
            )),
            wing_color,
        );
    }
    let fin_h = b.u(0.12, 0.2);
    let fc = b.u(0.12, 0.2);
    let twin = b.chance(0.5);
    let xs: &[f64] = if twin { &[-1.0, 1.0] } else { &[0.0] };
    for &sx in xs {
        let x = sx * r * 0.7;
        let fin = sheared_box(
            v(x - MIN_THICKNESS / 2.0, 0.0, -z0 - fc),
            v(x + MIN_THICKNESS / 2.0, r + fin_h, -z0),
            v(sx * 0.03, 0.0, fc * 0.4),
            [1.0, 0.5],
        );
        b.push(hexahedron(fin), wing_color);
    }
}

/// Propeller plane: straight, untapered wings on top of the fuselage, a propeller disc.
fn propeller_plane(b: &mut Builder) {
    let body = b.color();
    let wing_color = if b.chance(0.5) { body } else { b.color() };
    let len = b.u(0.6, 0.8);
    let r = b.u(0.05, 0.08);
    let z0 = -len / 2.0;
    b.frustum(
        v(0.0, 0.0, z0 + 0.05),
        v(0.0, r * 0.4, -z0),
        r,
        r * 0.35,
        body,
    );
    b.frustum(v(0.0, 0.0, z0 + 0.05), v(0.0, 0.0, z0), r, r * 0.6, body);
    let prop = b.u(0.1, 0.16);
    let prop_color = b.dark().map(|c| c * 2.0);
    b.frustum(
        v(0.0, 0.0, z0 - 0.005),
        v(0.0, 0.0, z0 - 0.005 - MIN_THICKNESS),
        prop,
        prop,
        prop_color,
    );
    let span = b.u(0.45, 0.55);
    let chord = b.u(0.1, 0.16);
    let wz = z0 + len * b.u(0.2, 0.35);
    let high = b.chance(0.6);
    let wy = if high { r * 0.9 } else { -r * 0.5 };
    let taper = b.u(0.75, 1.0);
    let dihedral = b.u(0.0, 0.03);
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(
                sx,
                wz,
                wy,
                span,
                chord,
                taper,
                0.0,
                dihedral,
                MIN_THICKNESS,
            )),
            wing_color,
        );
    }
    let tspan = span * b.u(0.3, 0.4);
    let tchord = chord * b.u(0.7, 1.0);
    let tz = -z0 - tchord;
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(
                sx,
                tz,
                r * 0.4,
                tspan,
                tchord,
                0.8,
                0.02,
                0.0,
                MIN_THICKNESS,
            )),
            wing_color,
        );
    }
    let fin_h = b.u(0.1, 0.16);
    let fin = sheared_box(
        v(-MIN_THICKNESS / 2.0, r * 0.3, tz),
        v(MIN_THICKNESS / 2.0, r + fin_h, -z0),
        v(0.0, 0.0, tchord * 0.4),
        [1.0, 0.6],
    );
    b.push(hexahedron(fin), wing_color);
}

/// The four wheels of a car: `wr` radius, `ww` wide, at `±wz` along its length.
fn wheels(b: &mut Builder, w: f64, wr: f64, ww: f64, wz: [f64; 2], tyre: [f32; 3]) {
    for sx in [-1.0, 1.0] {
        for z in wz {
            let x = sx * (w - ww * 0.3);
            b.frustum(v(x - ww / 2.0, wr, z), v(x + ww / 2.0, wr, z), wr, wr, tyre);
        }
    }
}

/// Van or SUV: a tall body and a long, tall cabin.
fn van(b: &mut Builder) {
    let paint = b.color();
    let glass = if b.chance(0.5) { b.dark() } else { paint };
    let tyre = b.dark();
    let l = b.u(0.8, 1.0) / 2.0;
    let w = b.u(0.4, 0.5) / 2.0;
    let wr = b.u(0.07, 0.11);
    let body_h = b.u(0.16, 0.26);
    let y0 = wr * 0.7;
    b.cuboid(v(-w, y0, -l), v(w, y0 + body_h, l), paint);
    let front = b.u(0.05, 0.35) * l;
    let cab_h = b.u(0.14, 0.26);
    let cabin = sheared_box(
        v(-w * 0.95, y0 + body_h - 0.01, -l + front),
        v(w * 0.95, y0 + body_h + cab_h, l - 0.01),
        v(0.0, 0.0, b.u(0.0, 0.04)),
        [b.u(0.9, 1.0), b.u(0.85, 0.98)],
    );
    b.push(hexahedron(cabin), glass);
    let ww = b.u(MIN_THICKNESS, 0.08);
    let wz = l * b.u(0.6, 0.75);
    wheels(b, w, wr, ww, [-wz, wz], tyre);
}

/// Pickup: a cabin at the front, an open bed behind it.
fn pickup(b: &mut Builder) {
    let paint = b.color();
    let glass = if b.chance(0.5) { b.dark() } else { paint };
    let tyre = b.dark();
    let l = b.u(0.9, 1.0) / 2.0;
    let w = b.u(0.4, 0.48) / 2.0;
    let wr = b.u(0.08, 0.11);
    let body_h = b.u(0.14, 0.2);
    let y0 = wr * 0.75;
    b.cuboid(v(-w, y0, -l), v(w, y0 + body_h, l), paint);
    let cab_front = -l + b.u(0.25, 0.4) * l;
    let cab_back = cab_front + b.u(0.45, 0.65) * l;
    let cab_h = b.u(0.14, 0.2);
    let cabin = sheared_box(
        v(-w * 0.95, y0 + body_h - 0.01, cab_front),
        v(w * 0.95, y0 + body_h + cab_h, cab_back),
        v(0.0, 0.0, 0.01),
        [0.95, b.u(0.7, 0.9)],
    );
    b.push(hexahedron(cabin), glass);
    let bed_h = b.u(0.05, 0.1);
    let t = MIN_THICKNESS;
    let y1 = y0 + body_h - 0.01;
    for sx in [-1.0, 1.0] {
        let x0 = sx * w;
        let x1 = x0 - sx * t;
        b.cuboid(
            v(x0.min(x1), y1, cab_back),
            v(x0.max(x1), y1 + bed_h, l),
            paint,
        );
    }
    b.cuboid(v(-w, y1, l - t), v(w, y1 + bed_h, l), paint);
    let ww = b.u(MIN_THICKNESS, 0.08);
    let wz = [-l * b.u(0.6, 0.72), l * b.u(0.55, 0.7)];
    wheels(b, w, wr, ww, wz, tyre);
}

/// Sports car: low and wide, a low swept cabin, big wheels.
fn sports_car(b: &mut Builder) {
    let paint = b.color();
    let glass = b.dark();
    let tyre = b.dark();
    let l = b.u(0.85, 1.0) / 2.0;
    let w = b.u(0.44, 0.52) / 2.0;
    let wr = b.u(0.08, 0.1);
    let body_h = b.u(0.07, 0.11);
    let y0 = wr * 0.6;
    let nose = sheared_box(
        v(-w, y0, -l),
        v(w, y0 + body_h, l),
        v(0.0, 0.0, 0.0),
        [1.0, b.u(0.9, 1.0)],
    );
    b.push(hexahedron(nose), paint);
    let cab_l = b.u(0.3, 0.45) * l;
    let cab_h = b.u(0.06, 0.1);
    let cab_z = b.u(0.0, 0.2) * l;
    let cabin = sheared_box(
        v(-w * 0.85, y0 + body_h - 0.01, cab_z - cab_l),
        v(w * 0.85, y0 + body_h + cab_h, cab_z + cab_l),
        v(0.0, 0.0, b.u(0.02, 0.06)),
        [b.u(0.8, 0.9), b.u(0.4, 0.6)],
    );
    b.push(hexahedron(cabin), glass);
    if b.chance(0.4) {
        let sp = MIN_THICKNESS;
        b.cuboid(
            v(-w * 0.9, y0 + body_h + 0.04, l - 0.08),
            v(w * 0.9, y0 + body_h + 0.04 + sp, l - 0.01),
            paint,
        );
        for sx in [-1.0, 1.0] {
            let x = sx * w * 0.6;
            b.cuboid(
                v(x - sp / 2.0, y0 + body_h - 0.01, l - 0.03 - sp),
                v(x + sp / 2.0, y0 + body_h + 0.045, l - 0.03),
                paint,
            );
        }
    }
    let ww = b.u(0.05, 0.09);
    let wz = l * b.u(0.6, 0.72);
    wheels(b, w, wr, ww, [-wz, wz], tyre);
}

/// Floor lamp: a round base, a tall pole, a wide drum shade.
fn floor_lamp(b: &mut Builder) {
    let metal = b.color();
    let shade_color = b.color();
    let base_r = b.u(0.12, 0.2);
    let base_t = b.u(MIN_THICKNESS, 0.05);
    b.frustum(
        v(0.0, 0.0, 0.0),
        v(0.0, base_t, 0.0),
        base_r,
        base_r * 0.9,
        metal,
    );
    let pr = MIN_THICKNESS / 2.0 * b.u(1.0, 1.3);
    let h = b.u(0.75, 0.9);
    b.frustum(v(0.0, 0.0, 0.0), v(0.0, h, 0.0), pr, pr, metal);
    let sh = b.u(0.14, 0.22);
    let r = b.u(0.14, 0.22);
    let r_top = r * b.u(0.75, 1.0);
    b.frustum(
        v(0.0, h - sh * 0.6, 0.0),
        v(0.0, h + sh * 0.4, 0.0),
        r,
        r_top,
        shade_color,
    );
}

/// Arc lamp: a heavy block base, a pole, an arm out over the floor, a shade hanging open-down.
fn arc_lamp(b: &mut Builder) {
    let metal = b.color();
    let shade_color = b.color();
    let bs = b.u(0.08, 0.14);
    let bt = b.u(0.04, 0.08);
    b.cuboid(v(-bs, 0.0, -bs), v(bs, bt, bs), metal);
    let pr = MIN_THICKNESS / 2.0 * b.u(1.0, 1.3);
    let h = b.u(0.6, 0.85);
    let reach = b.u(0.3, 0.5);
    let rise = b.u(0.0, 0.12);
    b.frustum(v(0.0, 0.0, 0.0), v(0.0, h, 0.0), pr, pr, metal);
    let knee = v(0.0, h, 0.0);
    let mid = knee + v(0.0, rise, -reach * 0.5);
    let end = v(0.0, h + rise * 0.5, -reach);
    b.frustum(knee, mid, pr, pr, metal);
    b.frustum(mid, end, pr, pr, metal);
    let sh = b.u(0.1, 0.18);
    let r_low = b.u(0.1, 0.18);
    let r_top = r_low * b.u(0.2, 0.45);
    b.frustum(
        end - v(0.0, sh, 0.0),
        end + v(0.0, 0.01, 0.0),
        r_low,
        r_top,
        shade_color,
    );
}

/// Table lamp: a vase-shaped body, a short neck, a drum shade.
fn vase_lamp(b: &mut Builder) {
    let body = b.color();
    let shade_color = b.color();
    let r = b.u(0.09, 0.16);
    let bh = b.u(0.2, 0.35);
    let belly = bh * b.u(0.3, 0.6);
    let foot = r * b.u(0.5, 0.8);
    let shoulder = r * b.u(0.3, 0.6);
    b.frustum(v(0.0, 0.0, 0.0), v(0.0, belly, 0.0), foot, r, body);
    b.frustum(v(0.0, belly, 0.0), v(0.0, bh, 0.0), r, shoulder, body);
    let pr = MIN_THICKNESS / 2.0 * 1.2;
    let neck = b.u(0.05, 0.15);
    b.frustum(v(0.0, bh - 0.01, 0.0), v(0.0, bh + neck, 0.0), pr, pr, body);
    let sh = b.u(0.15, 0.28);
    let sr = b.u(0.14, 0.24);
    let sr_top = sr * b.u(0.6, 1.0);
    b.frustum(
        v(0.0, bh + neck - sh * 0.3, 0.0),
        v(0.0, bh + neck + sh * 0.7, 0.0),
        sr,
        sr_top,
        shade_color,
    );
}

/// Picnic bench: a seat on two A-frames of crossed legs, a stretcher between them.
fn picnic_bench(b: &mut Builder) {
    let wood = b.color();
    let l = b.u(0.85, 1.0) / 2.0;
    let d = b.u(0.22, 0.34) / 2.0;
    let h = b.u(0.35, 0.45);
    let t = b.u(MIN_THICKNESS, 0.07);
    b.cuboid(v(-l, h, -d), v(l, h + t, d), wood);
    let s = b.u(MIN_THICKNESS, 0.06) / 2.0;
    let inset = b.u(0.08, 0.2);
    let spread = b.u(0.1, 0.2);
    for sx in [-1.0, 1.0] {
        let x = sx * (l - inset);
        for sz in [-1.0, 1.0] {
            b.frustum(
                v(x, 0.0, sz * (d + spread)),
                v(x, h + t / 2.0, -sz * d * 0.3),
                s,
                s,
                wood,
            );
        }
    }
    let sy = h * 0.4;
    b.cuboid(v(-l + inset, sy - s, -s), v(l - inset, sy + s, s), wood);
}

/// Ottoman bench: a padded block, on the floor or on short feet.
fn ottoman_bench(b: &mut Builder) {
    let cloth = b.color();
    let l = b.u(0.75, 1.0) / 2.0;
    let d = b.u(0.3, 0.45) / 2.0;
    let h = b.u(0.3, 0.42);
    let feet = b.chance(0.5);
    let y0 = if feet { b.u(0.05, 0.12) } else { 0.0 };
    b.cuboid(v(-l, y0, -d), v(l, h, d), cloth);
    if feet {
        let wood = b.color();
        let f = b.u(MIN_THICKNESS, 0.06) / 2.0;
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (l - f - 0.03), 0.0, sz * (d - f - 0.03));
            b.cuboid(c - v(f, 0.0, f), c + v(f, y0 + 0.01, f), wood);
        }
    }
    if b.chance(0.5) {
        let top = b.color();
        let th = b.u(0.04, 0.08);
        b.cuboid(
            v(-l + 0.01, h - 0.01, -d + 0.01),
            v(l - 0.01, h + th, d - 0.01),
            top,
        );
    }
}

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

fn four_leg_chair(b: &mut Builder) {
    let seat_color = b.color();
    let back_color = if b.chance(0.6) { seat_color } else { b.color() };
    let leg_color = b.color();
    let w = b.u(0.42, 0.6) / 2.0;
    let d = b.u(0.4, 0.58) / 2.0;
    let t = b.u(MIN_THICKNESS, 0.08);
    let h = b.u(0.36, 0.5);
    b.cuboid(v(-w, h, -d), v(w, h + t, d), seat_color);
    // Legs: square posts, round posts, or splayed posts.
    let style = (b.rng.unit() * 3.0) as u32;
    let s = b.u(MIN_THICKNESS, 0.065) / 2.0;
    let splay = if style == 2 { b.u(0.03, 0.07) } else { 0.0 };
    let inset = b.u(0.0, 0.04) + s;
    for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
        let top = v(sx * (w - inset), h + t / 2.0, sz * (d - inset));
        let foot = v(top.x + sx * splay, 0.0, top.z + sz * splay);
        match style {
            0 => b.cuboid(
                v(top.x - s, 0.0, top.z - s),
                v(top.x + s, h + t / 2.0, top.z + s),
                leg_color,
            ),
            _ => b.frustum(foot, top, s * 1.1, s * 1.1, leg_color),
        }
    }
    // Back at the rear (+z), tilted backwards.
    let bh = b.u(0.35, 0.6);
    let bt = b.u(MIN_THICKNESS, 0.07);
    let tilt = b.u(0.0, 0.1);
    let taper = b.u(0.8, 1.05);
    let back = sheared_box(
        v(-w, h + t * 0.5, d - bt),
        v(w, h + t + bh, d),
        v(0.0, 0.0, tilt),
        [taper, 1.0],
    );
    b.push(hexahedron(back), back_color);
    if b.chance(0.35) {
        let ah = b.u(0.16, 0.26);
        let aw = b.u(MIN_THICKNESS, 0.07);
        for sx in [-1.0, 1.0] {
            let x0 = sx * w;
            let x1 = x0 - sx * aw;
            // Support post at the front, then the rest on top of it.
            b.cuboid(
                v(x0.min(x1), h + t, -d + 0.02),
                v(x0.max(x1), h + t + ah, -d + 0.02 + aw),
                back_color,
            );
            b.cuboid(
                v(x0.min(x1), h + t + ah - aw, -d),
                v(x0.max(x1), h + t + ah, d),
                back_color,
            );
        }
    }
}

fn leg_table(b: &mut Builder) {
    let top_color = b.color();
    let leg_color = if b.chance(0.5) { top_color } else { b.color() };
    let h = b.u(0.5, 0.75);
    let t = b.u(MIN_THICKNESS, 0.07);
    let round = b.chance(0.3);
    if round {
        let r = b.u(0.3, 0.5);
        b.frustum(v(0.0, h, 0.0), v(0.0, h + t, 0.0), r, r, top_color);
        if b.chance(0.6) {
            // Pedestal: column and foot.
            let pr = b.u(0.03, 0.07);
            b.frustum(
                v(0.0, 0.0, 0.0),
                v(0.0, h + t / 2.0, 0.0),
                pr,
                pr,
                leg_color,
            );
            let fr = b.u(0.18, 0.3);
            let ft = b.u(MIN_THICKNESS, 0.06);
            b.frustum(v(0.0, 0.0, 0.0), v(0.0, ft, 0.0), fr, fr * 0.8, leg_color);
        } else {
            let s = b.u(MIN_THICKNESS, 0.06) / 2.0;
            let q = r * 0.6;
            for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
                let c = v(sx * q * 0.707, 0.0, sz * q * 0.707);
                b.frustum(c, c + v(0.0, h + t / 2.0, 0.0), s, s, leg_color);
            }
        }
    } else {
        let w = b.u(0.6, 1.0) / 2.0;
        let d = b.u(0.4, 0.7) / 2.0;
        b.cuboid(v(-w, h, -d), v(w, h + t, d), top_color);
        let s = b.u(MIN_THICKNESS, 0.08) / 2.0;
        let inset = b.u(0.0, 0.06) + s;
        let round_legs = b.chance(0.4);
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (w - inset), 0.0, sz * (d - inset));
            if round_legs {
                b.frustum(c, c + v(0.0, h + t / 2.0, 0.0), s, s * 0.8, leg_color);
            } else {
                b.cuboid(c - v(s, 0.0, s), c + v(s, h + t / 2.0, s), leg_color);
            }
        }
        if b.chance(0.3) {
            let sh = b.u(0.08, 0.2);
            b.cuboid(
                v(-w + inset, sh, -d + inset),
                v(w - inset, sh + MIN_THICKNESS, d - inset),
                leg_color,
            );
        }
    }
}

fn airliner(b: &mut Builder) {
    let body = b.color();
    let wing_color = if b.chance(0.5) { body } else { b.color() };
    let len = b.u(0.8, 1.0);
    let r = b.u(0.045, 0.08);
    let z0 = -len / 2.0;
    let nose = b.u(0.08, 0.15);
    let tail = b.u(0.12, 0.22);
    // Fuselage along z, nose at −z.
    b.frustum(v(0.0, 0.0, z0 + nose), v(0.0, 0.0, -z0 - tail), r, r, body);
    b.frustum(v(0.0, 0.0, z0 + nose), v(0.0, 0.0, z0), r, r * 0.25, body);
    b.frustum(
        v(0.0, 0.0, -z0 - tail),
        v(0.0, r * 0.5, -z0),
        r,
        r * 0.3,
        body,
    );
    // Wings: swept, tapered slabs from the fuselage's axis outwards.
    let span = b.u(0.35, 0.5);
    let chord = b.u(0.18, 0.32);
    let taper = b.u(0.3, 0.7);
    let sweep = b.u(0.0, 0.25);
    let wz = b.u(-0.12, 0.05);
    let wt = MIN_THICKNESS;
    let wy = b.u(-r * 0.6, r * 0.3);
    let dihedral = b.u(0.0, 0.06);
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(sx, wz, wy, span, chord, taper, sweep, dihedral, wt)),
            wing_color,
        );
    }
    // Tail plane and fin.
    let tspan = span * b.u(0.3, 0.45);
    let tchord = chord * b.u(0.45, 0.7);
    let tz = -z0 - tchord * 1.1;
    for sx in [-1.0f64, 1.0] {
        b.push(
            hexahedron(wing(sx, tz, r * 0.3, tspan, tchord, 0.6, 0.06, 0.0, wt)),
            wing_color,
        );
    }
    let fin_h = b.u(0.12, 0.22);
    let fc = tchord * 1.1;
    let fin = sheared_box(
        v(-wt / 2.0, 0.0, tz - fc * 0.2),
        v(wt / 2.0, r + fin_h, tz + fc * 0.8),
        v(0.0, 0.0, fc * 0.35),
        [1.0, 0.55],
    );
    b.push(hexahedron(fin), wing_color);
    if b.chance(0.5) {
        let er = b.u(0.03, 0.045);
        let el = b.u(0.12, 0.2);
        for sx in [-1.0, 1.0] {
            let x = sx * span * 0.45;
            let z = wz + sweep * 0.45 - el * 0.4;
            b.frustum(
                v(x, wy - er * 1.2, z),
                v(x, wy - er * 1.2, z + el),
                er,
                er * 0.85,
                body,
            );
        }
    }
}

/// A wing on side `sx` (±1): root at x = 0 from z = `z` over `chord`, tip at x = `sx span`,
/// swept back by `sweep`, tapered to `taper × chord`, raised by `dihedral`, `t` thick.
#[allow(clippy::too_many_arguments)]
fn wing(
    sx: f64,
    z: f64,
    y: f64,
    span: f64,
    chord: f64,
    taper: f64,
    sweep: f64,
    dihedral: f64,
    t: f64,
) -> [DVec3; 8] {
    std::array::from_fn(|i| {
        let tip = (i & 1 != 0) == (sx > 0.0);
        let top = i & 2 != 0;
        let back = i & 4 != 0;
        let (x, zs, c, yy) = if tip {
            (sx * span, z + sweep, chord * taper, y + dihedral)
        } else {
            (0.0, z, chord, y)
        };
        let thick = if tip { t * 0.8_f64.max(taper) } else { t };
        v(
            x,
            yy + if top { thick / 2.0 } else { -thick / 2.0 },
            zs + if back { c } else { 0.0 },
        )
    })
}

fn sedan(b: &mut Builder) {
    let paint = b.color();
    let glass = if b.chance(0.5) { b.dark() } else { paint };
    let tyre = b.dark();
    let l = b.u(0.85, 1.0) / 2.0;
    let w = b.u(0.36, 0.46) / 2.0;
    let wr = b.u(0.07, 0.1);
    let body_h = b.u(0.12, 0.2);
    let y0 = wr * 0.7;
    b.cuboid(v(-w, y0, -l), v(w, y0 + body_h, l), paint);
    let cab_l = b.u(0.45, 0.65) * l;
    let cab_h = b.u(0.1, 0.17);
    let cab_z = b.u(-0.1, 0.15) * l;
    let cabin = sheared_box(
        v(-w * 0.92, y0 + body_h - 0.01, cab_z - cab_l),
        v(w * 0.92, y0 + body_h + cab_h, cab_z + cab_l),
        v(0.0, 0.0, b.u(0.0, 0.05)),
        [b.u(0.8, 0.95), b.u(0.55, 0.8)],
    );
    b.push(hexahedron(cabin), glass);
    let ww = b.u(MIN_THICKNESS, 0.08);
    let wz = l * b.u(0.6, 0.75);
    for sx in [-1.0, 1.0] {
        for sz in [-1.0, 1.0] {
            let x = sx * (w - ww * 0.3);
            b.frustum(
                v(x - ww / 2.0, wr, sz * wz),
                v(x + ww / 2.0, wr, sz * wz),
                wr,
                wr,
                tyre,
            );
        }
    }
}

fn desk_lamp(b: &mut Builder) {
    let metal = b.color();
    let shade_color = b.color();
    let base_r = b.u(0.1, 0.18);
    let base_t = b.u(MIN_THICKNESS, 0.06);
    let round_base = b.chance(0.6);
    if round_base {
        b.frustum(
            v(0.0, 0.0, 0.0),
            v(0.0, base_t, 0.0),
            base_r,
            base_r * 0.85,
            metal,
        );
    } else {
        b.cuboid(v(-base_r, 0.0, -base_r), v(base_r, base_t, base_r), metal);
    }
    let pr = MIN_THICKNESS / 2.0 * b.u(1.0, 1.3);
    let h = b.u(0.5, 0.8);
    let bent = b.chance(0.45);
    let top = if bent {
        let knee = v(0.0, h * b.u(0.55, 0.75), 0.0);
        b.frustum(v(0.0, 0.0, 0.0), knee, pr, pr, metal);
        let reach = b.u(0.15, 0.3);
        let head = knee + v(0.0, h * 0.35, -reach);
        b.frustum(knee, head, pr, pr, metal);
        head
    } else {
        let head = v(0.0, h, 0.0);
        b.frustum(v(0.0, 0.0, 0.0), head, pr, pr, metal);
        head
    };
    let sh = b.u(0.14, 0.26);
    let r_low = b.u(0.12, 0.24);
    let r_high = r_low * b.u(0.35, 0.8);
    let drop = b.u(0.3, 0.7) * sh;
    b.frustum(
        top - v(0.0, drop, 0.0),
        top + v(0.0, sh - drop, 0.0),
        r_low,
        r_high,
        shade_color,
    );
}

fn leg_bench(b: &mut Builder) {
    let wood = b.color();
    let frame = if b.chance(0.5) { wood } else { b.color() };
    let l = b.u(0.85, 1.0) / 2.0;
    let d = b.u(0.24, 0.4) / 2.0;
    let h = b.u(0.32, 0.45);
    let t = b.u(MIN_THICKNESS, 0.07);
    b.cuboid(v(-l, h, -d), v(l, h + t, d), wood);
    let slab_legs = b.chance(0.5);
    let s = b.u(MIN_THICKNESS, 0.07) / 2.0;
    let inset = b.u(0.02, 0.1) + s;
    for sx in [-1.0, 1.0] {
        let x = sx * (l - inset);
        if slab_legs {
            b.cuboid(v(x - s, 0.0, -d), v(x + s, h + t / 2.0, d), frame);
        } else {
            for sz in [-1.0, 1.0] {
                let z = sz * (d - s - 0.01);
                b.cuboid(v(x - s, 0.0, z - s), v(x + s, h + t / 2.0, z + s), frame);
            }
        }
    }
    if b.chance(0.6) {
        let slats = 1 + (b.rng.unit() * 3.0) as u32;
        let bh = b.u(0.2, 0.35);
        let gap = bh / f64::from(slats);
        let st = MIN_THICKNESS;
        for k in 0..slats {
            let y = h + t + gap * f64::from(k) + gap * 0.3;
            b.cuboid(v(-l, y, d - st), v(l, y + gap * 0.7, d), wood);
        }
        for sx in [-1.0, 1.0] {
            let x = sx * (l - inset);
            b.cuboid(
                v(x - s, h + t / 2.0, d - st),
                v(x + s, h + t + bh, d),
                frame,
            );
        }
    }
}

fn sofa(b: &mut Builder) {
    let cloth = b.color();
    let cushion = if b.chance(0.5) { cloth } else { b.color() };
    let w = b.u(0.85, 1.0) / 2.0;
    let d = b.u(0.38, 0.52) / 2.0;
    let y0 = b.u(0.0, 0.06);
    let base_h = b.u(0.16, 0.26);
    b.cuboid(v(-w, y0, -d), v(w, y0 + base_h, d), cloth);
    if y0 > 0.02 {
        let f = MIN_THICKNESS / 2.0;
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (w - 0.05), 0.0, sz * (d - 0.05));
            b.cuboid(c - v(f, 0.0, f), c + v(f, y0 + 0.01, f), cushion);
        }
    }
    let bt = b.u(0.08, 0.14);
    let bh = b.u(0.18, 0.32);
    let back = sheared_box(
        v(-w, y0 + base_h - 0.01, d - bt),
        v(w, y0 + base_h + bh, d),
        v(0.0, 0.0, b.u(0.0, 0.05)),
        [1.0, 1.0],
    );
    b.push(hexahedron(back), cloth);
    let at = b.u(0.07, 0.13);
    let ah = b.u(0.08, 0.18);
    for sx in [-1.0, 1.0] {
        let x0 = sx * w;
        let x1 = x0 - sx * at;
        b.cuboid(
            v(x0.min(x1), y0 + base_h - 0.01, -d),
            v(x0.max(x1), y0 + base_h + ah, d - bt * 0.5),
            cloth,
        );
    }
    let n = 1 + (b.rng.unit() * 3.0) as u32;
    let ct = b.u(MIN_THICKNESS, 0.08);
    let inner = w - at;
    let cw = 2.0 * inner / f64::from(n);
    for k in 0..n {
        let x = -inner + cw * f64::from(k);
        b.cuboid(
            v(x + 0.005, y0 + base_h - 0.01, -d),
            v(x + cw - 0.005, y0 + base_h + ct, d - bt),
            cushion,
        );
    }
}

fn cabinet(b: &mut Builder) {
    let wood = b.color();
    let front = if b.chance(0.5) { wood } else { b.color() };
    let handle = b.dark();
    let w = b.u(0.45, 0.9) / 2.0;
    let h = b.u(0.55, 1.0);
    let d = b.u(0.3, 0.5) / 2.0;
    let feet = b.chance(0.4);
    let y0 = if feet { b.u(0.04, 0.1) } else { 0.0 };
    b.cuboid(v(-w, y0, -d), v(w, y0 + h, d), wood);
    if feet {
        let f = b.u(MIN_THICKNESS, 0.06) / 2.0;
        for (sx, sz) in [(-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0), (1.0, 1.0)] {
            let c = v(sx * (w - f - 0.02), 0.0, sz * (d - f - 0.02));
            b.cuboid(c - v(f, 0.0, f), c + v(f, y0 + 0.01, f), wood);
        }
    }
    // Doors (side by side) or drawers (stacked), proud of the front by a little.
    let drawers = b.chance(0.5);
    let n = 2 + (b.rng.unit() * 2.0) as u32;
    let m = 0.025;
    let proud = 0.02;
    for k in 0..n {
        let f = f64::from(k);
        let (lo, hi) = if drawers {
            let step = (h - 2.0 * m) / f64::from(n);
            (
                v(-w + m, y0 + m + step * f + 0.005, -d - proud),
                v(w - m, y0 + m + step * (f + 1.0) - 0.005, -d + 0.01),
            )
        } else {
            let step = (2.0 * w - 2.0 * m) / f64::from(n);
            (
                v(-w + m + step * f + 0.005, y0 + m, -d - proud),
                v(-w + m + step * (f + 1.0) - 0.005, y0 + h - m, -d + 0.01),
            )
        };
        b.cuboid(lo, hi, front);
        let c = (lo + hi) / 2.0;
        let hs = MIN_THICKNESS / 2.0;
        b.cuboid(
            v(c.x - 2.0 * hs, c.y - hs, lo.z - proud),
            v(c.x + 2.0 * hs, c.y + hs, lo.z + 0.005),
            handle,
        );
    }
}

fn display(b: &mut Builder) {
    let frame = b.color();
    let screen = b.dark();
    let w = b.u(0.75, 1.0) / 2.0;
    let sh = b.u(0.45, 0.65);
    let t = b.u(MIN_THICKNESS, 0.07);
    let neck_h = b.u(0.12, 0.25);
    let foot_w = b.u(0.25, 0.5) / 2.0;
    let foot_d = b.u(0.15, 0.25) / 2.0;
    let foot_t = b.u(MIN_THICKNESS, 0.06);
    b.cuboid(v(-foot_w, 0.0, -foot_d), v(foot_w, foot_t, foot_d), frame);
    let nw = b.u(0.05, 0.12) / 2.0;
    b.cuboid(
        v(-nw, foot_t - 0.01, -MIN_THICKNESS / 2.0 + t),
        v(nw, foot_t + neck_h + 0.1, MIN_THICKNESS / 2.0 + t),
        frame,
    );
    let y = foot_t + neck_h;
    b.cuboid(v(-w, y, -t / 2.0), v(w, y + sh, t / 2.0), frame);
    // The glass, a thin slab proud of the bezel's front.
    let bezel = b.u(0.015, 0.04);
    b.cuboid(
        v(-w + bezel, y + bezel, -t / 2.0 - 0.01),
        v(w - bezel, y + sh - bezel, -t / 2.0 + 0.02),
        screen,
    );
}
