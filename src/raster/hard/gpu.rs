//! The hard rasterizer, `interpolate` and `antialias` on the GPU: [`HardRasterizer`].

use super::Shape;
use super::antialias::{self, AntialiasInput, ImageShape, PosLayout, TopologyHash};
use super::reference::{self, AttrLayout};
use crate::error::{Error, Result};
use crate::gpu::Context;

/// One rasterized layer as the host gets it, `[B, H, W, 4]` f32 (nvdiffrast's layout).
#[derive(Clone, Debug, PartialEq)]
pub struct HardLayer {
    /// `(u, v, z/w, id + 1)`.
    pub rast: Vec<f32>,
    /// `(du/dX, du/dY, dv/dX, dv/dY)`.
    pub rast_db: Vec<f32>,
    /// Per pixel the drawn surface's depth key `(z/w bits, id + 1)` (`[0, 0]`: none), what the
    /// next depth-peeling layer starts after.
    pub keys: Vec<[u32; 2]>,
}

/// The gradients of `interpolate`, f32.
#[derive(Clone, Debug, PartialEq)]
pub struct InterpolateGrads32 {
    /// Same shape as `attr`.
    pub attr: Vec<f32>,
    /// `[B, H, W, 4]`.
    pub rast: Vec<f32>,
    /// `[B, H, W, 4]`.
    pub rast_db: Vec<f32>,
}

/// The arrays `antialias` reads, f32, in nvdiffrast's layouts.
#[derive(Clone, Copy, Debug)]
pub struct AntialiasArgs<'a> {
    /// `[B, H, W, C]`.
    pub color: &'a [f32],
    /// `[B, H, W, 4]`, as `rasterize` wrote it.
    pub rast: &'a [f32],
    /// `[B, V, 4]` (instanced) or `[V, 4]`.
    pub pos: &'a [f32],
    /// Whether `pos` holds one set of vertices per minibatch item.
    pub instanced: bool,
    /// V.
    pub vertex_count: u32,
    /// `[T, 3]`.
    pub tri: &'a [[u32; 3]],
    /// B, H, W, C.
    pub batch: u32,
    /// H.
    pub height: u32,
    /// W.
    pub width: u32,
    /// C.
    pub channels: u32,
}

/// nvdiffrast's primitives on the GPU.
pub struct HardRasterizer {}

fn wide(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| f64::from(x)).collect()
}

