//! The colour generator (SoftRas's "color generator"): vertex colours sampled from the input
//! image through a learned selection, so that a reconstruction keeps the colours of what it
//! was given.
//!
//! Per object the network outputs `P × K` sampling logits `s` and `V × P` selection logits `w`
//! (after the mesh head's `3 V + 3`), and with `q_k` the mean RGB of cell `k` of the input image
//! pooled to a `grid × grid` lattice of [`POOL`]-pixel cells (`K = grid²`):
//!
//! ```text
//! C_p = Σ_k softmax(s_p)_k q_k          a palette of P colours, each a learned sample of the image
//! c_i = Σ_p softmax(w_i)_p C_p          each vertex a learned selection over the palette
//! ```
//!
//! Every colour is a convex combination of the image's own (pooled) colours, so the colours
//! cannot drift out of what the input shows, and what is learned is *where* to look and which
//! sample each vertex takes; the network need not encode colour values in its weights.
//! Kernels (`kernels/softvk/recon/`): `recon_pool.comp` (the pooled cells), `recon_palette.comp`,
//! `recon_colors.comp` (written to every copy of the object in the renderer's vertex-colour
//! layout), and the backward `recon_colors_backward.comp` (dL/dw) and
//! `recon_palette_backward.comp` (dL/dC through the selections, then dL/ds). The input image
//! gets no gradient. Deterministic: each output has one writer and sums run in a fixed order.
//! Twins: [`cpu`].

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, LimitKind, Result};
use crate::gpu::{BufferRange, Context, Kernel, Recorder};
use crate::specs;

/// Colours in each object's palette (P).
pub const PALETTE: u32 = 8;

/// Pixels per side of a pooled cell: a 64² input gives a 16 × 16 grid (K = 256).
pub const POOL: u32 = 4;

/// Network outputs per object of a generator for `vertices` vertices and `image`² inputs:
/// `P K` sampling then `V P` selection logits (`K = (image / POOL)²`).
pub fn outputs_per_object(vertices: u32, image: u32) -> u64 {
    let grid = u64::from(image / POOL);
    u64::from(PALETTE) * (grid * grid + u64::from(vertices))
}

/// Push constants of the five kernels (`kernels/softvk/include/recon_colors.glsl`).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct ColorPush {
    vertex_count: u32,
    objects: u32,
    copies: u32,
    stride: u32,
    offset: u32,
    palette: u32,
    grid: u32,
    pool: u32,
}

/// Where the generator's outputs sit in each object's network outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HeadLayout {
    /// Network outputs per object.
    pub stride: u32,
    /// The generator's first output in an object's.
    pub offset: u32,
}

/// The colour generator on the GPU for a template of `V` vertices and square inputs.
pub struct ColorGenerator {
    pool: Arc<Kernel>,
    palette: Arc<Kernel>,
    colors: Arc<Kernel>,
    colors_backward: Arc<Kernel>,
    palette_backward: Arc<Kernel>,
    vertex_count: u32,
    grid: u32,
}

impl ColorGenerator {
    /// Pipelines for `vertex_count` vertices and `image`² inputs (a positive multiple of
    /// [`POOL`], else [`Error::Input`]). The palette's loops run over the pooled cells and
    /// the vertices: more of either than the device's shader loop limit is
    /// [`Error::DeviceLimit`].
    pub fn new(ctx: &Context, vertex_count: u32, image: u32) -> Result<Self> {
        if image == 0 || image % POOL != 0 || vertex_count == 0 {
            return Err(Error::Input(format!(
                "colour generator: {image}² images of {vertex_count} vertices (the side must \
                 be a positive multiple of {POOL})"
            )));
        }
        let grid = image / POOL;
        if let Some(max) = ctx.info().shader_loop_limit() {
            let need = u64::from(grid * grid).max(u64::from(vertex_count));
            if need > max {
                return Err(Error::DeviceLimit {
                    kind: LimitKind::LoopIterations,
                    what: "the colour generator's palette (loops over the pooled cells and the \
                           vertices)"
                        .into(),
                    need,
                    max,
                    device: ctx.info().name.clone(),
                    hint: "use smaller images or a template with fewer vertices",
                });
            }
        }
        Ok(Self {
            pool: ctx.kernel(&specs::RECON_POOL, &[])?,
            palette: ctx.kernel(&specs::RECON_PALETTE, &[])?,
            colors: ctx.kernel(&specs::RECON_COLORS, &[])?,
            colors_backward: ctx.kernel(&specs::RECON_COLORS_BACKWARD, &[])?,
            palette_backward: ctx.kernel(&specs::RECON_PALETTE_BACKWARD, &[])?,
            vertex_count,
            grid,
        })
    }

