//! The f64 CPU twin of the hard rasterizer and of `interpolate`, forward and backward: every
//! rule of the module docs ([`super`]) written plainly, pixel by pixel, as the oracle of the
//! kernels' tests.
//!
//! Coverage is decided in exact integer arithmetic on snapped vertices, so the twin and the
//! kernels (which snap f32 projections) agree on every pixel unless a vertex projects within a
//! rounding error of a snapping boundary, or two candidate depths are within f32's reach of
//! each other: such pixels are flagged in [`Layer::ambiguous`], and tests compare ids exactly
//! on the rest and count these.
//!
//! Gradients are the dual-number derivative ([`super::dual`]) of the same per-pixel function
//! the forward evaluates, for fixed visibility.

mod coverage;
mod interpolate;
mod shade;

#[cfg(test)]
mod tests;

pub use coverage::{
    Coverage, SNAP_LIMIT, Snapped, coverage, edge_function, homogeneous_covers,
    homogeneous_uncertain, outside_one_plane, pixel_ndc, sample, snap, snappable,
};
pub use interpolate::{AttrLayout, InterpolateGrads, interpolate, interpolate_grad};
pub use shade::{Scalar, Shaded, shade};

use super::Shape;
use super::dual::Dual;
/// A clip-space vertex `(x, y, z, w)`.
pub type Clip = [f64; 4];

/// One rasterized layer, `[B, H, W, 4]` arrays in nvdiffrast's layout.
#[derive(Clone, Debug, PartialEq)]
pub struct Layer {
    /// `(u, v, z/w, id + 1)`, zero where nothing is drawn.
    pub rast: Vec<f64>,
    /// `(du/dX, du/dY, dv/dX, dv/dY)`, zero where nothing is drawn.
    pub rast_db: Vec<f64>,
    /// Per pixel, the drawn surface's place in the depth order (what the next peeled layer
    /// starts after); `None` where nothing is drawn.
    pub keys: Vec<Option<DepthKey>>,
    /// Pixels whose id the f32 kernels may decide otherwise (see the module docs).
    pub ambiguous: Vec<bool>,
}

/// A surface's place in a pixel's depth order: nearest `z/w` first (unclamped), then the
/// highest triangle id.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthKey {
    /// `z/w` at the pixel centre, before the output's clamp.
    pub zw: f64,
    /// The triangle's index.
    pub triangle: u32,
}

impl DepthKey {
    /// Whether `self` comes before `other` in the pixel's depth order.
    pub fn before(&self, other: &DepthKey) -> bool {
        self.zw < other.zw || (self.zw == other.zw && self.triangle > other.triangle)
    }
}

/// Two depths closer than this may be ordered either way by the f32 kernels.
const DEPTH_TOLERANCE: f64 = 1e-5;

/// Within this many sub-pixel units of an uncertain triangle's edges, coverage is ambiguous.
const EDGE_TOLERANCE: f64 = 2.0;

fn corners(shape: &Shape, pos: &[f64], tri: &[[u32; 3]], b: u32, t: u32) -> [Clip; 3] {
    let base = shape.vertex_base(b);
    tri[t as usize].map(|v| {
        let o = 4 * (base + v as usize);
        [pos[o], pos[o + 1], pos[o + 2], pos[o + 3]]
    })
}

