//! nvdiffrast's primitives on softvk: hard rasterization of clip-space triangles
//! (`rasterize`, with depth peeling), attribute interpolation (`interpolate`) and analytic
//! antialiasing (`antialias`), forward and backward. The f64 CPU twins are
//! [`reference`](mod@reference) and [`antialias`](mod@antialias); the GPU kernels are
//! `kernels/raster/hard/` driven by [`gpu`].
//!
//! The contract is nvdiffrast's (its documentation, its paper — Laine et al. 2020, "Modular
//! Primitives for High-Performance Differentiable Rendering" — and its behaviour as its source
//! shows it). softvk's code is its own. Where softvk follows nvdiffrast and where it differs on
//! purpose:
//!
//! - **Clip space.** Positions are OpenGL clip coordinates `(x, y, z, w)`; the view frustum is
//!   `|x|, |y|, |z| ≤ w`. A triangle wholly beyond one frustum plane is not drawn (as
//!   nvdiffrast). One with every vertex in front of the eye (`w > 0`), inside the depth range
//!   (`|z| ≤ w`) and projecting within 2^21 sub-pixel units of the centre (a guard band of
//!   2^18 / W viewport half-widths) is snapped (below) as it is, also where it leaves the
//!   viewport: nvdiffrast clips such a triangle to the viewport first and snaps the pieces, so
//!   an edge leaving the viewport may differ by a sub-pixel step; here it
//!   runs between its own snapped ends, the same for both triangles that share it. One that
//!   crosses the near or far plane (or the guard band) is drawn where, at the pixel centre, its
//!   three homogeneous edge functions have their sum's sign, the interpolated `w` is positive
//!   and `|z/w| ≤ 1`: exactly the coverage of its clipped part, unsnapped (nvdiffrast snaps the
//!   clipped pieces), so an edge it shares with a snapped neighbour can leave or double a
//!   centre within 1/32 pixel of the edge. Either way every drawn pixel reports the original
//!   triangle's id.
//! - **Pixels.** Pixel `(x, y)` (column, row; **row 0 is the bottom row**) has its centre at NDC
//!   `((2x + 1)/W − 1, (2y + 1)/H − 1)`. Outputs are `[B, H, W, 4]`, row-major from row 0.
//! - **Coverage**, as nvdiffrast's rasterizer decides it: vertices projected to the viewport are
//!   snapped to a 1/16-pixel grid (`round-half-even(x/w · 8 W)` units from the centre), and a
//!   pixel centre is inside a snapped (sub)triangle by exact integer edge functions. A centre
//!   exactly on an edge belongs to the triangle for which that edge is a left edge or a bottom
//!   edge when the triangle is taken counter-clockwise (y up): an edge shared by two triangles
//!   draws each of its centres once. Both windings are drawn; a triangle of zero snapped area is
//!   not.
//! - **Depth.** The nearest `z/w` wins, computed from the unclipped, unsnapped vertices at the
//!   pixel centre (for a snapped triangle, from the plane its corners' NDC points span: z/w is
//!   affine in NDC over a triangle in front of the eye); of two equal depths the triangle later in the draw order (the
//!   higher id) wins, as in nvdiffrast's ROP. softvk compares f32 `z/w` where nvdiffrast compares
//!   a 32-bit fixed-point depth from a plane equation, so two surfaces within one fixed-point
//!   step may be ordered differently.
//! - **Outputs.** `rast = (u, v, z/w, id + 1)`: the perspective-correct barycentrics of vertices
//!   0 and 1 from homogeneous 2D edge functions, each clamped to [0, 1] and their sum to at most
//!   1 (both scaled down), `z/w` clamped to [−1, 1]; all zero where nothing is drawn. `rast_db
//!   = (du/dX, du/dY, dv/dX, dv/dY)` per pixel, from the clamped `u, v`, as nvdiffrast.
//! - **Depth peeling.** Each layer is the next surface in the order (nearest `z/w`, then highest
//!   id) after the previous layer's, kept per pixel as its unclamped `z/w` and id. nvdiffrast
//!   keeps only strictly farther depths, so it loses one of two surfaces at exactly one depth;
//!   softvk returns both, one layer after the other.
//! - **Backward**: the exact derivative of this forward (through the clamps, which pass no
//!   gradient where they bind) for fixed visibility, to `x`, `y` and `w` of the three vertices;
//!   `z/w` and the id carry none. nvdiffrast adds 1e-6 to the area and ignores the clamps; the
//!   two agree wherever the barycentrics are in range. Sums are in a fixed order (no float
//!   atomics): the same bits on every run.

pub mod antialias;
pub mod dual;
pub mod gpu;
pub mod reference;
pub mod texture;

use crate::error::{Error, Result};

/// Sub-pixel grid of the snapped vertices: 16 steps a pixel (nvdiffrast's `CR_SUBPIXEL_LOG2`).
pub const SUBPIXELS: i64 = 16;