    /// Pooled cells K of an input.
    pub fn cells(&self) -> u32 {
        self.grid * self.grid
    }

    /// Network outputs per object: `P K` sampling then `V P` selection logits.
    pub fn outputs_per_object(&self) -> u64 {
        outputs_per_object(self.vertex_count, self.grid * POOL)
    }

    /// Floats of the pooled-cell scratch for `objects` objects (4 per cell).
    pub fn pooled_floats(&self, objects: u32) -> u64 {
        4 * u64::from(self.cells()) * u64::from(objects)
    }

    /// Floats of the palette scratch for `objects` objects (4 per entry).
    pub fn palette_floats(&self, objects: u32) -> u64 {
        4 * u64::from(PALETTE) * u64::from(objects)
    }

    /// The push constants, after checking the shape and the ranges both passes bind.
    fn checked_push(
        &self,
        objects: u32,
        copies: u32,
        head: HeadLayout,
        outputs: &BufferRange<'_>,
        pooled: &BufferRange<'_>,
        palette: &BufferRange<'_>,
    ) -> Result<ColorPush> {
        let push = self.push(objects, copies, head)?;
        let b = u64::from(objects);
        crate::gpu::check_floats("colours: outputs", outputs, b * u64::from(head.stride))?;
        crate::gpu::check_floats("colours: pooled", pooled, self.pooled_floats(objects))?;
        crate::gpu::check_floats("colours: palette", palette, self.palette_floats(objects))?;
        Ok(push)
    }

    fn push(&self, objects: u32, copies: u32, head: HeadLayout) -> Result<ColorPush> {
        if objects == 0 || copies == 0 {
            return Err(Error::Input(
                "the colour generator needs at least one object and one copy".into(),
            ));
        }
        if u64::from(head.offset) + self.outputs_per_object() > u64::from(head.stride) {
            return Err(Error::Input(format!(
                "colour generator: {} outputs from {} do not fit a stride of {}",
                self.outputs_per_object(),
                head.offset,
                head.stride
            )));
        }
        Ok(ColorPush {
            vertex_count: self.vertex_count,
            objects,
            copies,
            stride: head.stride,
            offset: head.offset,
            palette: PALETTE,
            grid: self.grid,
            pool: POOL,
        })
    }

    /// Records the forward for `objects` objects of `copies` copies each: the network
    /// `outputs` (laid out as `head` says) and the input `images` (`4 × H × W` floats per
    /// object, planar RGBA in [0, 1]) → `pooled` ([`Self::pooled_floats`]), `palette`
    /// ([`Self::palette_floats`]; the backward reads both) and `colors`, the renderer's vertex
    /// colours (RGB and an unused float per vertex, copy `k` of object `b` as mesh
    /// `b · copies + k`).
    #[allow(clippy::too_many_arguments)]
    pub fn record_forward(
        &self,
        rec: &mut Recorder<'_>,
        objects: u32,
        copies: u32,
        head: HeadLayout,
        outputs: BufferRange<'_>,
        images: BufferRange<'_>,
        pooled: BufferRange<'_>,
        palette: BufferRange<'_>,
        colors: BufferRange<'_>,
    ) -> Result<()> {
        let push = self.checked_push(objects, copies, head, &outputs, &pooled, &palette)?;
        let (b, v) = (u64::from(objects), u64::from(self.vertex_count));
        let side = u64::from(self.grid * POOL);
        crate::gpu::check_floats("colours: images", &images, 4 * b * side * side)?;
        crate::gpu::check_floats("colours: colours", &colors, 4 * b * u64::from(copies) * v)?;
        rec.dispatch(
            &self.pool,
            &specs::ReconPoolBindings { images, pooled }.for_kernel(&self.pool)?,
            &push,
            crate::gpu::groups(b * u64::from(self.cells()), 64)?,
        )?;
        rec.dispatch(
            &self.palette,
            &specs::ReconPaletteBindings {
                outputs,
                pooled,
                palette,
            }
            .for_kernel(&self.palette)?,
            &push,
            crate::gpu::groups(b * u64::from(PALETTE), 64)?,
        )?;
        rec.dispatch(
            &self.colors,
            &specs::ReconColorsBindings {
                outputs,
                palette,
                colors,
            }
            .for_kernel(&self.colors)?,
            &push,
            crate::gpu::groups(b * v, 64)?,
        )
    }

