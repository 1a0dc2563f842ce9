//! A cube-map lookup, forward ([`sample_cube`]) and backward ([`sample_cube_backward`]), in
//! every filter mode: the nearest texel or the seamless bilinear taps on the levels `λ` picks.

use super::level::{CubeLevelInput, cube_level_gradient, cube_mip_levels};
use super::{
    Projection, check_cube, cube_bilinear, cube_bilinear_backward, cube_offset, cube_texel,
    texel_of,
};
use crate::error::{Error, Result};
use crate::raster::hard::texture::{Filter, MipStack};
/// One pixel's cube-map sample of minibatch item `item`: `C` values, in any filter mode
/// (`level` read by the mipmap modes only).
pub fn sample_cube(
    stack: &MipStack,
    item: usize,
    dir: [f64; 3],
    level: CubeLevelInput,
    filter: Filter,
) -> Result<Vec<f64>> {
    check_cube(stack, item)?;
    let Some(p) = Projection::of(dir) else {
        return Ok(vec![0.0; stack.channels]);
    };
    let st = p.clamped(dir);
    Ok(match filter {
        Filter::Nearest => {
            let n = stack.levels[0].width as f64;
            let (x, y) = (texel_of(st[0], n), texel_of(st[1], n));
            cube_texel(stack, 0, item, p.face, x, y).to_vec()
        }
        Filter::Linear => cube_bilinear(stack, item, 0, p.face, st),
        Filter::LinearMipmapNearest | Filter::LinearMipmapLinear => {
            let (_, l0, l1, f) = cube_mip_levels(stack, dir, level, filter);
            let a = cube_bilinear(stack, item, l0, p.face, st);
            if f == 0.0 && l0 == l1 {
                return Ok(a);
            }
            let b = cube_bilinear(stack, item, l1, p.face, st);
            a.iter().zip(&b).map(|(a, b)| a + f * (b - a)).collect()
        }
    })
}

/// One cube-map pixel's gradients to its own inputs (`texture`'s backward, besides the
/// texels').
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CubeGrad {
    /// To the direction.
    pub dir: [f64; 3],
    /// To `uv_da` (linear-mipmap-linear only), laid out as it.
    pub uv_da: [f64; 6],
    /// To `mip_level_bias` (linear-mipmap-linear only).
    pub bias: f64,
}

/// The backward of [`sample_cube`] for one pixel with output gradient `dy` (`C` values): adds
/// the texels' gradients into `tex_grad` (laid out as [`MipStack::zero_grads`]; carry them to
/// the base with [`MipStack::pyramid_backward`]) and returns the pixel's own. The exact
/// derivative of the forward, piecewise, the face held fixed: at a texel centre's kink, a face
/// edge and an integer `λ` the side taken is the forward's.
pub fn sample_cube_backward(
    stack: &MipStack,
    item: usize,
    dir: [f64; 3],
    level: CubeLevelInput,
    filter: Filter,
    dy: &[f64],
    tex_grad: &mut [Vec<f64>],
) -> Result<CubeGrad> {
    check_cube(stack, item)?;
    let shapes_match = tex_grad.len() == stack.levels.len()
        && tex_grad
            .iter()
            .zip(&stack.levels)
            .all(|(g, l)| g.len() == l.texels.len());
    if dy.len() != stack.channels || !shapes_match {
        return Err(Error::Input(format!(
            "texture: the cube backward takes dy of {} channels and tex_grad laid out as the \
             stack's {} levels, not {} channels and {} levels",
            stack.channels,
            stack.levels.len(),
            dy.len(),
            tex_grad.len()
        )));
    }
    let mut grad = CubeGrad::default();
    let Some(p) = Projection::of(dir) else {
        return Ok(grad);
    };
    let st = p.clamped(dir);
    let d_st = match filter {
        Filter::Nearest => {
            let n = stack.levels[0].width as f64;
            let o = cube_offset(
                stack,
                0,
                item,
                p.face,
                texel_of(st[0], n),
                texel_of(st[1], n),
            );
            for (g, d) in tex_grad[0][o..o + stack.channels].iter_mut().zip(dy) {
                *g += d;
            }
            return Ok(grad);
        }
        Filter::Linear => cube_bilinear_backward(stack, item, 0, p.face, st, dy, 1.0, tex_grad),
        Filter::LinearMipmapNearest | Filter::LinearMipmapLinear => {
            let (raw, l0, l1, f) = cube_mip_levels(stack, dir, level, filter);
            if f == 0.0 && l0 == l1 {
                cube_bilinear_backward(stack, item, l0, p.face, st, dy, 1.0, tex_grad)
            } else {
                let g0 = cube_bilinear_backward(stack, item, l0, p.face, st, dy, 1.0 - f, tex_grad);
                let g1 = cube_bilinear_backward(stack, item, l1, p.face, st, dy, f, tex_grad);
                // Through the fraction: d/dλ = Σ dy (b − a), where λ is not clamped.
                if raw > 0.0 && raw < stack.max_level() as f64 {
                    let a = cube_bilinear(stack, item, l0, p.face, st);
                    let b = cube_bilinear(stack, item, l1, p.face, st);
                    let dl: f64 = dy
                        .iter()
                        .zip(a.iter().zip(&b))
                        .map(|(d, (a, b))| d * (b - a))
                        .sum();
                    if level.bias.is_some() {
                        grad.bias = dl;
                    }
                    if let Some(da) = level.uv_da {
                        let lg = cube_level_gradient(dir, da, stack.levels[0].width);
                        grad.uv_da = lg.uv_da.map(|g| dl * g);
                        grad.dir = lg.dir.map(|g| dl * g);
                    }
                }
                [g0[0] + g1[0], g0[1] + g1[1]]
            }
        }
    };
    // Through the projection: (dL/ds, dL/dt) by the Jacobian, transposed.
    let [js, jt] = p.jacobian(dir);
    for i in 0..3 {
        grad.dir[i] += d_st[0] * js[i] + d_st[1] * jt[i];
    }
    Ok(grad)
}
