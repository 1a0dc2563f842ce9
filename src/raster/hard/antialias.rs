//! The f64 CPU twin of nvdiffrast's `antialias` and `antialias_construct_topology_hash`,
//! forward and backward: the oracle the GPU kernels are tested against.
//!
//! # What it computes, and why
//!
//! A point-sampled render is piecewise constant in the vertex positions: moving a silhouette
//! moves no pixel colour until a pixel centre changes sides, so it has no visibility gradient.
//! nvdiffrast's `antialias` (Laine et al. 2020, "Modular Primitives for High-Performance
//! Differentiable Rendering", section on analytic antialiasing) fixes that after shading: where
//! two neighbouring pixels show different surfaces and a *silhouette* edge of the nearer one
//! passes between their centres, the pixel whose box the edge cuts gets a share of its
//! neighbour's colour proportional to how far the edge lies past the box's middle. The blend is
//! continuous in the edge's position, so its derivative is the visibility gradient.
//!
//! The twin follows nvdiffrast's rules (learned from `csrc/common/antialias.cu`,
//! `csrc/torch/torch_antialias.cpp` and `nvdiffrast/torch/ops.py`, commit 253ac4f), written in
//! its own code. Pixel conventions are the module's: pixel `(x, y)` of minibatch item `b` is
//! array entry `(b·H + y)·W + x`, row 0 at NDC y = −1, centre at NDC
//! `((2x + 1)/W − 1, (2y + 1)/H − 1)`; in pixel units (`[0, W] × [0, H]`) a vertex lies at
//! `((X/W_c + 1)·W/2, (Y/W_c + 1)·H/2)`.
//!
//! ## Topology (`antialias_construct_topology_hash`; mesh kernel and hash lookup in `antialias.cu`)
//!
//! - For every undirected edge (vertex-index pair) the hash keeps at most two *opposite
//!   vertices* (the third vertex of a triangle on that edge), the first two distinct ones seen.
//!   Triangles with two equal indices are left out. nvdiffrast fills its table with atomics, so
//!   on an edge with three or more distinct opposite vertices *which* two it keeps is a race; the
//!   twin keeps those of the lowest-indexed triangles (the order a GPU port should use too).
//! - Looking up edge `(a, b)` for a triangle whose third vertex is `own`: if `own` is one of the
//!   two kept vertices the answer is the other slot (possibly empty), otherwise there is none.
//!   So an edge of one triangle, an edge of a triangle that lost the race, or an edge of two
//!   copies of one triangle (e.g. both windings) has no opposite vertex.
//! - An edge with no opposite vertex is always a silhouette edge (nvdiffrast runs the test
//!   below with the triangle's own vertex in its place, which agrees but for zero-area
//!   triangles). Otherwise it is one when the opposite vertex lies, in screen space, on the
//!   same side of the edge's line as `own` (the signed area of the triangle with `own`
//!   replaced by the opposite vertex has the sign bit of the triangle's own signed area): the
//!   neighbour folds back over the edge, whatever the two triangles' windings. Indices, not
//!   positions, decide adjacency: an unwelded mesh is all silhouette.
//! - No hash given: one is built from `tri` for the call (as `ops.antialias` does).
//!
//! ## Forward (discontinuity and analysis kernels in `antialias.cu`)
//!
//! - **Pairs.** Every pixel is paired with its right neighbour `(x + 1, y)` and its next-row
//!   neighbour `(x, y + 1)` (nvdiffrast's "down": the next row in memory, i.e. up in NDC with
//!   row 0 at the bottom); none past the last column or row. A pair is examined when the two
//!   id channels (`rast[..][3]`) differ as floats. "Pixel 0" is the pair's first pixel `(x, y)`,
//!   "pixel 1" the neighbour.
//! - **Triangle.** If only one pixel has a triangle (id ≥ 1), that one; if both, pixel 0's
//!   when its `z/w` (`rast[..][2]`) is strictly smaller, else pixel 1's (**a tie goes to
//!   pixel 1**). The geometry is then measured from the centre of the pixel whose triangle it
//!   is. An id past `tri` skips the pair.
//! - **Frame.** Vertices are projected to pixel units relative to that centre; for a next-row
//!   pair x and y are swapped, so the pair always runs along +x and the other pixel's centre is
//!   at `σ = +1` (triangle in pixel 0) or `σ = −1` (triangle in pixel 1) on the x axis.
//! - **Edge.** Of the triangle's edges whose ends lie on different sides of the axis through
//!   the two centres (sign bits of their y differ), the one whose crossing `x_c` with that axis
//!   is farthest toward the other pixel (largest `σ·x_c`): the edge the triangle leaves by.
//!   Crossings are compared as fractions by cross-multiplication, with nvdiffrast's tie rule
//!   (of equal crossings the later edge wins when their y-extents have opposite signs, the
//!   earlier when the same). Edge `k` is the one opposite vertex `k`: (1, 2), (2, 0), (0, 1).
//!   Only that edge is considered: the pair is skipped unless it is a silhouette edge **and**
//!   no more along the pair than across it (`|Δy| ≥ |Δx|` in the swapped frame; a 45° edge
//!   passes for both pair directions).
//! - **Crossing.** `r = σ·x_c`, the distance from the triangle's pixel centre to the crossing
//!   toward the other centre, `x_c = (x_a·Δy − y_a·Δx)/Δy` from edge start `a`. The pair is
//!   skipped unless `−1/16 < r < 1 + 1/16` ([`CROSSING_SLACK`], for rasterizer inaccuracy);
//!   then `r` is clamped to `[0, 1]`.
//! - **Blend.** `α = σ·(1/2 − r)`. Only one pixel changes: pixel 0 if `α > 0`, else pixel 1;
//!   `out[target] += α·(color[pixel 1] − color[pixel 0])`. That is, the pixel whose box holds
//!   the crossing takes the other pixel's colour in proportion to the part of its box, along
//!   the pair, on the far side of the crossing. The colours are always the *input* colours.
//! - **Sums.** `out` starts as a copy of `color`; pairs are visited minibatch by minibatch, row
//!   by row from row 0, column by column, and at each pixel the right pair before the next-row
//!   pair; each pair adds its term to its one target pixel in that order. (nvdiffrast adds
//!   with float atomics in no fixed order; the GPU port should use this order.)
//!
//! ## Backward (gradient kernel in `antialias.cu`, `pos_gradient_boost` in `ops.py`)
//!
//! - The decisions are the forward's: the same pairs, triangle, edge and `α` (nvdiffrast reuses
//!   the forward's work list; the twin recomputes it from the same inputs). `rast` gets no
//!   gradient (`ops.py` returns `None` for it), so the position gradient is the derivative for
//!   fixed visibility: through the edge's geometry only.
//! - A pair whose `α` is `+0.0` does nothing (it is nvdiffrast's "no work" marker; `−0.0`, from
//!   `r = 1/2` with the triangle in pixel 1, does count and its position gradient is kept).
//! - **Colour**, exact: with `g = dy[target]`, `grad_color[pixel 0] −= α·g`, `grad_color[pixel
//!   1] += α·g` (per channel), on top of `grad_color = dy`.
//! - **Positions**, with `dL/dα = Σ_ch g·(color[pixel 1] − color[pixel 0])` and
//!   dα/dx_c = −1: the derivative of `x_c` with respect to the edge's two end vertices, chained
//!   through the projection `x = (X/W_c)·W/2`, `y = (Y/W_c)·H/2` to X, Y and W_c. **Z gets
//!   none**, nor do the opposite vertices (they only decide the silhouette test). It is the
//!   exact derivative except that every `1/Δy` is `1/(Δy + 10⁻³·sign Δy)`
//!   ([`GRADIENT_DY_EPSILON`], Δy in pixels, swapped frame), including inside `x_c`: a relative
//!   error of about `10⁻³/|Δy|`. Nothing flows when `|α| ≥ 1/2` (the clamp of `r` binds, or
//!   `r` is exactly 0 or 1) or when `dL/dα = 0`.
//! - **Sums**: in the forward's pair order, per pair pixel 0 before pixel 1 and the edge's start
//!   vertex before its end; then `grad_pos` is multiplied by `pos_gradient_boost`
//!   (`grad_color` is not).
//!
//! ## How well the blend approximates coverage
//!
//! Measured in `tests::blend_factor_against_exact_box_coverage`. For a straight edge crossing
//! a pair at offset `r` with slope `s = Δx/Δy` (`|s| < 1`, the triangle on pixel 0's side),
//! let `A₀` be the exact area of pixel 0's box beyond the edge and `A₁` that of pixel 1's box
//! on the triangle's side. The twin's factors are `B₀ = max(1/2 − r, 0)` on pixel 0 and
//! `B₁ = max(r − 1/2, 0)` on pixel 1.
//! - `B = A`, value and derivative in `r` (to rounding), wherever the edge stays inside one
//!   box over the box's height: `r + |s|/2 ≤ 1/2` (pixel 0's box) or `r − |s|/2 ≥ 1/2`
//!   (pixel 1's). For an axis-aligned edge (`s = 0`) that is every `r`.
//! - The net transfer is always exact: `B₀ − B₁ = A₀ − A₁ = 1/2 − r`, and so is its
//!   derivative, −1. What the blend gets wrong is the split between the two pixels when the
//!   edge cuts the boundary between their boxes (`|r − 1/2| < |s|/2`): in value by at most
//!   `|s|/8`, reached at `r = 1/2` (measured on a grid of `r` at 0.01 from it: 0.0265,
//!   0.0576, 0.0888, 0.1138 for `s` = 0.25, 0.5, 0.75, 0.95); in derivative by up to 1/2, also
//!   at `r = 1/2`, where the blend's slope jumps from −1 to 0 and the exact one passes
//!   through −1/2 (measured 0.46 to 0.49 at 0.01 from it). So nvdiffrast's per-pixel position
//!   gradients are exact for axis-aligned edges, and for sloped ones everywhere but a window
//!   of width `|s|` around `r = 1/2`; where `dL/dout` is the same at both pixels of the pair
//!   the gradient is exact at any slope.
//! - Only the crossing on the line through the two centres is used; the blend does not see
//!   the edge's other crossings, the triangle's corners, or other edges in the box. For
//!   `−1/16 < r < 0` (the centre is, exactly, outside the triangle, which a rasterizer that
//!   snaps vertices can produce) the pixel gets the full `1/2` and no gradient.
//!
//! ## Gradient checks
//!
//! `tests::grad_pos_matches_central_differences_with_rast_fixed`: on 16×16 octahedra
//! (instanced) and a two-layer scene (range mode), the backward with the guard off matches
//! central differences (step 1e-6, `rast` fixed) to 4e-9 in `|error| / (1 + |fd|)` on every
//! component whose step flips no decision (6 of 96 are skipped); with nvdiffrast's guard the
//! relative error is at most 5.3e-4 there.