    /// Records the backward: dL/d(colours) (3 floats per copy vertex, the renderer's
    /// backward's layout) with the forward's `pooled` and `palette` → the generator's slots of
    /// dL/d(`outputs`) (overwritten; the other slots are left alone).
    #[allow(clippy::too_many_arguments)]
    pub fn record_backward(
        &self,
        rec: &mut Recorder<'_>,
        objects: u32,
        copies: u32,
        head: HeadLayout,
        outputs: BufferRange<'_>,
        pooled: BufferRange<'_>,
        palette: BufferRange<'_>,
        d_colors: BufferRange<'_>,
        d_outputs: BufferRange<'_>,
    ) -> Result<()> {
        let push = self.checked_push(objects, copies, head, &outputs, &pooled, &palette)?;
        let (b, v) = (u64::from(objects), u64::from(self.vertex_count));
        crate::gpu::check_floats(
            "colours: d_colours",
            &d_colors,
            3 * b * u64::from(copies) * v,
        )?;
        crate::gpu::check_floats("colours: d_outputs", &d_outputs, b * u64::from(head.stride))?;
        rec.dispatch(
            &self.colors_backward,
            &specs::ReconColorsBackwardBindings {
                outputs,
                palette,
                d_colors,
                d_outputs,
            }
            .for_kernel(&self.colors_backward)?,
            &push,
            crate::gpu::groups(b * v, 64)?,
        )?;
        rec.dispatch(
            &self.palette_backward,
            &specs::ReconPaletteBackwardBindings {
                outputs,
                pooled,
                palette,
                d_colors,
                d_outputs,
            }
            .for_kernel(&self.palette_backward)?,
            &push,
            crate::gpu::groups(b * u64::from(PALETTE), 64)?,
        )
    }
}

/// CPU twin, in f64.
pub mod cpu {
    use super::{HeadLayout, PALETTE, POOL};

    /// The generator's shape for the twin.
    #[derive(Clone, Copy, Debug)]
    pub struct Shape {
        /// Template vertices V.
        pub vertices: usize,
        /// Input side (a multiple of [`POOL`]).
        pub image: usize,
        /// Where the generator's outputs sit.
        pub head: HeadLayout,
    }

    impl Shape {
        fn cells(&self) -> usize {
            let g = self.image / POOL as usize;
            g * g
        }

        fn sampling(&self, b: usize, p: usize) -> usize {
            b * self.head.stride as usize + self.head.offset as usize + p * self.cells()
        }

        fn selection(&self, b: usize, i: usize) -> usize {
            b * self.head.stride as usize
                + self.head.offset as usize
                + PALETTE as usize * (self.cells() + i)
        }
    }

    /// What the forward computes for each object: its pooled cells, its palette and the
    /// softmaxes (`a` per palette entry over the cells, `beta` per vertex over the palette).
    pub struct Forward {
        /// Per object, the mean RGB of each cell.
        pub pooled: Vec<Vec<[f64; 3]>>,
        /// Per object, the palette.
        pub palette: Vec<Vec<[f64; 3]>>,
        /// Per object, `a[p][k]`.
        pub a: Vec<Vec<Vec<f64>>>,
        /// Per object, `beta[i][p]`.
        pub beta: Vec<Vec<Vec<f64>>>,
        /// Per object, the vertex colours.
        pub colors: Vec<Vec<[f64; 3]>>,
    }