/// Rasterizes every minibatch item of `shape` (validated by [`Shape::check`]); with `previous`
/// (the keys of the layer before), the next depth-peeling layer instead of the nearest.
pub fn rasterize(
    shape: &Shape,
    pos: &[f64],
    tri: &[[u32; 3]],
    previous: Option<&[Option<DepthKey>]>,
) -> Layer {
    let (w, h) = (shape.width, shape.height);
    let n = shape.pixels();
    let mut layer = Layer {
        rast: vec![0.0; 4 * n],
        rast_db: vec![0.0; 4 * n],
        keys: vec![None; n],
        ambiguous: vec![false; n],
    };
    for b in 0..shape.batch() {
        let drawn: Vec<(u32, [Clip; 3], Coverage)> = shape
            .triangles_of(b)
            .filter_map(|t| {
                let c = corners(shape, pos, tri, b, t);
                coverage(c, w, h).map(|cov| (t, c, cov))
            })
            .collect();
        for y in 0..h {
            for x in 0..w {
                let i = (b as usize * h as usize + y as usize) * w as usize + x as usize;
                let s = sample(x, y, w, h);
                let f = pixel_ndc(x, y, w, h);
                let after = previous.and_then(|p| p[i]);
                if previous.is_some() && after.is_none() {
                    continue; // the layer before drew nothing here: nothing is behind it
                }
                let mut best: Option<(DepthKey, [Clip; 3])> = None;
                let mut ambiguous = false;
                let mut zs = Vec::new();
                for (t, c, cov) in &drawn {
                    let covered = match cov {
                        Coverage::Snapped(q) => {
                            if q.uncertain && q.boundary_distance(s).abs() < EDGE_TOLERANCE {
                                ambiguous = true;
                            }
                            q.covers(s)
                        }
                        Coverage::Homogeneous => {
                            if homogeneous_uncertain(c, f) {
                                ambiguous = true;
                            }
                            homogeneous_covers(c, f)
                        }
                    };
                    if !covered {
                        continue;
                    }
                    let key = DepthKey {
                        zw: shade_f64(c, f, w, h).zw,
                        triangle: *t,
                    };
                    if !key.zw.is_finite() {
                        continue; // edge-on at this centre: not drawn
                    }
                    zs.push(key.zw);
                    if let Some(prev) = after {
                        if key.triangle != prev.triangle
                            && (key.zw - prev.zw).abs() < DEPTH_TOLERANCE
                        {
                            ambiguous = true;
                        }
                        if !prev.before(&key) {
                            continue;
                        }
                    }
                    if best.is_none_or(|(k, _)| key.before(&k)) {
                        best = Some((key, *c));
                    }
                }
                if let Some((key, c)) = best {
                    if zs
                        .iter()
                        .filter(|&&z| (z - key.zw).abs() < DEPTH_TOLERANCE)
                        .count()
                        > 1
                    {
                        ambiguous = true;
                    }
                    let sh = shade_f64(&c, f, w, h);
                    layer.rast[4 * i..4 * i + 4].copy_from_slice(&[
                        sh.uv[0],
                        sh.uv[1],
                        sh.zw.clamp(-1.0, 1.0),
                        f64::from(key.triangle + 1),
                    ]);
                    layer.rast_db[4 * i..4 * i + 4].copy_from_slice(&sh.db);
                    layer.keys[i] = Some(key);
                }
                layer.ambiguous[i] = ambiguous;
            }
        }
    }
    layer
}

fn shade_f64(c: &[Clip; 3], f: [f64; 2], w: u32, h: u32) -> Shaded<f64> {
    shade(c.map(|v| [v[0], v[1], v[3]]), c.map(|v| v[2]), f, w, h)
}

/// The drawn triangle of a `rast` pixel (channel 3 is its id + 1), or `None`.
pub fn drawn_triangle(rast: &[f64], i: usize, triangle_count: u32) -> Option<u32> {
    let id = rast[4 * i + 3];
    (id >= 1.0 && id <= f64::from(triangle_count)).then(|| id as u32 - 1)
}

/// The backward of [`rasterize`] for the visibility in `rast`: `dy` is the upstream gradient of
/// `rast` (channels 0 and 1 are used: z/w and the id take none) and `ddb` that of `rast_db`;
/// returns the gradient of `pos` (x, y and w; z gets none).
pub fn rasterize_grad(
    shape: &Shape,
    pos: &[f64],
    tri: &[[u32; 3]],
    rast: &[f64],
    dy: &[f64],
    ddb: Option<&[f64]>,
) -> Vec<f64> {
    let (w, h) = (shape.width, shape.height);
    let mut grad = vec![0.0; pos.len()];
    for b in 0..shape.batch() {
        let base = shape.vertex_base(b);
        for y in 0..h {
            for x in 0..w {
                let i = (b as usize * h as usize + y as usize) * w as usize + x as usize;
                let Some(t) = drawn_triangle(rast, i, shape.triangle_count) else {
                    continue;
                };
                let c = corners(shape, pos, tri, b, t);
                // Inputs 3k, 3k + 1, 3k + 2: vertex k's x, y and w.
                let xyw: [[Dual<9>; 3]; 3] = std::array::from_fn(|k| {
                    std::array::from_fn(|m| Dual::input(c[k][[0, 1, 3][m]], 3 * k + m))
                });
                let sh = shade(xyw, c.map(|v| v[2]), pixel_ndc(x, y, w, h), w, h);
                let mut g = [0.0; 9];
                let mut add = |d: &Dual<9>, up: f64| {
                    if up != 0.0 {
                        g.iter_mut().zip(d.grad).for_each(|(g, d)| *g += up * d);
                    }
                };
                add(&sh.uv[0], dy[4 * i]);
                add(&sh.uv[1], dy[4 * i + 1]);
                if let Some(ddb) = ddb {
                    for k in 0..4 {
                        add(&sh.db[k], ddb[4 * i + k]);
                    }
                }
                for (k, &v) in tri[t as usize].iter().enumerate() {
                    let o = 4 * (base + v as usize);
                    grad[o] += g[3 * k];
                    grad[o + 1] += g[3 * k + 1];
                    grad[o + 3] += g[3 * k + 2];
                }
            }
        }
    }
    grad
}