use std::collections::HashMap;

/// How far (in pixels) past either pixel centre a crossing may lie and still be blended:
/// nvdiffrast's allowance for a rasterizer that is off by up to 1/16 pixel.
pub const CROSSING_SLACK: f64 = 1.0 / 16.0;

/// What nvdiffrast adds (with the sign of Δy, in pixels) to an edge's extent across the pair
/// before dividing by it in the position gradient: keeps near-parallel edges finite.
pub const GRADIENT_DY_EPSILON: f64 = 1e-3;

/// Edge `k` of a triangle runs between these two of its vertices; it is opposite vertex `k`.
const EDGE_ENDS: [(usize, usize); 3] = [(1, 2), (2, 0), (0, 1)];

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
/// stays constant, to pass to [`antialias`] and [`antialias_backward`] instead of rebuilding it.
pub fn antialias_construct_topology_hash(tri: &[[u32; 3]]) -> TopologyHash {
    TopologyHash::new(tri)
}

/// The undirected edge's key: its two vertex indices, smaller first.
fn edge_key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// How `pos` is laid out, and so where each minibatch item finds its vertices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PosLayout {
    /// `pos [V, 4]`, shared by the whole minibatch; ids in `rast` index `tri` directly.
    Range {
        /// V.
        vertices: usize,
    },
    /// `pos [B, V, 4]`: minibatch item `b` uses vertices `b·V .. (b + 1)·V`; `tri` indexes
    /// within one item.
    Instanced {
        /// V, per minibatch item.
        vertices: usize,
    },
}

/// The image arrays' shape: `color` and `dy` are `[batch, height, width, channels]`, `rast`
/// is `[batch, height, width, 4]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageShape {
    /// B, the minibatch size.
    pub batch: usize,
    /// H, rows.
    pub height: usize,
    /// W, columns.
    pub width: usize,
    /// C ≥ 1, channels of `color`.
    pub channels: usize,
}

impl ImageShape {
    /// Pixels in the whole minibatch, `B·H·W`.
    pub fn pixel_count(&self) -> usize {
        self.batch * self.height * self.width
    }
}

/// Everything `antialias` reads.
#[derive(Clone, Copy, Debug)]
pub struct AntialiasInput<'a> {
    /// The image to antialias, `[B, H, W, C]`.
    pub color: &'a [f64],
    /// The rasterizer's output, `[B, H, W, 4]` = `(u, v, z/w, id + 1)`; ids must be exact
    /// integers (nvdiffrast's f32 bit trick for ids above 2²⁴ is not needed in f64).
    pub rast: &'a [f64],
    /// Clip-space vertex positions, `[V, 4]` or `[B, V, 4]` as `pos_layout` says.
    pub pos: &'a [f64],
    /// How `pos` is laid out.
    pub pos_layout: PosLayout,
    /// Triangles as vertex-index triples, each index < V.
    pub tri: &'a [[u32; 3]],
    /// The shape of `color` and `rast`.
    pub shape: ImageShape,
}

impl AntialiasInput<'_> {
    /// Checks that the arrays agree with the shape and layout.
    fn validate(&self) -> Result<(), String> {
        let s = self.shape;
        if s.batch == 0 || s.height == 0 || s.width == 0 || s.channels == 0 {
            return Err(format!("antialias: empty image shape {s:?}"));
        }
        if self.color.len() != s.pixel_count() * s.channels {
            return Err(format!(
                "antialias: color has {} values, shape {s:?} needs {}",
                self.color.len(),
                s.pixel_count() * s.channels
            ));
        }
        if self.rast.len() != s.pixel_count() * 4 {
            return Err(format!(
                "antialias: rast has {} values, shape {s:?} needs {}",
                self.rast.len(),
                s.pixel_count() * 4
            ));
        }
        let (vertices, items) = match self.pos_layout {
            PosLayout::Range { vertices } => (vertices, 1),
            PosLayout::Instanced { vertices } => (vertices, s.batch),
        };
        if vertices == 0 || self.pos.len() != vertices * items * 4 {
            return Err(format!(
                "antialias: pos has {} values, {:?} over {} minibatch items needs {}",
                self.pos.len(),
                self.pos_layout,
                items,
                vertices * items * 4
            ));
        }
        if let Some((t, v)) = self
            .tri
            .iter()
            .enumerate()
            .find_map(|(t, v)| v.iter().any(|&i| i as usize >= vertices).then_some((t, v)))
        {
            return Err(format!(
                "antialias: triangle {t} = {v:?} indexes past {vertices} vertices"
            ));
        }
        Ok(())
    }

    /// Vertices per minibatch item (V).
    fn vertex_count(&self) -> usize {
        match self.pos_layout {
            PosLayout::Range { vertices } | PosLayout::Instanced { vertices } => vertices,
        }
    }

    /// Where minibatch item `b`'s vertices start in `pos`, in vertices.
    fn vertex_base(&self, b: usize) -> usize {
        match self.pos_layout {
            PosLayout::Range { .. } => 0,
            PosLayout::Instanced { vertices } => b * vertices,
        }
    }

    /// Clip-space position of vertex `v` (an index into the whole `pos`).
    fn vertex(&self, v: usize) -> [f64; 4] {
        let p = &self.pos[4 * v..4 * v + 4];
        [p[0], p[1], p[2], p[3]]
    }
}

/// One examined pixel pair that found a silhouette edge: the forward's decisions, which the
/// backward reuses (nvdiffrast's work item).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgePair {
    /// Minibatch item.
    pub batch: usize,
    /// Column of pixel 0, the pair's first pixel.
    pub x: usize,
    /// Row of pixel 0.
    pub y: usize,
    /// Pixel 1 is `(x, y + 1)` when true, `(x + 1, y)` when false.
    pub vertical: bool,
    /// The triangle is pixel 1's (so `σ = −1`); otherwise pixel 0's.
    pub from_second: bool,
    /// The triangle whose edge blends the pair (an index into `tri`).
    pub triangle: usize,
    /// Which of its edges: `k` is the edge opposite vertex `k`.
    pub edge: usize,
    /// The blend weight: pixel 0 changes if `alpha > 0`, else pixel 1, by
    /// `alpha · (color[pixel 1] − color[pixel 0])`. `|alpha| ≤ 1/2`.
    pub alpha: f64,
}

