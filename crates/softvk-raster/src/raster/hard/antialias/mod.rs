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
//! Measured in `tests::forward::blend_factor_against_exact_box_coverage`. For a straight edge
//! crossing a pair at offset `r` with slope `s = Δx/Δy` (`|s| < 1`, the triangle on pixel 0's
//! side), let `A₀` be the exact area of pixel 0's box beyond the edge and `A₁` that of pixel 1's
//! box on the triangle's side. The twin's factors are `B₀ = max(1/2 − r, 0)` on pixel 0 and
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
//! `tests::backward::grad_pos_matches_central_differences_with_rast_fixed`: on 16×16 octahedra
//! (instanced) and a two-layer scene (range mode), the backward with the guard off matches
//! central differences (step 1e-6, `rast` fixed) to 4e-9 in `|error| / (1 + |fd|)` on every
//! component whose step flips no decision (6 of 96 are skipped); with nvdiffrast's guard the
//! relative error is at most 5.3e-4 there.

mod backward;
mod forward;
mod topology;

#[cfg(test)]
mod tests;

pub use backward::antialias_backward;
pub use forward::{antialias, find_edge_pairs};
pub use topology::{TopologyHash, antialias_construct_topology_hash};

/// How far (in pixels) past either pixel centre a crossing may lie and still be blended:
/// nvdiffrast's allowance for a rasterizer that is off by up to 1/16 pixel.
pub const CROSSING_SLACK: f64 = 1.0 / 16.0;

/// What nvdiffrast adds (with the sign of Δy, in pixels) to an edge's extent across the pair
/// before dividing by it in the position gradient: keeps near-parallel edges finite.
pub const GRADIENT_DY_EPSILON: f64 = 1e-3;

/// Edge `k` of a triangle runs between these two of its vertices; it is opposite vertex `k`.
const EDGE_ENDS: [(usize, usize); 3] = [(1, 2), (2, 0), (0, 1)];

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
