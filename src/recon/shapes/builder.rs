//! The toolkit every recipe builds with: a [`Builder`] that draws proportions and colours from the
//! seeded stream and collects closed parts, and the parametric primitives (boxes, sheared and
//! tapered hexahedra, cylinders and cones), each closed and wound outward.

use glam::DVec3;

use super::{Category, MIN_THICKNESS, NORMALIZED_EXTENT, Part, Shape};
use crate::rng::SplitMix64;

/// Segments around a cylinder or cone.
const SEGMENTS: u32 = 12;

/// The longest side a recipe may build before normalization ([`Builder::finish`] checks it):
/// normalization then shrinks a part by at most `NORMALIZED_EXTENT / MAX_RAW_EXTENT`.
const MAX_RAW_EXTENT: f64 = 1.2;

/// The thinnest a recipe makes a part, before normalization: [`MIN_THICKNESS`] divided by the
/// most that normalization shrinks (0.98 / 1.2) and by the most that a leaning slab's
/// perpendicular thickness falls short of the thickness it was drawn with (cos 20°), so that
/// every part of a normalized object is at least [`MIN_THICKNESS`] thick. Tapers (wings,
/// cones) end at it, never below.
pub(super) const THIN: f64 = MIN_THICKNESS * MAX_RAW_EXTENT / NORMALIZED_EXTENT / 0.94;

/// Parts in f64 while an object is built.
pub(super) struct RawPart {
    pub(super) positions: Vec<DVec3>,
    pub(super) faces: Vec<[u32; 3]>,
    pub(super) color: [f32; 3],
}

pub(super) struct Builder {
    pub(super) rng: SplitMix64,
    pub(super) parts: Vec<RawPart>,
}

impl Builder {
    /// Uniform in [lo, hi).
    pub(super) fn u(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.rng.unit()
    }

    /// True with probability `p`.
    pub(super) fn chance(&mut self, p: f64) -> bool {
        self.rng.unit() < p
    }

    /// A colour: random hue, moderate saturation, bright enough to see under the lights.
    pub(super) fn color(&mut self) -> [f32; 3] {
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
    pub(super) fn dark(&mut self) -> [f32; 3] {
        let v = self.u(0.08, 0.2) as f32;
        [v, v, v]
    }

    pub(super) fn push(
        &mut self,
        (positions, faces): (Vec<DVec3>, Vec<[u32; 3]>),
        color: [f32; 3],
    ) {
        self.parts.push(RawPart {
            positions,
            faces,
            color,
        });
    }

    /// An axis-aligned box from its min and max corners.
    pub(super) fn cuboid(&mut self, lo: DVec3, hi: DVec3, color: [f32; 3]) {
        let hi = lo.max(hi);
        let lo2 = lo.min(hi);
        self.push(hexahedron(box_corners(lo2, hi)), color);
    }

    /// A cylinder or truncated cone whose narrow end is no thinner than any other part: a
    /// cone of half-angle θ is `2 r cos θ` thick at an end of radius r, measured square to its
    /// side, so each radius is raised to at least `THIN / (2 cos θ)` (a nose, a shade's top).
    pub(super) fn frustum(&mut self, p0: DVec3, p1: DVec3, r0: f64, r1: f64, color: [f32; 3]) {
        let len = (p1 - p0).length();
        let (mut r0, mut r1) = (r0, r1);
        // Raising the narrow end narrows θ, so each pass asks less; a few passes settle.
        for _ in 0..4 {
            let sec = (1.0 + ((r0 - r1) / len).powi(2)).sqrt();
            r0 = r0.max(THIN / 2.0 * sec);
            r1 = r1.max(THIN / 2.0 * sec);
        }
        self.push(frustum(p0, p1, r0, r1, SEGMENTS), color);
    }

    /// Centres and scales every part together into the unit cube.
    ///
    /// # Panics
    /// When the recipe built an object longer than [`MAX_RAW_EXTENT`]: normalization would
    /// shrink its thinnest parts below [`MIN_THICKNESS`] (a recipe's bug, whatever the seed).
    pub(super) fn finish(self, category: Category) -> Shape {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in self.parts.iter().flat_map(|p| &p.positions) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let centre = (lo + hi) / 2.0;
        let longest = (hi - lo).max_element();
        assert!(
            longest <= MAX_RAW_EXTENT,
            "a {category} recipe built an object {longest} long, over {MAX_RAW_EXTENT}"
        );
        let scale = NORMALIZED_EXTENT / longest;
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
pub(super) fn hexahedron(c: [DVec3; 8]) -> (Vec<DVec3>, Vec<[u32; 3]>) {
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
pub(super) fn sheared_box(lo: DVec3, hi: DVec3, shift: DVec3, taper: [f64; 2]) -> [DVec3; 8] {
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
pub(super) fn style(b: &mut Builder, n: u32) -> u32 {
    ((b.rng.unit() * f64::from(n)) as u32).min(n - 1)
}

/// A point, written short: the recipes place hundreds.
pub(super) fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}