    fn softmax(x: &[f64]) -> Vec<f64> {
        let m = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let e: Vec<f64> = x.iter().map(|&v| (v - m).exp()).collect();
        let total: f64 = e.iter().sum();
        e.iter().map(|v| v / total).collect()
    }

    /// The forward for `objects` objects: `outputs` (`objects × stride`) and `images` (`4 × H
    /// × W` per object, planar RGBA).
    pub fn forward(shape: Shape, outputs: &[f64], images: &[f64], objects: usize) -> Forward {
        let (side, pool, g) = (shape.image, POOL as usize, shape.image / POOL as usize);
        let plane = side * side;
        let p_n = PALETTE as usize;
        let mut f = Forward {
            pooled: Vec::new(),
            palette: Vec::new(),
            a: Vec::new(),
            beta: Vec::new(),
            colors: Vec::new(),
        };
        for b in 0..objects {
            let img = &images[4 * b * plane..4 * (b + 1) * plane];
            let pooled: Vec<[f64; 3]> = (0..g * g)
                .map(|k| {
                    let (gy, gx) = (k / g, k % g);
                    let mut s = [0.0; 3];
                    for dy in 0..pool {
                        for dx in 0..pool {
                            let p = (gy * pool + dy) * side + gx * pool + dx;
                            for (ch, s) in s.iter_mut().enumerate() {
                                *s += img[ch * plane + p];
                            }
                        }
                    }
                    s.map(|x| x / (pool * pool) as f64)
                })
                .collect();
            let a: Vec<Vec<f64>> = (0..p_n)
                .map(|p| {
                    let s0 = shape.sampling(b, p);
                    softmax(&outputs[s0..s0 + g * g])
                })
                .collect();
            let palette: Vec<[f64; 3]> = a
                .iter()
                .map(|a| {
                    let mut c = [0.0; 3];
                    for (ak, q) in a.iter().zip(&pooled) {
                        for ch in 0..3 {
                            c[ch] += ak * q[ch];
                        }
                    }
                    c
                })
                .collect();
            let beta: Vec<Vec<f64>> = (0..shape.vertices)
                .map(|i| {
                    let w0 = shape.selection(b, i);
                    softmax(&outputs[w0..w0 + p_n])
                })
                .collect();
            let colors = beta
                .iter()
                .map(|beta| {
                    let mut c = [0.0; 3];
                    for (bp, cp) in beta.iter().zip(&palette) {
                        for ch in 0..3 {
                            c[ch] += bp * cp[ch];
                        }
                    }
                    c
                })
                .collect();
            f.pooled.push(pooled);
            f.palette.push(palette);
            f.a.push(a);
            f.beta.push(beta);
            f.colors.push(colors);
        }
        f
    }

