//! A cube-map lookup's mip level: `uv_da` carried onto the face through the projection's
//! Jacobian, the 2D level of that footprint, its gradient, and the levels the mipmap modes
//! blend.

use super::{Projection, dot, split};
use crate::raster::hard::texture::forward::pick_levels;
use crate::raster::hard::texture::{Filter, LevelInput, MipStack, level_gradient, level_of_detail};
/// What picks one cube-map pixel's mip level: `uv_da` (the direction's pixel derivatives,
/// `(dx/dX, dx/dY, dy/dX, dy/dY, dz/dX, dz/dY)`) and the bias.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CubeLevelInput {
    /// The pixel's direction derivatives, component by component.
    pub uv_da: Option<[f64; 6]>,
    /// The pixel's `mip_level_bias`.
    pub bias: Option<f64>,
}

/// The face coordinates' pixel derivatives `(ds/dX, ds/dY, dt/dX, dt/dY)` of a direction whose
/// own are `uv_da`, the face held fixed; zero where they are not finite (a direction with no
/// face).
pub fn cube_face_derivatives(dir: [f64; 3], uv_da: [f64; 6]) -> [f64; 4] {
    let Some(p) = Projection::of(dir) else {
        return [0.0; 4];
    };
    let [js, jt] = p.jacobian(dir);
    let (dx, dy) = split(uv_da);
    let w = [dot(js, dx), dot(js, dy), dot(jt, dx), dot(jt, dy)];
    if w.iter().all(|v| v.is_finite()) {
        w
    } else {
        [0.0; 4]
    }
}

/// The mip level `λ` (unclamped) of a cube map whose faces are `size × size` texels.
pub fn cube_level_of_detail(dir: [f64; 3], input: CubeLevelInput, size: usize) -> f64 {
    let uv_da = input.uv_da.map(|da| cube_face_derivatives(dir, da));
    level_of_detail(
        LevelInput {
            uv_da,
            bias: input.bias,
        },
        size,
        size,
    )
}

/// dλ/d`dir` and dλ/d`uv_da` of [`cube_level_of_detail`] (the bias's is 1).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CubeLevelGrad {
    /// To the direction (the Jacobian's dependence on it).
    pub dir: [f64; 3],
    /// To `uv_da`, laid out as it.
    pub uv_da: [f64; 6],
}

/// The level's gradients of [`cube_level_of_detail`], both zero where either is not finite
/// (an isotropic or empty footprint, a direction with no face), as nvdiffrast takes them.
pub fn cube_level_gradient(dir: [f64; 3], uv_da: [f64; 6], size: usize) -> CubeLevelGrad {
    let Some(p) = Projection::of(dir) else {
        return CubeLevelGrad::default();
    };
    let g = level_gradient(cube_face_derivatives(dir, uv_da), size, size);
    let [js, jt] = p.jacobian(dir);
    let [hs, ht] = p.hessians(dir);
    let (dx, dy) = split(uv_da);
    let mut grad = CubeLevelGrad::default();
    for i in 0..3 {
        grad.uv_da[2 * i] = g[0] * js[i] + g[2] * jt[i];
        grad.uv_da[2 * i + 1] = g[1] * js[i] + g[3] * jt[i];
        grad.dir[i] = g[0] * dot(hs[i], dx)
            + g[1] * dot(hs[i], dy)
            + g[2] * dot(ht[i], dx)
            + g[3] * dot(ht[i], dy);
    }
    if grad.dir.iter().chain(&grad.uv_da).all(|v| v.is_finite()) {
        grad
    } else {
        CubeLevelGrad::default()
    }
}

/// The mipmap modes' levels of a cube-map lookup: `(λ unclamped, ⌊λ⌋, ⌊λ⌋ + 1 within the
/// stack, λ's fraction)`, as 2D's.
pub(super) fn cube_mip_levels(
    stack: &MipStack,
    dir: [f64; 3],
    level: CubeLevelInput,
    filter: Filter,
) -> (f64, usize, usize, f64) {
    let raw = cube_level_of_detail(dir, level, stack.levels[0].width);
    let (l0, l1, f) = pick_levels(stack, raw, filter);
    (raw, l0, l1, f)
}