impl EdgePair {
    /// Pixel 0's index in `[B, H, W]`.
    pub fn first_pixel(&self, shape: ImageShape) -> usize {
        (self.batch * shape.height + self.y) * shape.width + self.x
    }

    /// Pixel 1's index in `[B, H, W]`.
    pub fn second_pixel(&self, shape: ImageShape) -> usize {
        self.first_pixel(shape) + if self.vertical { shape.width } else { 1 }
    }

    /// The index of the one pixel the blend changes.
    pub fn target_pixel(&self, shape: ImageShape) -> usize {
        if self.alpha > 0.0 {
            self.first_pixel(shape)
        } else {
            self.second_pixel(shape)
        }
    }

    /// Column and row of the pixel whose centre the geometry is measured from (the one whose
    /// triangle was chosen).
    fn triangle_pixel(&self) -> (usize, usize) {
        match (self.from_second, self.vertical) {
            (false, _) => (self.x, self.y),
            (true, false) => (self.x + 1, self.y),
            (true, true) => (self.x, self.y + 1),
        }
    }
}

/// Gradients of a loss through [`antialias`].
#[derive(Clone, Debug, PartialEq)]
pub struct AntialiasGrad {
    /// With respect to `color`, `[B, H, W, C]`.
    pub color: Vec<f64>,
    /// With respect to `pos`, its shape; the z components are always zero.
    pub pos: Vec<f64>,
}

/// The pixel pairs that `antialias` blends, in the order it visits them (see the module docs):
/// the forward's decisions, for tests and for comparing with the GPU's work list.
pub fn find_edge_pairs(
    input: &AntialiasInput,
    topology: Option<&TopologyHash>,
) -> Result<Vec<EdgePair>, String> {
    input.validate()?;
    let built;
    let hash = match topology {
        Some(h) if h.triangle_count() != input.tri.len() => {
            return Err(format!(
                "antialias: topology hash built from {} triangles, tri has {}",
                h.triangle_count(),
                input.tri.len()
            ));
        }
        Some(h) => h,
        None => {
            built = TopologyHash::new(input.tri);
            &built
        }
    };
    let s = input.shape;
    let mut pairs = Vec::new();
    for b in 0..s.batch {
        for y in 0..s.height {
            for x in 0..s.width {
                if x + 1 < s.width {
                    pairs.extend(analyse_pair(input, hash, b, x, y, false));
                }
                if y + 1 < s.height {
                    pairs.extend(analyse_pair(input, hash, b, x, y, true));
                }
            }
        }
    }
    Ok(pairs)
}

/// nvdiffrast's `antialias` forward: `color` with every silhouette-crossed pixel pair blended
/// (same shape as `color`). Without `topology`, the adjacency is built from `tri` for the call.
pub fn antialias(
    input: &AntialiasInput,
    topology: Option<&TopologyHash>,
) -> Result<Vec<f64>, String> {
    let pairs = find_edge_pairs(input, topology)?;
    let s = input.shape;
    let c = s.channels;
    let color = input.color;
    let mut out = color.to_vec();
    for pair in &pairs {
        let (p0, p1) = (pair.first_pixel(s), pair.second_pixel(s));
        let t = pair.target_pixel(s);
        for ch in 0..c {
            out[t * c + ch] += pair.alpha * (color[p1 * c + ch] - color[p0 * c + ch]);
        }
    }
    Ok(out)
}

/// nvdiffrast's `antialias` backward: given `dy = dL/d(output)`, `dL/dcolor` and `dL/dpos`
/// (the latter times `pos_gradient_boost`), for fixed `rast`.
pub fn antialias_backward(
    input: &AntialiasInput,
    topology: Option<&TopologyHash>,
    dy: &[f64],
    pos_gradient_boost: f64,
) -> Result<AntialiasGrad, String> {
    backward_with_epsilon(input, topology, dy, pos_gradient_boost, GRADIENT_DY_EPSILON)
}

/// The backward with the `1/Δy` guard as a parameter: `GRADIENT_DY_EPSILON` is nvdiffrast's,
/// 0 gives the exact derivative of the forward (what the tests check against differences).
fn backward_with_epsilon(
    input: &AntialiasInput,
    topology: Option<&TopologyHash>,
    dy: &[f64],
    pos_gradient_boost: f64,
    dy_epsilon: f64,
) -> Result<AntialiasGrad, String> {
    let pairs = find_edge_pairs(input, topology)?;
    if dy.len() != input.color.len() {
        return Err(format!(
            "antialias backward: dy has {} values, color has {}",
            dy.len(),
            input.color.len()
        ));
    }
    let s = input.shape;
    let c = s.channels;
    let color = input.color;
    let mut grad_color = dy.to_vec();
    let mut grad_pos = vec![0.0; input.pos.len()];
    for pair in &pairs {
        // +0.0 is the work list's "no blend" value in nvdiffrast; -0.0 is not.
        if pair.alpha.to_bits() == 0 {
            continue;
        }
        let (p0, p1) = (pair.first_pixel(s), pair.second_pixel(s));
        let t = pair.target_pixel(s);
        // dL/dα, accumulated while the colour gradient is passed to both pixels.
        let mut dl_dalpha = 0.0;
        for ch in 0..c {
            let g = dy[t * c + ch];
            dl_dalpha += g * (color[p1 * c + ch] - color[p0 * c + ch]);
            grad_color[p0 * c + ch] -= pair.alpha * g;
            grad_color[p1 * c + ch] += pair.alpha * g;
        }
        // A saturated α is a clamped r (the crossing distance): flat in the geometry.
        if dl_dalpha == 0.0 || pair.alpha.abs() >= 0.5 {
            continue;
        }
        let verts = input.tri[pair.triangle];
        let (ia, ib) = EDGE_ENDS[pair.edge];
        let base = input.vertex_base(pair.batch);
        let (va, vb) = (base + verts[ia] as usize, base + verts[ib] as usize);
        let (pa, pb) = (input.vertex(va), input.vertex(vb));
        let (cx, cy) = pair.triangle_pixel();
        let mut a = pixel_frame(pa, cx, cy, s);
        let mut b = pixel_frame(pb, cx, cy, s);
        if pair.vertical {
            a.swap(0, 1);
            b.swap(0, 1);
        }
        // x_c = (a_x Δy − a_y Δx)/Δy and α = σ/2 − x_c (unclamped), so dL/dx_c = −dL/dα.
        let (ex, ey) = (b[0] - a[0], b[1] - a[1]);
        let inv = 1.0 / (ey + dy_epsilon.copysign(ey));
        let xc = (a[0] * ey - a[1] * ex) * inv;
        let g = -dl_dalpha;
        let mut ga = [g * b[1] * inv, g * (xc - b[0]) * inv];
        let mut gb = [-g * a[1] * inv, g * (a[0] - xc) * inv];
        if pair.vertical {
            ga.swap(0, 1);
            gb.swap(0, 1);
        }
        add_clip_gradient(&mut grad_pos, va, pa, ga, s);
        add_clip_gradient(&mut grad_pos, vb, pb, gb, s);
    }
    if pos_gradient_boost != 1.0 {
        for g in &mut grad_pos {
            *g *= pos_gradient_boost;
        }
    }
    Ok(AntialiasGrad {
        color: grad_color,
        pos: grad_pos,
    })
}