    /// Adds to `d_outputs` the generator's gradient from dL/d(copy colours) (`objects ×
    /// copies × V`, mesh after mesh).
    pub fn backward(
        shape: Shape,
        outputs: &[f64],
        images: &[f64],
        objects: usize,
        copies: usize,
        d_colors: &[[f64; 3]],
        d_outputs: &mut [f64],
    ) {
        let f = forward(shape, outputs, images, objects);
        let v_n = shape.vertices;
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        for b in 0..objects {
            let mut d_palette = vec![[0.0; 3]; PALETTE as usize];
            for i in 0..v_n {
                let mut g = [0.0; 3];
                for j in 0..copies {
                    for (gk, d) in g.iter_mut().zip(d_colors[(b * copies + j) * v_n + i]) {
                        *gk += d;
                    }
                }
                let w0 = shape.selection(b, i);
                for (p, dp) in d_palette.iter_mut().enumerate() {
                    let beta = f.beta[b][i][p];
                    d_outputs[w0 + p] += beta * dot(sub(f.palette[b][p], f.colors[b][i]), g);
                    for ch in 0..3 {
                        dp[ch] += beta * g[ch];
                    }
                }
            }
            for (p, dp) in d_palette.iter().enumerate() {
                let s0 = shape.sampling(b, p);
                for (k, q) in f.pooled[b].iter().enumerate() {
                    d_outputs[s0 + k] += f.a[b][p][k] * dot(sub(*q, f.palette[b][p]), *dp);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::cpu::{Shape, backward, forward};
    use super::*;
    use softvk_testing::{Lcg, assert_grad_matches_fd};

    fn shape(vertices: usize, image: usize, offset: u32) -> Shape {
        let cells = (image / POOL as usize).pow(2);
        let own = PALETTE as usize * (cells + vertices);
        Shape {
            vertices,
            image,
            head: HeadLayout {
                stride: offset + own as u32 + 2,
                offset,
            },
        }
    }

    #[test]
    fn push_constant_struct_matches_the_kernels_layout() {
        let size = std::mem::size_of::<ColorPush>() as u32;
        for spec in [
            &specs::RECON_POOL,
            &specs::RECON_PALETTE,
            &specs::RECON_COLORS,
            &specs::RECON_COLORS_BACKWARD,
            &specs::RECON_PALETTE_BACKWARD,
        ] {
            assert_eq!(size, spec.push_constant_size, "{}", spec.name);
        }
    }

    #[test]
    fn twin_gradient_matches_central_differences() {
        let (objects, copies) = (2, 2);
        let s = shape(5, 8, 3);
        let mut rng = Lcg(5);
        let outputs: Vec<f64> = (0..objects * s.head.stride as usize)
            .map(|_| rng.range(-2.0, 2.0))
            .collect();
        let images: Vec<f64> = (0..objects * 4 * 64).map(|_| rng.range(0.0, 1.0)).collect();
        let w: Vec<[f64; 3]> = (0..objects * copies * s.vertices)
            .map(|_| [0; 3].map(|_| rng.range(-1.0, 1.0)))
            .collect();
        let mut grad = vec![0.0; outputs.len()];
        backward(s, &outputs, &images, objects, copies, &w, &mut grad);
        // L = Σ_copies w · colour (every copy has the object's colours).
        assert_grad_matches_fd(&outputs, &grad, 1e-6, |r| {
            let f = forward(s, r, &images, objects);
            let mut l = 0.0;
            for b in 0..objects {
                for j in 0..copies {
                    for (i, c) in f.colors[b].iter().enumerate() {
                        let wi = w[(b * copies + j) * s.vertices + i];
                        l += c[0] * wi[0] + c[1] * wi[1] + c[2] * wi[2];
                    }
                }
            }
            l
        });
        // Slots outside the generator's range get nothing.
        for b in 0..objects {
            let row = &grad[b * s.head.stride as usize..(b + 1) * s.head.stride as usize];
            assert!(
                row[..3]
                    .iter()
                    .chain(&row[row.len() - 2..])
                    .all(|&g| g == 0.0)
            );
        }
    }

    /// The colours come from the image: logits that pick one cell per palette entry and one
    /// entry per vertex give each vertex exactly the colour of its cell.
    #[test]
    fn sharp_logits_copy_the_colours_of_the_chosen_cells() {
        let s = shape(3, 8, 0);
        let plane = 64;
        // Cell k (2 × 2 grid of 4-pixel cells) has colour (k/4, 1 − k/4, 0.5).
        let mut image = vec![0.0; 4 * plane];
        for y in 0..8 {
            for x in 0..8 {
                let k = (y / 4) * 2 + x / 4;
                let c = [k as f64 / 4.0, 1.0 - k as f64 / 4.0, 0.5, 1.0];
                for ch in 0..4 {
                    image[ch * plane + y * 8 + x] = c[ch];
                }
            }
        }
        let mut outputs = vec![0.0; s.head.stride as usize];
        // Entry p samples cell p % 4; vertex i selects entry 2 i + 1.
        for p in 0..PALETTE as usize {
            outputs[p * 4 + p % 4] = 60.0;
        }
        for i in 0..3 {
            outputs[PALETTE as usize * 4 + i * PALETTE as usize + 2 * i + 1] = 60.0;
        }
        let f = forward(s, &outputs, &image, 1);
        for i in 0..3 {
            let k = (2 * i + 1) % 4;
            let want = [k as f64 / 4.0, 1.0 - k as f64 / 4.0, 0.5];
            for ch in 0..3 {
                assert!(
                    (f.colors[0][i][ch] - want[ch]).abs() < 1e-12,
                    "vertex {i}: {:?} vs {want:?}",
                    f.colors[0][i]
                );
            }
        }
    }
}