/// The largest image side the kernels address: every snapped coordinate, `8 W` units each side
/// of the centre, and every edge function stay well inside their integer ranges.
pub const MAX_SIZE: u32 = 1 << 15;

/// How the minibatch finds its triangles (nvdiffrast's two modes).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Topology {
    /// `pos [B, V, 4]`: every minibatch item draws all triangles over its own vertices.
    Instanced {
        /// B.
        batch: u32,
    },
    /// `pos [V, 4]` shared: minibatch item `b` draws triangles `first .. first + count` of
    /// `ranges[b] = [first, count]`; ids stay the global triangle indices.
    Ranged(Vec<[u32; 2]>),
}

/// What one rasterization is over: the sizes every primitive checks its arrays against.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Shape {
    /// Image width W in pixels.
    pub width: u32,
    /// Image height H in pixels.
    pub height: u32,
    /// Vertices V (per minibatch item in instanced mode).
    pub vertex_count: u32,
    /// Triangles T.
    pub triangle_count: u32,
    /// The minibatch.
    pub topology: Topology,
}

impl Shape {
    /// Minibatch items B.
    pub fn batch(&self) -> u32 {
        match &self.topology {
            Topology::Instanced { batch } => *batch,
            Topology::Ranged(r) => r.len() as u32,
        }
    }

    /// Pixels over the minibatch.
    pub fn pixels(&self) -> usize {
        self.batch() as usize * self.width as usize * self.height as usize
    }

    /// Floats of `pos`: `B·V·4` instanced, `V·4` ranged.
    pub fn pos_len(&self) -> usize {
        let sets = match self.topology {
            Topology::Instanced { batch } => batch as usize,
            Topology::Ranged(_) => 1,
        };
        sets * self.vertex_count as usize * 4
    }

    /// The triangles minibatch item `b` draws, in draw order.
    pub fn triangles_of(&self, b: u32) -> std::ops::Range<u32> {
        match &self.topology {
            Topology::Instanced { .. } => 0..self.triangle_count,
            Topology::Ranged(r) => r[b as usize][0]..r[b as usize][0] + r[b as usize][1],
        }
    }

    /// The first vertex of minibatch item `b`'s positions.
    pub fn vertex_base(&self, b: u32) -> usize {
        match self.topology {
            Topology::Instanced { .. } => b as usize * self.vertex_count as usize,
            Topology::Ranged(_) => 0,
        }
    }

    /// Checks the sizes and the triangles against nvdiffrast's contract: one clear error for
    /// anything the kernels could not draw sensibly.
    pub fn check(&self, tri: &[[u32; 3]]) -> Result<()> {
        let what = "rasterize";
        if self.width == 0 || self.height == 0 || self.width > MAX_SIZE || self.height > MAX_SIZE {
            return Err(Error::Input(format!(
                "{what}: resolution {}x{} (height x width) is outside 1..={MAX_SIZE}",
                self.height, self.width
            )));
        }
        if self.batch() == 0 {
            return Err(Error::Input(format!("{what}: the minibatch is empty")));
        }
        if self.triangle_count >= 1 << 24 {
            return Err(Error::Input(format!(
                "{what}: {} triangles; rast holds ids as float32, exact below 2^24",
                self.triangle_count
            )));
        }
        if tri.len() != self.triangle_count as usize {
            return Err(Error::Input(format!(
                "{what}: {} triangles given for {}",
                tri.len(),
                self.triangle_count
            )));
        }
        if let Some((t, bad)) = tri
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&v| v >= self.vertex_count))
        {
            return Err(Error::Input(format!(
                "{what}: triangle {t} has vertex index {} outside the {} vertices",
                bad.iter().max().copied().unwrap_or(0),
                self.vertex_count
            )));
        }
        if let Topology::Ranged(ranges) = &self.topology {
            for (b, &[first, count]) in ranges.iter().enumerate() {
                if u64::from(first) + u64::from(count) > u64::from(self.triangle_count) {
                    return Err(Error::Input(format!(
                        "{what}: range {b} [{first}, {first} + {count}) passes the {} triangles",
                        self.triangle_count
                    )));
                }
            }
        }
        Ok(())
    }

    /// Checks `pos` for this shape: its length and that every coordinate is finite.
    pub fn check_pos<T: Copy + Into<f64>>(&self, pos: &[T]) -> Result<()> {
        if pos.len() != self.pos_len() {
            return Err(Error::Input(format!(
                "rasterize: pos holds {} floats, the shape needs {}",
                pos.len(),
                self.pos_len()
            )));
        }
        match pos.iter().position(|&c| !c.into().is_finite()) {
            None => Ok(()),
            Some(i) => Err(Error::Input(format!(
                "rasterize: vertex {} has a coordinate that is not finite ({})",
                i / 4,
                pos[i].into()
            ))),
        }
    }
}