/// Examines pair `(x, y)`–right (`vertical` false) or –next row (true) of item `b`; returns
/// its decisions if a silhouette edge blends it.
fn analyse_pair(
    input: &AntialiasInput,
    hash: &TopologyHash,
    b: usize,
    x: usize,
    y: usize,
    vertical: bool,
) -> Option<EdgePair> {
    let s = input.shape;
    let p0 = (b * s.height + y) * s.width + x;
    let p1 = p0 + if vertical { s.width } else { 1 };
    let (id0, id1) = (input.rast[4 * p0 + 3], input.rast[4 * p1 + 3]);
    if id0 == id1 {
        return None;
    }
    let (t0, t1) = (id0 as i64 - 1, id1 as i64 - 1);
    let chosen = if t0 >= 0 && t1 >= 0 {
        if input.rast[4 * p0 + 2] < input.rast[4 * p1 + 2] {
            t0
        } else {
            t1
        }
    } else if t0 >= 0 {
        t0
    } else {
        t1
    };
    if chosen < 0 || chosen as usize >= input.tri.len() {
        return None;
    }
    let mut pair = EdgePair {
        batch: b,
        x,
        y,
        vertical,
        from_second: chosen == t1,
        triangle: chosen as usize,
        edge: 0,
        alpha: 0.0,
    };
    let (cx, cy) = pair.triangle_pixel();
    let verts = input.tri[pair.triangle];
    let base = input.vertex_base(b);
    let q = verts.map(|v| pixel_frame(input.vertex(base + v as usize), cx, cy, s));

    // Silhouette test per edge, before the swap (it is a 2D side test, frame-independent).
    let own_area = signed_area(q[0], q[1], q[2]);
    let silhouette = EDGE_ENDS.map(|(i, j)| {
        let own = 3 - i - j;
        match hash.opposite_vertex(verts[i], verts[j], verts[own]) {
            // (A hash built from another mesh could name a vertex that is not there.)
            Some(o) if o as usize >= input.vertex_count() => true,
            None => true,
            Some(o) => {
                let qo = pixel_frame(input.vertex(base + o as usize), cx, cy, s);
                same_sign_bit(signed_area(qo, q[i], q[j]), own_area)
            }
        }
    });

    let q = if vertical { q.map(|[u, v]| [v, u]) } else { q };
    let sigma = if pair.from_second { -1.0 } else { 1.0 };
    // Per edge: whether it straddles the axis through the two centres, its crossing with it
    // as numerator / denominator (the denominator is the edge's extent across the pair, Δy),
    // and its extent along the pair (Δx).
    let straddles = EDGE_ENDS.map(|(i, j)| !same_sign_bit(q[i][1], q[j][1]));
    let num = EDGE_ENDS.map(|(i, j)| {
        let (a, e) = (q[i], q[j]);
        sigma * (a[0] * (e[1] - a[1]) - a[1] * (e[0] - a[0]))
    });
    let den = EDGE_ENDS.map(|(i, j)| q[j][1] - q[i][1]);
    let along = EDGE_ENDS.map(|(i, j)| q[j][0] - q[i][0]);
    // Edge m's crossing lies farther toward the other pixel than edge n's; an edge that does
    // not straddle has no crossing and loses to any that does.
    let beats = |m: usize, n: usize| {
        straddles[m] && (!straddles[n] || fraction_greater(num[m], den[m], num[n], den[n]))
    };
    let k = if beats(2, 0) && beats(2, 1) {
        2
    } else if beats(1, 0) {
        1
    } else {
        0
    };
    if !straddles[k] || !silhouette[k] || den[k].abs() < along[k].abs() {
        return None;
    }
    let reach = num[k] / den[k];
    if !(reach > -CROSSING_SLACK && reach < 1.0 + CROSSING_SLACK) {
        return None;
    }
    pair.edge = k;
    pair.alpha = sigma * (0.5 - reach.clamp(0.0, 1.0));
    Some(pair)
}

/// A clip-space vertex in pixel units relative to the centre of pixel `(cx, cy)`.
fn pixel_frame(p: [f64; 4], cx: usize, cy: usize, s: ImageShape) -> [f64; 2] {
    let (hx, hy) = (0.5 * s.width as f64, 0.5 * s.height as f64);
    let inv_w = 1.0 / p[3];
    [
        p[0] * inv_w * hx - (cx as f64 + 0.5 - hx),
        p[1] * inv_w * hy - (cy as f64 + 0.5 - hy),
    ]
}

/// Adds the gradient `g` with respect to vertex `v`'s pixel-frame position to `grad_pos`, chained
/// through the projection to its clip X, Y and W (Z does not enter the projection).
fn add_clip_gradient(grad_pos: &mut [f64], v: usize, p: [f64; 4], g: [f64; 2], s: ImageShape) {
    let (hx, hy) = (0.5 * s.width as f64, 0.5 * s.height as f64);
    let inv_w = 1.0 / p[3];
    let gx = g[0] * hx * inv_w;
    let gy = g[1] * hy * inv_w;
    grad_pos[4 * v] += gx;
    grad_pos[4 * v + 1] += gy;
    grad_pos[4 * v + 3] -= (p[0] * gx + p[1] * gy) * inv_w;
}

/// Twice the signed area of triangle `(a, b, c)`, measured from `a`.
fn signed_area(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
}

/// Whether two numbers have the same sign bit (so +0 and −0 differ, as in nvdiffrast).
fn same_sign_bit(a: f64, b: f64) -> bool {
    a.is_sign_negative() == b.is_sign_negative()
}

