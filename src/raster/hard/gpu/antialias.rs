//! `antialias` on the GPU (the twin behind it until its kernels land).

use super::{AntialiasArgs, HardRasterizer, antialias_input, narrow, wide};
use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::raster::hard::antialias::{self, TopologyHash};

impl HardRasterizer {
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
