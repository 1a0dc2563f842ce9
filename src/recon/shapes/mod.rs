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
//! per part and OR the occupancies ([`Shape::voxelize`]). Every part of a normalized object is
//! at least [`MIN_THICKNESS`] thick everywhere (a wing at its tip, a cone at its narrow end, a
//! leaning slab measured square to its faces), more than the 1/31 spacing of the dataset's
//! voxel centres, so no part falls between voxel centres. The recipes draw thin parts from a
//! minimum above it that allows for normalization shrinking the object (their objects are at
//! most 1.2 long before it, which building checks) and for a slab's lean.
//!
//! Each category is a recipe in the file of its family (`seating`, `tables`, `vehicles`,
//! `lamps`), built with the primitives of `builder`.

mod builder;
mod lamps;
mod seating;
mod tables;
mod vehicles;

use builder::Builder;
use lamps::{display, lamp};
use seating::{bench, chair, sofa};
use tables::{cabinet, table};
use vehicles::{airplane, car};

use crate::error::{Error, Result};
use crate::field::Cube;
use crate::field::voxel::{Occupancy, voxelize_mesh};
use crate::mesh::Mesh;
use crate::rng::SplitMix64;

/// The longest side of every normalized object (a hair under 1, so that no face lies exactly
/// on the voxel centres at ±0.5).
pub const NORMALIZED_EXTENT: f64 = 0.98;

/// The thinnest any part of a generated (normalized) object is, in any direction: 1.4 voxel
/// spacings of the dataset's 32³ lattice.
pub const MIN_THICKNESS: f64 = 0.045;

/// An object category, with its ShapeNet synset id (the class id of the NMR/SoftRas files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Category {
    /// Airplane (`02691156`): airliner (swept wings, low or T tail, no, two or four engines),
    /// fighter (delta wings, one or two fins), propeller plane (straight high or low wings) or
    /// biplane (two staggered wings on struts).
    Airplane,
    /// Bench (`02828884`): long seat on slab or post legs with an optional slatted back, a
    /// picnic bench on A-frames, an ottoman block, or a seat between solid end panels (arms,
    /// optional back).
    Bench,
    /// Cabinet (`02933112`): a body with doors or drawers and handles, optional feet.
    Cabinet,
    /// Car (`02958343`): sedan, van, pickup, sports car or hatchback: body, cabin, four wheels.
    Car,
    /// Chair (`03001627`): four-legged (posts, round, splayed; tilted back, optional arms),
    /// office chair (column and five spokes), stool, armchair with solid sides, or sled chair
    /// on a bent-tube frame.
    Chair,
    /// Display (`03211117`): thin screen on a neck and a foot.
    Display,
    /// Lamp (`03636649`): desk lamp (straight or bent pole, conical shade), floor lamp, arc
    /// lamp, table lamp on a vase, or tripod lamp.
    Lamp,
    /// Sofa (`04256520`): base, back, arms, cushions.
    Sofa,
    /// Table (`04379243`): rectangular or round top on four legs or a pedestal (optional
    /// shelf), coffee table, desk on side panels, trestle table, or a bistro-to-bar-height top
    /// on a column and a cross foot.
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

// Each category draws one of several styles (ShapeNet's categories hold many kinds of object:
// stools and office chairs are chairs, pickups and vans are cars), each with continuous
// proportions and optional parts, so that a test object rarely has a near twin among the
// training objects.

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