/// Whether `na/da > nb/db`, by cross-multiplying (no division, so zero denominators give an
/// answer); when the denominators' signs differ the comparison flips, and then equal fractions
/// count as greater (nvdiffrast's tie rule).
fn fraction_greater(na: f64, da: f64, nb: f64, db: f64) -> bool {
    let greater = na * db > nb * da;
    if same_sign_bit(da, db) {
        greater
    } else {
        !greater
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// splitmix64: a seeded, dependency-free source of test data.
    struct Rng(u64);

    impl Rng {
        fn uniform(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 53) as f64
        }

        fn values(&mut self, n: usize, lo: f64, hi: f64) -> Vec<f64> {
            (0..n).map(|_| lo + (hi - lo) * self.uniform()).collect()
        }
    }

    /// A brute-force f64 rasterizer of one image, computing coverage and `(u, v, z/w)` as
    /// nvdiffrast's pixel shader does: homogeneous 2D edge functions at the pixel centre,
    /// inside when all three have the sign of their sum, nearest `z/w` in [−1, 1] wins. `pos`
    /// holds the image's vertices; ids written are `t + 1` for the global index `t`.
    fn rasterize_image(
        pos: &[f64],
        tri: &[[u32; 3]],
        triangles: std::ops::Range<usize>,
        width: usize,
        height: usize,
    ) -> Vec<f64> {
        let mut rast = vec![0.0; width * height * 4];
        for y in 0..height {
            for x in 0..width {
                let fx = (2 * x + 1) as f64 / width as f64 - 1.0;
                let fy = (2 * y + 1) as f64 / height as f64 - 1.0;
                let mut best: Option<(f64, [f64; 4])> = None;
                for t in triangles.clone() {
                    let v = tri[t].map(|i| {
                        let i = 4 * i as usize;
                        [pos[i], pos[i + 1], pos[i + 2], pos[i + 3]]
                    });
                    let p = v.map(|c| [c[0] - fx * c[3], c[1] - fy * c[3]]);
                    let a = [
                        p[1][0] * p[2][1] - p[1][1] * p[2][0],
                        p[2][0] * p[0][1] - p[2][1] * p[0][0],
                        p[0][0] * p[1][1] - p[0][1] * p[1][0],
                    ];
                    let sum = a[0] + a[1] + a[2];
                    if sum == 0.0 || a.iter().any(|&ak| ak * sum < 0.0) {
                        continue;
                    }
                    let zw = (0..3).map(|k| v[k][2] * a[k]).sum::<f64>()
                        / (0..3).map(|k| v[k][3] * a[k]).sum::<f64>();
                    if !(-1.0..=1.0).contains(&zw) {
                        continue;
                    }
                    if best.is_none_or(|(z, _)| zw < z) {
                        best = Some((zw, [a[0] / sum, a[1] / sum, zw, (t + 1) as f64]));
                    }
                }
                if let Some((_, r)) = best {
                    rast[4 * (y * width + x)..4 * (y * width + x) + 4].copy_from_slice(&r);
                }
            }
        }
        rast
    }

    /// Everything one antialias call reads, owned.
    struct Scene {
        pos: Vec<f64>,
        layout: PosLayout,
        tri: Vec<[u32; 3]>,
        rast: Vec<f64>,
        color: Vec<f64>,
        shape: ImageShape,
    }

    impl Scene {
        fn input(&self) -> AntialiasInput<'_> {
            self.input_with(&self.pos)
        }

        fn input_with<'a>(&'a self, pos: &'a [f64]) -> AntialiasInput<'a> {
            AntialiasInput {
                color: &self.color,
                rast: &self.rast,
                pos,
                pos_layout: self.layout,
                tri: &self.tri,
                shape: self.shape,
            }
        }
    }

    /// One image over `clip` (flattened `[V, 4]`), rasterized by [`rasterize_image`].
    fn single_image(
        clip: Vec<f64>,
        tri: Vec<[u32; 3]>,
        width: usize,
        height: usize,
        channels: usize,
    ) -> Scene {
        let rast = rasterize_image(&clip, &tri, 0..tri.len(), width, height);
        let shape = ImageShape {
            batch: 1,
            height,
            width,
            channels,
        };
        Scene {
            layout: PosLayout::Range {
                vertices: clip.len() / 4,
            },
            pos: clip,
            tri,
            rast,
            color: vec![0.0; shape.pixel_count() * channels],
            shape,
        }
    }

    /// A regular octahedron of radius 1: vertices ±x, ±y, ±z, eight faces.
    fn octahedron() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let v = vec![
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ];
        let t = vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        (v, t)
    }

    /// Rotates `p` by `yaw` about y then `pitch` about x, puts it `dist` in front of a camera
    /// at the origin looking down −z, and projects with focal length 2.2 (OpenGL depth for
    /// near 1, far 10).
    fn project(p: [f64; 3], yaw: f64, pitch: f64, dist: f64) -> [f64; 4] {
        let (sy, cy) = yaw.sin_cos();
        let (sp, cp) = pitch.sin_cos();
        let x1 = cy * p[0] + sy * p[2];
        let z1 = -sy * p[0] + cy * p[2];
        let y2 = cp * p[1] - sp * z1;
        let z2 = sp * p[1] + cp * z1 - dist;
        let (near, far, focal) = (1.0, 10.0, 2.2);
        [
            focal * x1,
            focal * y2,
            (far + near) / (near - far) * z2 + 2.0 * far * near / (near - far),
            -z2,
        ]
    }

    /// Flattened clip positions of `verts` in one pose.
    fn posed(verts: &[[f64; 3]], yaw: f64, pitch: f64) -> Vec<f64> {
        verts
            .iter()
            .flat_map(|&p| project(p, yaw, pitch, 3.5))
            .collect()
    }

    /// The octahedron in one pose per minibatch item (instanced), random colours.
    fn instanced_octahedra(
        poses: &[(f64, f64)],
        size: usize,
        channels: usize,
        rng: &mut Rng,
    ) -> Scene {
        let (verts, tri) = octahedron();
        let mut pos = Vec::new();
        let mut rast = Vec::new();
        for &(yaw, pitch) in poses {
            let clip = posed(&verts, yaw, pitch);
            rast.extend(rasterize_image(&clip, &tri, 0..tri.len(), size, size));
            pos.extend(clip);
        }
        let shape = ImageShape {
            batch: poses.len(),
            height: size,
            width: size,
            channels,
        };
        Scene {
            pos,
            layout: PosLayout::Instanced {
                vertices: verts.len(),
            },
            tri,
            rast,
            color: rng.values(shape.pixel_count() * channels, 0.0, 1.0),
            shape,
        }
    }

    /// Range mode, two images over one `pos`: image 0 draws the octahedron (triangles 0..8),
    /// image 1 a small triangle in front of a big one (8..10), with varied w (perspective).
    fn ranged_scene(size: usize, channels: usize, rng: &mut Rng) -> Scene {
        let (verts, mut tri) = octahedron();
        let mut pos = posed(&verts, 0.45, -0.3);
        // (NDC x, NDC y, z/w, w): back triangle at z/w 0.5, front one at −0.2.
        let layers = [
            [-0.9, -0.8, 0.5, 1.0],
            [0.85, -0.7, 0.5, 1.3],
            [0.1, 0.9, 0.5, 1.6],
            [-0.5, -0.3, -0.2, 1.2],
            [0.6, -0.1, -0.2, 0.9],
            [-0.1, 0.6, -0.2, 1.5],
        ];
        for [x, y, z, w] in layers {
            pos.extend([x * w, y * w, z * w, w]);
        }
        tri.push([6, 7, 8]);
        tri.push([9, 10, 11]);
        let mut rast = rasterize_image(&pos, &tri, 0..8, size, size);
        rast.extend(rasterize_image(&pos, &tri, 8..10, size, size));
        let shape = ImageShape {
            batch: 2,
            height: size,
            width: size,
            channels,
        };
        Scene {
            layout: PosLayout::Range {
                vertices: pos.len() / 4,
            },
            pos,
            tri,
            rast,
            color: rng.values(shape.pixel_count() * channels, 0.0, 1.0),
            shape,
        }
    }

    /// `Σ dy · antialias(input)`.
    fn loss(input: &AntialiasInput, dy: &[f64]) -> f64 {
        let out = antialias(input, None).unwrap();
        out.iter().zip(dy).map(|(o, d)| o * d).sum()
    }

    /// The forward's discrete decisions, with α reduced to what changes the blend's formula:
    /// its sign, whether it saturates, whether it is the +0 no-op.
    fn decisions(input: &AntialiasInput) -> Vec<EdgePair> {
        find_edge_pairs(input, None)
            .unwrap()
            .into_iter()
            .map(|p| {
                let class = if p.alpha.to_bits() == 0 {
                    0.0
                } else if p.alpha.abs() >= 0.5 {
                    2.0
                } else {
                    1.0
                };
                EdgePair {
                    alpha: class * p.alpha.signum(),
                    ..p
                }
            })
            .collect()
    }

    fn id(scene: &Scene, pixel: usize) -> f64 {
        scene.rast[4 * pixel + 3]
    }

    // ---- 1. hand-computed blends ----

    #[test]
    fn vertical_edge_blends_the_pixel_whose_box_holds_the_crossing() {
        // W = 4, H = 2, C = 3; a triangle left of a vertical edge at pixel x = `edge`, drawn
        // at w = 2 (the projection divides it out). Pixel centres are at x = 0.5 .. 3.5.
        for (edge, target, other, share) in [(2.3, 2, 1, 0.3), (1.8, 1, 2, 0.2)] {
            let e = 2.0 * edge / 4.0 - 1.0;
            let w = 2.0;
            let clip = [[-10.0, -10.0], [e, -10.0], [e, 10.0]]
                .iter()
                .flat_map(|&[x, y]| [x * w, y * w, 0.1 * w, w])
                .collect();
            let mut scene = single_image(clip, vec![[0, 1, 2]], 4, 2, 3);
            for p in 0..8 {
                assert_eq!(id(&scene, p), if p % 4 < 2 { 1.0 } else { 0.0 });
            }
            scene.color = (0..24).map(|i| 0.1 + 0.37 * i as f64).collect();
            let out = antialias(&scene.input(), None).unwrap();
            for p in 0..8 {
                for ch in 0..3 {
                    let c = |q: usize| scene.color[3 * q + ch];
                    let row = p - p % 4;
                    let expected = if p % 4 == target {
                        (1.0 - share) * c(p) + share * c(row + other)
                    } else {
                        c(p)
                    };
                    assert!(
                        (out[3 * p + ch] - expected).abs() < 1e-12,
                        "edge {edge}, pixel {p}, channel {ch}: {} vs {expected}",
                        out[3 * p + ch]
                    );
                }
            }
        }
    }

    #[test]
    fn horizontal_edge_seen_from_the_upper_pixel_blends_the_upper_pixel() {
        // W = 2, H = 4; a triangle above a horizontal edge at pixel y = 1.3: rows 1..3 are
        // covered, row 0 is not, so each column's pair (row 0, row 1) takes the triangle from
        // its second pixel (σ = −1) and row 1's box, [1, 2], is 0.3 background.
        let e = 2.0 * 1.3 / 4.0 - 1.0;
        let clip = [[-10.0, e], [10.0, e], [0.0, 10.0]]
            .iter()
            .flat_map(|&[x, y]| [x, y, 0.0, 1.0])
            .collect();
        let mut scene = single_image(clip, vec![[0, 1, 2]], 2, 4, 1);
        scene.color = vec![0.25, 0.5, 2.0, 4.0, 2.5, 4.5, 3.0, 5.0];
        let pairs = find_edge_pairs(&scene.input(), None).unwrap();
        assert_eq!(pairs.len(), 2);
        for (x, pair) in pairs.iter().enumerate() {
            assert_eq!(
                (pair.x, pair.y, pair.vertical, pair.from_second),
                (x, 0, true, true)
            );
            assert_eq!((pair.triangle, pair.edge), (0, 2), "edge (v0, v1)");
            assert!((pair.alpha + 0.3).abs() < 1e-12, "alpha {}", pair.alpha);
        }
        let out = antialias(&scene.input(), None).unwrap();
        let c = &scene.color;
        let expected = [
            c[0],
            c[1],
            0.7 * c[2] + 0.3 * c[0],
            0.7 * c[3] + 0.3 * c[1],
            c[4],
            c[5],
            c[6],
            c[7],
        ];
        for (o, e) in out.iter().zip(expected) {
            assert!((o - e).abs() < 1e-12, "{out:?} vs {expected:?}");
        }
    }

    #[test]
    fn nearer_triangle_supplies_the_edge_and_a_depth_tie_goes_to_the_second_pixel() {
        // W = 4, H = 1. Triangle A lies left of x = 2.3, triangle B right of x = 1.7; the
        // centres 1.5 and 2.5 see only A and only B. If A is nearer its edge at 2.3 blends
        // pixel 2 (0.3 of A's colour); if B is nearer (or the depths tie) its edge at 1.7
        // blends pixel 1 (0.3 of B's colour).
        let ndc = |px: f64| 2.0 * px / 4.0 - 1.0;
        for (za, zb, a_wins) in [(0.1, 0.4, true), (0.4, 0.1, false), (0.2, 0.2, false)] {
            let (ea, eb) = (ndc(2.3), ndc(1.7));
            let clip = [
                [-10.0, 0.0, za],
                [ea, -10.0, za],
                [ea, 10.0, za],
                [10.0, 0.0, zb],
                [eb, 10.0, zb],
                [eb, -10.0, zb],
            ]
            .iter()
            .flat_map(|&[x, y, z]| [x, y, z, 1.0])
            .collect();
            let mut scene = single_image(clip, vec![[0, 1, 2], [3, 4, 5]], 4, 1, 1);
            assert_eq!(
                (0..4).map(|p| id(&scene, p)).collect::<Vec<_>>(),
                [1.0, 1.0, 2.0, 2.0]
            );
            scene.color = vec![1.0, 3.0, 7.0, 15.0];
            let pairs = find_edge_pairs(&scene.input(), None).unwrap();
            assert_eq!(pairs.len(), 1);
            assert_eq!(pairs[0].triangle, if a_wins { 0 } else { 1 });
            assert_eq!(pairs[0].from_second, !a_wins);
            let out = antialias(&scene.input(), None).unwrap();
            let expected = if a_wins {
                [1.0, 3.0, 0.7 * 7.0 + 0.3 * 3.0, 15.0]
            } else {
                [1.0, 0.7 * 3.0 + 0.3 * 7.0, 7.0, 15.0]
            };
            for (o, e) in out.iter().zip(expected) {
                assert!(
                    (o - e).abs() < 1e-12,
                    "za {za} zb {zb}: {out:?} vs {expected:?}"
                );
            }
        }
    }

    #[test]
    fn an_edge_is_a_silhouette_only_where_its_neighbour_folds_back() {
        // Triangle A = (v0, v1, v2) left of the vertical edge v1–v2 at pixel x = 2.3; triangle
        // B = (v2, v1, v3) shares that edge. Flat (v3 to the right) the edge is interior and
        // the pair (1, 2), A | B, is not blended; folded (v3 to the left, behind A) the pair
        // (1, 2), A | background, is.
        let e = 2.0 * 2.3 / 4.0 - 1.0;
        for (v3x, blended) in [(10.0, false), (-8.0, true)] {
            let clip = [
                [-10.0, 0.0, 0.1],
                [e, -10.0, 0.1],
                [e, 10.0, 0.1],
                [v3x, 0.5, 0.6],
            ]
            .iter()
            .flat_map(|&[x, y, z]| [x, y, z, 1.0])
            .collect();
            let scene = single_image(clip, vec![[0, 1, 2], [2, 1, 3]], 4, 1, 1);
            assert_eq!(id(&scene, 1), 1.0);
            assert_eq!(id(&scene, 2), if blended { 0.0 } else { 2.0 });
            let pairs = find_edge_pairs(&scene.input(), None).unwrap();
            assert_eq!(pairs.len(), usize::from(blended), "{pairs:?}");
            // Without the adjacency (two unrelated triangles) the edge always blends.
            let split = AntialiasInput {
                tri: &[[0, 1, 2], [2, 1, 3]],
                ..scene.input()
            };
            let apart = TopologyHash::new(&[[0, 1, 2], [4, 5, 3]]);
            assert_eq!(find_edge_pairs(&split, Some(&apart)).unwrap().len(), 1);
        }
    }

    #[test]
    fn topology_hash_keeps_the_first_two_distinct_opposite_vertices() {
        // Edge (0, 1) is shared by three triangles: the first two (in triangle order) are
        // each other's opposite vertices, the third has none. Edge (1, 2) has one triangle. A triangle
        // with a repeated index is left out.
        let hash = TopologyHash::new(&[[0, 1, 2], [1, 0, 3], [0, 4, 1], [2, 2, 5]]);
        assert_eq!(hash.triangle_count(), 4);
        assert_eq!(hash.opposite_vertex(0, 1, 2), Some(3));
        assert_eq!(hash.opposite_vertex(1, 0, 3), Some(2));
        assert_eq!(hash.opposite_vertex(0, 1, 4), None);
        assert_eq!(hash.opposite_vertex(1, 2, 0), None);
        assert_eq!(hash.opposite_vertex(2, 5, 2), None);
        assert_eq!(hash.opposite_vertex(3, 3, 0), None);
        // Two copies of one triangle (e.g. both windings) are not each other's opposite vertices.
        let twice = antialias_construct_topology_hash(&[[0, 1, 2], [2, 1, 0]]);
        for (a, b, own) in [(0, 1, 2), (1, 2, 0), (2, 0, 1)] {
            assert_eq!(twice.opposite_vertex(a, b, own), None);
        }
    }

    // ---- 2. a closed mesh ----

    #[test]
    fn closed_octahedron_blends_only_along_its_silhouette() {
        let (verts, tri) = octahedron();
        let hash = TopologyHash::new(&tri);
        for t in &tri {
            for (own, &(i, j)) in EDGE_ENDS.iter().enumerate() {
                assert!(
                    hash.opposite_vertex(t[i], t[j], t[own]).is_some(),
                    "closed: every edge has two sides"
                );
            }
        }
        let size = 16;
        let mut scene = single_image(posed(&verts, 0.6, 0.35), tri.clone(), size, size, 3);
        // Flat colour per face, another for the background: interior edges are colour edges too.
        scene.color = (0..size * size)
            .flat_map(|p| {
                let t = id(&scene, p);
                [
                    0.1 * t,
                    1.0 - 0.07 * t,
                    if t == 0.0 { 0.5 } else { 0.3 * (t % 3.0) },
                ]
            })
            .collect();
        let s = scene.shape;
        let pairs = find_edge_pairs(&scene.input(), Some(&hash)).unwrap();
        let out = antialias(&scene.input(), Some(&hash)).unwrap();

        let mut interior_pairs = 0;
        let mut next_to_background = vec![false; size * size];
        for y in 0..size {
            for x in 0..size {
                let p = y * size + x;
                for (q, ok) in [(p + 1, x + 1 < size), (p + size, y + 1 < size)] {
                    if !ok || id(&scene, p) == id(&scene, q) {
                        continue;
                    }
                    if id(&scene, p) == 0.0 || id(&scene, q) == 0.0 {
                        next_to_background[p] = true;
                        next_to_background[q] = true;
                    } else {
                        interior_pairs += 1;
                    }
                }
            }
        }
        assert!(
            interior_pairs > 10,
            "the view shows interior edges ({interior_pairs} pairs)"
        );
        assert!(
            pairs.len() > 10,
            "the silhouette is blended ({} pairs)",
            pairs.len()
        );
        for pair in &pairs {
            let ids = [
                id(&scene, pair.first_pixel(s)),
                id(&scene, pair.second_pixel(s)),
            ];
            assert!(
                ids.contains(&0.0),
                "a blended pair straddles the silhouette: {pair:?}"
            );
        }
        let mut changed = 0;
        for p in 0..size * size {
            let same = (0..3).all(|ch| out[3 * p + ch] == scene.color[3 * p + ch]);
            if !same {
                changed += 1;
                assert!(
                    next_to_background[p],
                    "pixel {p} changed away from the silhouette"
                );
                assert!(pairs.iter().any(|q| q.target_pixel(s) == p));
            }
            if !next_to_background[p] {
                assert!(same, "pixel {p} is unchanged");
            }
        }
        println!(
            "octahedron 16x16: {} blended pairs, {changed} pixels changed, {interior_pairs} interior pairs untouched",
            pairs.len()
        );
        assert!(changed > 10);

        // The same triangles with unshared vertices: every edge is a silhouette, so interior
        // pairs blend too.
        let split_pos: Vec<f64> = tri
            .iter()
            .flat_map(|t| {
                t.iter()
                    .flat_map(|&v| scene.pos[4 * v as usize..4 * v as usize + 4].to_vec())
            })
            .collect();
        let split_tri: Vec<[u32; 3]> = (0..tri.len() as u32)
            .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
            .collect();
        let split = AntialiasInput {
            pos: &split_pos,
            pos_layout: PosLayout::Range {
                vertices: 3 * tri.len(),
            },
            tri: &split_tri,
            ..scene.input()
        };
        let split_pairs = find_edge_pairs(&split, None).unwrap();
        let interior_blended = split_pairs
            .iter()
            .filter(|q| id(&scene, q.first_pixel(s)) != 0.0 && id(&scene, q.second_pixel(s)) != 0.0)
            .count();
        println!("unwelded: {interior_blended} interior pairs blended");
        assert!(interior_blended > 5);
    }

    // ---- 3. colour gradient ----

    #[test]
    fn grad_color_matches_central_differences() {
        let mut rng = Rng(3);
        let scene = instanced_octahedra(&[(0.6, 0.35), (-0.4, 0.8)], 16, 3, &mut rng);
        let dy = rng.values(scene.color.len(), -1.0, 1.0);
        let grad = antialias_backward(&scene.input(), None, &dy, 1.0).unwrap();
        let h = 0.5; // the forward is linear in colour: any step is exact but for rounding
        let mut worst: f64 = 0.0;
        let mut color = scene.color.clone();
        for k in 0..color.len() {
            let c0 = color[k];
            color[k] = c0 + h;
            let up = loss(
                &AntialiasInput {
                    color: &color,
                    ..scene.input()
                },
                &dy,
            );
            color[k] = c0 - h;
            let down = loss(
                &AntialiasInput {
                    color: &color,
                    ..scene.input()
                },
                &dy,
            );
            color[k] = c0;
            worst = worst.max(((up - down) / (2.0 * h) - grad.color[k]).abs());
        }
        println!(
            "grad_color: max |analytic - central difference| = {worst:e} over {} components",
            color.len()
        );
        assert!(worst < 1e-12);
    }

    // ---- 4. position gradient ----

    /// Checks `grad_pos` (exact, ε = 0; and nvdiffrast's ε) against central differences of
    /// the forward for fixed `rast`, skipping components whose step changes a decision.
    /// Returns (compared, skipped, worst exact error, worst relative error with nvdiffrast's ε).
    fn check_pos_gradient(scene: &Scene, dy: &[f64]) -> (usize, usize, f64, f64) {
        let h = 1e-6;
        let exact = backward_with_epsilon(&scene.input(), None, dy, 1.0, 0.0).unwrap();
        let nv = antialias_backward(&scene.input(), None, dy, 1.0).unwrap();
        let base = decisions(&scene.input());
        let (mut compared, mut skipped) = (0, 0);
        let (mut worst, mut worst_rel): (f64, f64) = (0.0, 0.0);
        let mut pos = scene.pos.clone();
        for k in 0..pos.len() {
            if k % 4 == 2 {
                assert_eq!(exact.pos[k], 0.0, "z gets no gradient");
                assert_eq!(nv.pos[k], 0.0, "z gets no gradient");
            }
            let p0 = pos[k];
            pos[k] = p0 + h;
            let up_ok = decisions(&scene.input_with(&pos)) == base;
            let up = loss(&scene.input_with(&pos), dy);
            pos[k] = p0 - h;
            let down_ok = decisions(&scene.input_with(&pos)) == base;
            let down = loss(&scene.input_with(&pos), dy);
            pos[k] = p0;
            if !(up_ok && down_ok) {
                skipped += 1;
                continue;
            }
            compared += 1;
            let fd = (up - down) / (2.0 * h);
            worst = worst.max((fd - exact.pos[k]).abs() / (1.0 + fd.abs()));
            if fd.abs() > 1e-3 {
                worst_rel = worst_rel.max((nv.pos[k] - fd).abs() / fd.abs());
            }
        }
        (compared, skipped, worst, worst_rel)
    }

    #[test]
    fn grad_pos_matches_central_differences_with_rast_fixed() {
        let mut rng = Rng(7);
        let instanced = instanced_octahedra(&[(0.6, 0.35), (-0.4, 0.8)], 16, 2, &mut rng);
        let ranged = ranged_scene(16, 2, &mut rng);
        for (name, scene) in [
            ("instanced octahedra", &instanced),
            ("range mode, two layers", &ranged),
        ] {
            let dy = rng.values(scene.color.len(), -1.0, 1.0);
            let pairs = find_edge_pairs(&scene.input(), None).unwrap();
            let grad = antialias_backward(&scene.input(), None, &dy, 1.0).unwrap();
            let moving = grad.pos.iter().filter(|g| **g != 0.0).count();
            let (compared, skipped, worst, worst_rel) = check_pos_gradient(scene, &dy);
            println!(
                "{name}: {} pairs, {moving}/{} components with a gradient; {compared} compared, \
                 {skipped} skipped (a decision flips); exact: max |err|/(1+|fd|) = {worst:e}; \
                 nvdiffrast eps: max rel err = {worst_rel:e}",
                pairs.len(),
                grad.pos.len()
            );
            assert!(
                moving >= scene.pos.len() / 2,
                "most components move the silhouette"
            );
            assert!(compared >= 4 * skipped && compared > 0);
            assert!(worst < 1e-7, "exact derivative");
            assert!(worst_rel < 2e-3, "nvdiffrast's 1e-3 guard on Δy");
        }
        // Both depth orders occur in the layered image.
        let layered: Vec<_> = find_edge_pairs(&ranged.input(), None)
            .unwrap()
            .into_iter()
            .filter(|p| p.batch == 1 && p.triangle == 9)
            .collect();
        assert!(layered.iter().any(|p| p.from_second) && layered.iter().any(|p| !p.from_second));
    }

    #[test]
    fn a_crossing_in_the_slack_saturates_and_passes_no_position_gradient() {
        // A triangle right of a vertical edge at pixel x = 1.53, so pixel 1's centre (1.5) is
        // 0.03 px outside it; the rast marks pixel 1 covered anyway, as a rasterizer that snaps
        // vertices may. The crossing lies within the 1/16 slack behind pixel 1's centre: r
        // clamps to 0, α = −1/2 (pixel 1 becomes the mean of the two) and no gradient reaches
        // the positions.
        let e = 2.0 * 1.53 / 4.0 - 1.0;
        let clip = [[10.0, -10.0], [e, 10.0], [e, -10.0]]
            .iter()
            .flat_map(|&[x, y]| [x, y, 0.0, 1.0])
            .collect();
        let mut scene = single_image(clip, vec![[0, 1, 2]], 4, 1, 1);
        assert_eq!(
            (0..4).map(|p| id(&scene, p)).collect::<Vec<_>>(),
            [0.0, 0.0, 1.0, 1.0]
        );
        scene.rast[4 + 3] = 1.0;
        scene.color = vec![0.0, 1.0, 5.0, 6.0];
        let pairs = find_edge_pairs(&scene.input(), None).unwrap();
        assert_eq!(pairs.len(), 1);
        assert_eq!((pairs[0].x, pairs[0].from_second), (0, true));
        assert_eq!(pairs[0].alpha, -0.5);
        let out = antialias(&scene.input(), None).unwrap();
        assert_eq!(out, [0.0, 0.5, 5.0, 6.0]);
        let grad = antialias_backward(&scene.input(), None, &[0.0, 1.0, 0.0, 0.0], 1.0).unwrap();
        assert!(grad.pos.iter().all(|&g| g == 0.0));
        assert_eq!(grad.color, [0.5, 0.5, 0.0, 0.0]);
        // Past the slack (0.1 px outside) the pair is not blended at all.
        scene.pos[4] = 2.0 * 1.6 / 4.0 - 1.0;
        scene.pos[8] = scene.pos[4];
        assert!(find_edge_pairs(&scene.input(), None).unwrap().is_empty());
    }

    #[test]
    fn pos_gradient_boost_scales_only_the_position_gradient() {
        let mut rng = Rng(11);
        let scene = instanced_octahedra(&[(0.2, 0.5)], 12, 2, &mut rng);
        let dy = rng.values(scene.color.len(), -1.0, 1.0);
        let one = antialias_backward(&scene.input(), None, &dy, 1.0).unwrap();
        let boosted = antialias_backward(&scene.input(), None, &dy, 3.0).unwrap();
        assert_eq!(one.color, boosted.color);
        assert!(one.pos.iter().any(|&g| g != 0.0));
        for (a, b) in one.pos.iter().zip(&boosted.pos) {
            assert_eq!(3.0 * a, *b);
        }
    }

    #[test]
    fn instanced_layout_equals_range_layout_with_offset_copies() {
        // [B, V, 4] instanced equals range mode over the concatenated vertices, each item
        // drawing its own copy of the triangles (ids shifted by the copy's offset).
        let mut rng = Rng(5);
        let inst = instanced_octahedra(&[(0.6, 0.35), (-0.4, 0.8)], 16, 2, &mut rng);
        let t = inst.tri.len();
        let tri2: Vec<[u32; 3]> = inst
            .tri
            .iter()
            .copied()
            .chain(inst.tri.iter().map(|v| v.map(|i| i + 6)))
            .collect();
        let mut rast2 = inst.rast.clone();
        for (p, px) in rast2.chunks_mut(4).enumerate() {
            if p >= 256 && px[3] != 0.0 {
                px[3] += t as f64;
            }
        }
        let ranged = AntialiasInput {
            rast: &rast2,
            pos_layout: PosLayout::Range { vertices: 12 },
            tri: &tri2,
            ..inst.input()
        };
        let dy = rng.values(inst.color.len(), -1.0, 1.0);
        assert_eq!(
            antialias(&inst.input(), None).unwrap(),
            antialias(&ranged, None).unwrap()
        );
        assert_eq!(
            antialias_backward(&inst.input(), None, &dy, 1.0).unwrap(),
            antialias_backward(&ranged, None, &dy, 1.0).unwrap()
        );
    }

    #[test]
    fn inconsistent_inputs_are_rejected() {
        let mut rng = Rng(1);
        let scene = instanced_octahedra(&[(0.2, 0.5)], 8, 1, &mut rng);
        let short = &scene.color[1..];
        assert!(
            antialias(
                &AntialiasInput {
                    color: short,
                    ..scene.input()
                },
                None
            )
            .is_err()
        );
        assert!(
            antialias(
                &AntialiasInput {
                    rast: &scene.rast[4..],
                    ..scene.input()
                },
                None
            )
            .is_err()
        );
        let layout = PosLayout::Instanced { vertices: 5 };
        assert!(
            antialias(
                &AntialiasInput {
                    pos_layout: layout,
                    ..scene.input()
                },
                None
            )
            .is_err()
        );
        assert!(
            antialias(
                &AntialiasInput {
                    tri: &[[0, 1, 6]],
                    ..scene.input()
                },
                None
            )
            .is_err()
        );
        let other = TopologyHash::new(&[[0, 1, 2]]);
        assert!(antialias(&scene.input(), Some(&other)).is_err());
        assert!(antialias_backward(&scene.input(), None, &[0.0; 3], 1.0).is_err());
    }

    // ---- 5. the blend against exact coverage ----

    /// `∫_{−1/2}^{1/2} clamp(a + b·y, 0, 1) dy` exactly, and the length of `y` where the clamp
    /// does not bind (its derivative in `a`). The integrand is linear between the cuts, so the
    /// midpoint rule is exact on each piece.
    fn clamped_strip(a: f64, b: f64) -> (f64, f64) {
        let mut cuts = vec![-0.5, 0.5];
        if b != 0.0 {
            for level in [0.0, 1.0] {
                let y = (level - a) / b;
                if y > -0.5 && y < 0.5 {
                    cuts.push(y);
                }
            }
        }
        cuts.sort_by(f64::total_cmp);
        let (mut area, mut active) = (0.0, 0.0);
        for w in cuts.windows(2) {
            let v = a + b * 0.5 * (w[0] + w[1]);
            area += (w[1] - w[0]) * v.clamp(0.0, 1.0);
            if v > 0.0 && v < 1.0 {
                active += w[1] - w[0];
            }
        }
        (area, active)
    }

    #[test]
    fn blend_factor_against_exact_box_coverage() {
        // An 8 × 8 image, one straight edge x = 3.5 + r + s·(y − 3.5) (pixels) with the
        // triangle to its left, so the pair (3, 3)–(4, 3) has its crossing at r from pixel
        // 0's centre. Colour 1 on the triangle, 0 off it: the forward's pixel 0 shows
        // B₀ = 1 − out₀ background, pixel 1 shows B₁ = out₁ triangle. Exact: A₀ = area of pixel
        // 0's box right of the line, A₁ = area of pixel 1's box left of it. Derivatives in r
        // from the backward (ε = 0, so they are the forward's own) against the exact ones.
        // The transposed scene (a near-horizontal edge, a next-row pair) must agree.
        let size = 8;
        let pixel0 = 3 * size + 3;
        let mut report = Vec::new();
        for s in [0.0, 0.25, 0.5, 0.75, 0.95, -0.6] {
            let mut worst = [0.0f64; 4]; // |A₀ − B₀|, |A₁ − B₁|, |A₀' − B₀'|, |A₁' − B₁'|
            for transposed in [false, true] {
                let pixel1 = if transposed {
                    pixel0 + size
                } else {
                    pixel0 + 1
                };
                for step in 0..50 {
                    let r = 0.01 + 0.02 * step as f64;
                    let line = |y: f64| 3.5 + r + s * (y - 3.5);
                    let px = [[line(-50.0), -50.0], [line(58.0), 58.0], [-100.0, 4.0]];
                    let clip = px
                        .iter()
                        .flat_map(|&[x, y]| {
                            let (x, y) = if transposed { (y, x) } else { (x, y) };
                            [
                                2.0 * x / size as f64 - 1.0,
                                2.0 * y / size as f64 - 1.0,
                                0.0,
                                1.0,
                            ]
                        })
                        .collect();
                    let mut scene = single_image(clip, vec![[0, 1, 2]], size, size, 1);
                    assert_eq!((id(&scene, pixel0), id(&scene, pixel1)), (1.0, 0.0));
                    scene.color = scene
                        .rast
                        .chunks(4)
                        .map(|r| if r[3] > 0.0 { 1.0 } else { 0.0 })
                        .collect();
                    let out = antialias(&scene.input(), None).unwrap();
                    let (b0, b1) = (1.0 - out[pixel0], out[pixel1]);
                    // d out / d r: both edge ends move by one pixel = 2/size in NDC.
                    let slope = |pixel: usize| {
                        let mut dy = vec![0.0; size * size];
                        dy[pixel] = 1.0;
                        let g = backward_with_epsilon(&scene.input(), None, &dy, 1.0, 0.0).unwrap();
                        let axis = usize::from(transposed);
                        (g.pos[axis] + g.pos[4 + axis]) * 2.0 / size as f64
                    };
                    let (db0, db1) = (-slope(pixel0), slope(pixel1));
                    let (a0, act0) = clamped_strip(0.5 - r, -s);
                    let (a1, act1) = clamped_strip(r - 0.5, s);
                    let (da0, da1) = (-act0, act1);
                    // Net transfer and its derivative are exact.
                    assert!(((b0 - b1) - (a0 - a1)).abs() < 1e-12, "s {s} r {r}");
                    assert!(((db0 - db1) - (da0 - da1)).abs() < 1e-9, "s {s} r {r}");
                    // Exact where the line stays in one box over the box's height.
                    if r + s.abs() / 2.0 <= 0.5 || r - s.abs() / 2.0 >= 0.5 {
                        assert!(
                            (a0 - b0).abs() < 1e-12 && (a1 - b1).abs() < 1e-12,
                            "s {s} r {r}"
                        );
                        assert!(
                            (da0 - db0).abs() < 1e-9 && (da1 - db1).abs() < 1e-9,
                            "s {s} r {r}"
                        );
                    }
                    assert!((a0 - b0).abs() <= s.abs() / 8.0 + 1e-12);
                    for (w, d) in worst
                        .iter_mut()
                        .zip([a0 - b0, a1 - b1, da0 - db0, da1 - db1])
                    {
                        *w = w.max(d.abs());
                    }
                }
            }
            report.push(format!(
                "s = {s:5.2}: max |A0-B0| {:.4}, |A1-B1| {:.4}, |A0'-B0'| {:.4}, |A1'-B1'| {:.4}",
                worst[0], worst[1], worst[2], worst[3]
            ));
        }
        println!("{}", report.join("\n"));
        // The exact areas themselves, against 400 × 400 supersampling of pixel 0's box.
        for (r, s) in [(0.2, 0.7), (0.45, 0.95), (0.05, 0.3)] {
            let n = 400;
            let inside = (0..n * n)
                .filter(|i| {
                    let (x, y) = ((i % n) as f64 + 0.5, (i / n) as f64 + 0.5);
                    let (x, y) = (x / n as f64 - 0.5, y / n as f64 - 0.5);
                    x > r + s * y
                })
                .count();
            let sampled = inside as f64 / (n * n) as f64;
            assert!((sampled - clamped_strip(0.5 - r, -s).0).abs() < 5e-3);
        }
    }
}