fn narrow(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

impl HardRasterizer {
    /// Builds the pipelines.
    pub fn new(_ctx: &Context) -> Result<Self> {
        Ok(Self {})
    }

    /// Rasterizes `pos` (f32, [`Shape::pos_len`]) with `tri`; with `previous` (a layer's
    /// keys), the next depth-peeling layer.
    pub fn rasterize(
        &mut self,
        _ctx: &Context,
        shape: &Shape,
        pos: &[f32],
        tri: &[[u32; 3]],
        previous: Option<&[[u32; 2]]>,
    ) -> Result<HardLayer> {
        shape.check(tri)?;
        shape.check_pos(pos)?;
        let prev: Option<Vec<Option<reference::DepthKey>>> = previous.map(|p| {
            p.iter()
                .map(|k| {
                    (k[1] != 0).then(|| reference::DepthKey {
                        zw: f64::from(f32::from_bits(k[0])),
                        triangle: k[1] - 1,
                    })
                })
                .collect()
        });
        let l = reference::rasterize(shape, &wide(pos), tri, prev.as_deref());
        Ok(HardLayer {
            rast: narrow(&l.rast),
            rast_db: narrow(&l.rast_db),
            keys: l
                .keys
                .iter()
                .map(|k| k.map_or([0, 0], |k| [(k.zw as f32).to_bits(), k.triangle + 1]))
                .collect(),
        })
    }

    /// The gradient of `pos` given the upstream gradients of `rast` (`dy`, `[B, H, W, 4]`) and
    /// of `rast_db` (`ddb`).
    #[allow(clippy::too_many_arguments)]
    pub fn rasterize_grad(
        &mut self,
        _ctx: &Context,
        shape: &Shape,
        pos: &[f32],
        tri: &[[u32; 3]],
        rast: &[f32],
        dy: &[f32],
        ddb: Option<&[f32]>,
    ) -> Result<Vec<f32>> {
        let ddb = ddb.map(wide);
        Ok(narrow(&reference::rasterize_grad(
            shape,
            &wide(pos),
            tri,
            &wide(rast),
            &wide(dy),
            ddb.as_deref(),
        )))
    }

    /// `interpolate`: `(out [B, H, W, A], out_da [B, H, W, 2N])`.
    #[allow(clippy::too_many_arguments)]
    pub fn interpolate(
        &mut self,
        _ctx: &Context,
        attr: &[f32],
        layout: AttrLayout,
        rast: &[f32],
        tri: &[[u32; 3]],
        pixels_per_item: usize,
        rast_db: Option<&[f32]>,
        diff: &[u32],
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        let db = rast_db.map(wide);
        let (o, d) = reference::interpolate(
            &wide(attr),
            layout,
            &wide(rast),
            tri,
            pixels_per_item,
            db.as_deref(),
            diff,
        );
        Ok((narrow(&o), narrow(&d)))
    }

    /// The backward of [`HardRasterizer::interpolate`].
    #[allow(clippy::too_many_arguments)]
    pub fn interpolate_grad(
        &mut self,
        _ctx: &Context,
        attr: &[f32],
        layout: AttrLayout,
        rast: &[f32],
        tri: &[[u32; 3]],
        pixels_per_item: usize,
        rast_db: Option<&[f32]>,
        diff: &[u32],
        dy: &[f32],
        dda: Option<&[f32]>,
    ) -> Result<InterpolateGrads32> {
        let db = rast_db.map(wide);
        let dda = dda.map(wide);
        let g = reference::interpolate_grad(
            &wide(attr),
            layout,
            &wide(rast),
            tri,
            pixels_per_item,
            db.as_deref(),
            diff,
            &wide(dy),
            dda.as_deref(),
        );
        Ok(InterpolateGrads32 {
            attr: narrow(&g.attr),
            rast: narrow(&g.rast),
            rast_db: narrow(&g.rast_db),
        })
    }

    /// `antialias`: the image with its silhouette edges blended by the coverage their geometry
    /// gives.
    pub fn antialias(
        &mut self,
        _ctx: &Context,
        args: &AntialiasArgs<'_>,
        topology: &TopologyHash,
    ) -> Result<Vec<f32>> {
        let (color, rast, pos) = (wide(args.color), wide(args.rast), wide(args.pos));
        let input = antialias_input(args, &color, &rast, &pos);
        antialias::antialias(&input, Some(topology))
            .map(|v| narrow(&v))
            .map_err(Error::Input)
    }

    /// The backward of [`HardRasterizer::antialias`]: `(grad_color, grad_pos)`.
    pub fn antialias_grad(
        &mut self,
        _ctx: &Context,
        args: &AntialiasArgs<'_>,
        topology: &TopologyHash,
        dy: &[f32],
        pos_gradient_boost: f64,
    ) -> Result<(Vec<f32>, Vec<f32>)> {
        let (color, rast, pos) = (wide(args.color), wide(args.rast), wide(args.pos));
        let input = antialias_input(args, &color, &rast, &pos);
        let g =
            antialias::antialias_backward(&input, Some(topology), &wide(dy), pos_gradient_boost)
                .map_err(Error::Input)?;
        Ok((narrow(&g.color), narrow(&g.pos)))
    }
}

fn antialias_input<'a>(
    args: &AntialiasArgs<'a>,
    color: &'a [f64],
    rast: &'a [f64],
    pos: &'a [f64],
) -> AntialiasInput<'a> {
    let vertices = args.vertex_count as usize;
    AntialiasInput {
        color,
        rast,
        pos,
        pos_layout: if args.instanced {
            PosLayout::Instanced { vertices }
        } else {
            PosLayout::Range { vertices }
        },
        tri: args.tri,
        shape: ImageShape {
            batch: args.batch as usize,
            height: args.height as usize,
            width: args.width as usize,
            channels: args.channels as usize,
        },
    }
}
