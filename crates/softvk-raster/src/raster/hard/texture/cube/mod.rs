//! Cube maps: the f64 twin of nvdiffrast's `texture` with `boundary_mode='cube'`, forward
//! ([`sample_cube`]) and backward ([`sample_cube_backward`]), and of `texture_construct_mip`
//! with `cube_mode=True` ([`MipStack::cube`], then [`MipStack::build`]).
//!
//! nvdiffrast's behaviour, as its documentation and source show it (softvk's code is its own):
//!
//! - **Layout.** A cube map is `[B, 6, S, S, C]`, faces +x, −x, +y, −y, +z, −z, held here as a
//!   [`MipStack`] of `6 B` items (`B` 1: one cube shared by every minibatch item). `uv` is a
//!   direction, `[B, h, w, 3]`, of any length; `uv_da` is `[B, h, w, 6]`, the direction's
//!   pixel derivatives component by component:
//!   `(dx/dX, dx/dY, dy/dX, dy/dY, dz/dX, dz/dY)`.
//! - **The face** ([`cube_face`]). OpenGL's cube-map table: the component of largest magnitude
//!   and its sign pick the face, ties going to x, then y (z wins only when strictly larger than
//!   both, y only when strictly larger than x; a zero is positive). `s` and `t` are the other
//!   two components, signed by the table, over twice the major one's magnitude, plus ½, clamped
//!   to `[0, 1]`. A direction with no finite `(s, t)` (zero, or not finite) reads zero and takes
//!   no gradient.
//! - **Filters.** `nearest` reads texel `⌊s S⌋, ⌊t S⌋` (clamped) of the base level's face.
//!   `linear` blends the four texels around `(s S − ½, t S − ½)` seamlessly: a tap past the
//!   face's edge reads the neighbouring face's texel that shares that edge at the same place
//!   along it (the one the tap's centre, continued on the face's plane, projects into), and a
//!   tap past two edges at once, beyond a cube corner where no texel is, reads the mean of the
//!   other three taps. The mipmap modes blend the same way on the levels `λ` picks, by the 2D
//!   rules (`λ` clamped to `[0, the last level]`, NaN to 0; `linear-mipmap-nearest` on `⌊λ⌋`,
//!   `linear-mipmap-linear` also on `⌊λ⌋ + 1`, mixed by the fraction).
//! - **The level** ([`cube_level_of_detail`]). `uv_da` is carried onto the face through the
//!   projection's Jacobian, the face held fixed: `(ds/dX, ds/dY, dt/dX, dt/dY)`
//!   ([`cube_face_derivatives`]), where a minor component `a` moves `s` by `±1/(2|m|)` and the
//!   major one `m` moves it by `−(s − ½)/m`. `λ` is the 2D level of those four in a face of
//!   `S × S` texels (the base level's size), then the bias; a Jacobian that is not finite counts
//!   as zero (`λ = −∞`, which the clamp takes to level 0).
//! - **The mip stack.** Each face is halved as a 2D texture, apart from the others (the
//!   stack's items are the faces), so `S` must halve down to 1 or `max_mip_level` stop it.
//! - **The backward** ([`sample_cube_backward`]). Texels take the bilinear weights; a tap
//!   beyond a corner shares its weight, a third each, among the three texels its mean reads.
//!   The direction takes `(dL/ds, dL/dt)` through the Jacobian transposed (the face held
//!   fixed) and, in `linear-mipmap-linear` with `uv_da`, `dL/dλ` through `λ`'s own dependence
//!   on the direction (the Jacobian moves with it). `uv_da` takes `dL/dλ` times the 2D level's
//!   gradient carried back through the Jacobian; the bias takes `dL/dλ`. The level's gradients
//!   are zero where `λ` is clamped, and, to the direction and `uv_da` together, where they are
//!   not finite (an isotropic footprint: 0/0), as nvdiffrast takes them. `nearest` gives the
//!   texels their gradients only.
//!
//! nvdiffrast writes each face's Jacobian and its second derivatives out by hand (in f32, the
//! major component's reciprocal rounded toward zero); term by term they are the exact
//! derivatives this twin takes, so the twin's direction gradient is nvdiffrast's in real
//! arithmetic. They can part only at the kinks (a texel centre, a face edge, an integer `λ`),
//! where each takes the side its forward takes.

mod level;
mod sample;

#[cfg(test)]
mod tests;

pub use level::{
    CubeLevelGrad, CubeLevelInput, cube_face_derivatives, cube_level_gradient, cube_level_of_detail,
};
pub use sample::{CubeGrad, sample_cube, sample_cube_backward};

use super::{Level, MipStack};
use crate::error::{Error, Result};
/// OpenGL's cube-map table, faces +x, −x, +y, −y, +z, −z: each face's major axis, and the axis
/// and sign of the numerators of `s` and `t`.
const FACES: [(usize, [(usize, f64); 2]); 6] = [
    (0, [(2, -1.0), (1, -1.0)]),
    (0, [(2, 1.0), (1, -1.0)]),
    (1, [(0, 1.0), (2, 1.0)]),
    (1, [(0, 1.0), (2, -1.0)]),
    (2, [(0, 1.0), (1, -1.0)]),
    (2, [(0, -1.0), (1, -1.0)]),
];

/// A direction's face and the projection onto it: `s = ½ + sign · dir[axis] / (2 |dir[major]|)`,
/// and `t` likewise.
#[derive(Clone, Copy, Debug)]
struct Projection {
    face: usize,
    major: usize,
    /// The axes of the numerators of `s` and `t`.
    axes: [usize; 2],
    /// Their signs.
    signs: [f64; 2],
}

impl Projection {
    /// The face `dir` looks at; `None` where its coordinates are not finite.
    fn of(dir: [f64; 3]) -> Option<Self> {
        let [ax, ay, az] = dir.map(f64::abs);
        let major = if az > ax.max(ay) {
            2
        } else if ay > ax {
            1
        } else {
            0
        };
        let face = 2 * major + usize::from(dir[major] < 0.0);
        let numerators = FACES[face].1;
        let p = Self {
            face,
            major,
            axes: numerators.map(|(axis, _)| axis),
            signs: numerators.map(|(_, sign)| sign),
        };
        let [s, t] = p.coords(dir);
        (s.is_finite() && t.is_finite()).then_some(p)
    }

    /// `(s, t)`, not clamped.
    fn coords(&self, dir: [f64; 3]) -> [f64; 2] {
        let m = dir[self.major].abs();
        [0, 1].map(|j| self.signs[j] * dir[self.axes[j]] / (2.0 * m) + 0.5)
    }

    /// `(s, t)` clamped to the face, as the lookups read them.
    fn clamped(&self, dir: [f64; 3]) -> [f64; 2] {
        self.coords(dir).map(|x| x.clamp(0.0, 1.0))
    }

    /// `s = ½ + k a / m` for `s` (`j = 0`) or `t`: `(k, a's axis)`.
    fn factor(&self, j: usize, dir: [f64; 3]) -> (f64, usize) {
        (0.5 * self.signs[j] * dir[self.major].signum(), self.axes[j])
    }

    /// `∂s/∂dir` and `∂t/∂dir`, the face held fixed.
    fn jacobian(&self, dir: [f64; 3]) -> [[f64; 3]; 2] {
        let m = dir[self.major];
        [0, 1].map(|j| {
            let (k, a) = self.factor(j, dir);
            let mut g = [0.0; 3];
            g[a] = k / m;
            g[self.major] = -k * dir[a] / (m * m);
            g
        })
    }

    /// The second derivatives of `s` and `t` in the direction, the face held fixed.
    fn hessians(&self, dir: [f64; 3]) -> [[[f64; 3]; 3]; 2] {
        let m = dir[self.major];
        [0, 1].map(|j| {
            let (k, a) = self.factor(j, dir);
            let mut h = [[0.0; 3]; 3];
            h[a][self.major] = -k / (m * m);
            h[self.major][a] = -k / (m * m);
            h[self.major][self.major] = 2.0 * k * dir[a] / (m * m * m);
            h
        })
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `uv_da`'s two derivatives, `(d dir/dX, d dir/dY)`.
fn split(uv_da: [f64; 6]) -> ([f64; 3], [f64; 3]) {
    (
        [uv_da[0], uv_da[2], uv_da[4]],
        [uv_da[1], uv_da[3], uv_da[5]],
    )
}

/// The cube-map face a direction looks at and its face coordinates `(s, t)` in `[0, 1]`, by
/// OpenGL's cube-map table (faces +x, −x, +y, −y, +z, −z; ties go to x, then y, as
/// nvdiffrast's `indexCubeMap` breaks them); `None` for a direction with no finite face
/// coordinates (zero, or not finite).
pub fn cube_face(dir: [f64; 3]) -> Option<(usize, f64, f64)> {
    let p = Projection::of(dir)?;
    let [s, t] = p.clamped(dir);
    Some((p.face, s, t))
}

/// The direction of face coordinates `(s, t)` on `face` (the point on the unit cube's face
/// plane; `(s, t)` may lie outside `[0, 1]`, continuing the plane): `cube_face`'s inverse.
pub fn cube_direction(face: usize, s: f64, t: f64) -> [f64; 3] {
    let (a, b) = (2.0 * s - 1.0, 2.0 * t - 1.0);
    match face {
        0 => [1.0, -b, -a],
        1 => [-1.0, -b, a],
        2 => [a, 1.0, b],
        3 => [a, -1.0, -b],
        4 => [a, -b, 1.0],
        _ => [-a, -b, -1.0],
    }
}

impl MipStack {
    /// A cube map's base level: `cubes` cubes of six `size × size` faces (+x, −x, +y, −y, +z,
    /// −z), `[cubes, 6, size, size, channels]` row-major; [`MipStack::build`] then halves each
    /// face apart, as nvdiffrast's `texture_construct_mip(tex, max_mip_level, cube_mode=True)`.
    pub fn cube(cubes: usize, size: usize, channels: usize, texels: Vec<f64>) -> Result<Self> {
        if cubes == 0 {
            return Err(Error::Input(
                "texture: a cube map [B, 6, S, S, C] needs B > 0".into(),
            ));
        }
        Self::base(6 * cubes, size, size, channels, texels)
    }
}

/// Whether `stack` is a cube map that holds minibatch item `item`.
fn check_cube(stack: &MipStack, item: usize) -> Result<()> {
    let l = &stack.levels[0];
    if l.width != l.height || stack.items % 6 != 0 {
        return Err(Error::Input(format!(
            "texture: a cube map is [B, 6, S, S, C]; this one has {} faces of {}x{}",
            stack.items, l.height, l.width
        )));
    }
    let cubes = stack.items / 6;
    if cubes > 1 && item >= cubes {
        return Err(Error::Input(format!(
            "texture: minibatch item {item} of a cube map of {cubes} cubes"
        )));
    }
    Ok(())
}

/// Where texel `(x, y)` of `face` of item `item`'s cube on `level` starts.
fn cube_offset(
    stack: &MipStack,
    level: usize,
    item: usize,
    face: usize,
    x: usize,
    y: usize,
) -> usize {
    let l = &stack.levels[level];
    let cube = if stack.items == 6 { 0 } else { item };
    (((cube * 6 + face) * l.height + y) * l.width + x) * stack.channels
}

/// Texel `(x, y)` of `face` of item `item`'s cube on `level`.
fn cube_texel(
    stack: &MipStack,
    level: usize,
    item: usize,
    face: usize,
    x: usize,
    y: usize,
) -> &[f64] {
    let o = cube_offset(stack, level, item, face, x, y);
    &stack.levels[level].texels[o..o + stack.channels]
}

/// The texel a face coordinate falls in, on a face `n` texels across.
fn texel_of(x: f64, n: f64) -> usize {
    (x * n).floor().clamp(0.0, n - 1.0) as usize
}

/// The four taps of seamless bilinear filtering on one level, around `(s n − ½, t n − ½)`.
struct CubeTaps {
    /// `(face, x, y)` of the taps `00, 10, 01, 11`; `None`: beyond a cube corner (at most one).
    texels: [Option<(usize, usize, usize)>; 4],
    /// The weights' fractions along `s` and `t`.
    frac: [f64; 2],
    /// Texels across a face of the level: `du/ds`.
    size: f64,
}

impl CubeTaps {
    fn new(level: &Level, face: usize, st: [f64; 2]) -> Self {
        let n = level.width as f64;
        let (u, v) = (st[0] * n - 0.5, st[1] * n - 0.5);
        let (u0, v0) = (u.floor(), v.floor());
        let inside = |i: f64| (0.0..n).contains(&i);
        let tap = |x: f64, y: f64| match (inside(x), inside(y)) {
            (true, true) => Some((face, x as usize, y as usize)),
            (false, false) => None,
            _ => {
                // Past one edge: the tap's centre on this face's plane, looked up again.
                let d = cube_direction(face, (x + 0.5) / n, (y + 0.5) / n);
                let (f, s, t) = cube_face(d).expect("a point of a face plane has a face");
                Some((f, texel_of(s, n), texel_of(t, n)))
            }
        };
        Self {
            texels: [
                tap(u0, v0),
                tap(u0 + 1.0, v0),
                tap(u0, v0 + 1.0),
                tap(u0 + 1.0, v0 + 1.0),
            ],
            frac: [u - u0, v - v0],
            size: n,
        }
    }

    /// The corner tap's index, if one is beyond a corner.
    fn corner(&self) -> Option<usize> {
        self.texels.iter().position(Option::is_none)
    }

    /// Channel `k` of the four taps, the corner's the mean of the other three.
    fn values(&self, stack: &MipStack, level: usize, item: usize, k: usize) -> [f64; 4] {
        let mut v = self
            .texels
            .map(|t| t.map_or(0.0, |(f, x, y)| cube_texel(stack, level, item, f, x, y)[k]));
        if let Some(i) = self.corner() {
            v[i] = (v.iter().sum::<f64>()) / 3.0;
        }
        v
    }

    /// Each texel's share of the sample: the bilinear weights, the corner's shared a third
    /// each among the three its mean reads.
    fn weights(&self) -> [f64; 4] {
        let [fs, ft] = self.frac;
        let mut w = [
            (1.0 - fs) * (1.0 - ft),
            fs * (1.0 - ft),
            (1.0 - fs) * ft,
            fs * ft,
        ];
        if let Some(i) = self.corner() {
            let share = w[i] / 3.0;
            w[i] = 0.0;
            for (j, w) in w.iter_mut().enumerate() {
                if j != i {
                    *w += share;
                }
            }
        }
        w
    }
}

/// Seamless bilinear filtering of `face` at `st` on `level`.
fn cube_bilinear(
    stack: &MipStack,
    item: usize,
    level: usize,
    face: usize,
    st: [f64; 2],
) -> Vec<f64> {
    let taps = CubeTaps::new(&stack.levels[level], face, st);
    let [fs, ft] = taps.frac;
    (0..stack.channels)
        .map(|k| {
            let [a00, a10, a01, a11] = taps.values(stack, level, item, k);
            let top = a00 + fs * (a10 - a00);
            let bottom = a01 + fs * (a11 - a01);
            top + ft * (bottom - top)
        })
        .collect()
}

/// The backward of [`cube_bilinear`] scaled by `scale`: texel gradients into `tex_grad`, and
/// the gradient to `(s, t)` returned.
#[allow(clippy::too_many_arguments)]
fn cube_bilinear_backward(
    stack: &MipStack,
    item: usize,
    level: usize,
    face: usize,
    st: [f64; 2],
    dy: &[f64],
    scale: f64,
    tex_grad: &mut [Vec<f64>],
) -> [f64; 2] {
    let taps = CubeTaps::new(&stack.levels[level], face, st);
    let [fs, ft] = taps.frac;
    let (mut dfs, mut dft) = (0.0, 0.0);
    for (k, d) in dy.iter().enumerate() {
        let [a00, a10, a01, a11] = taps.values(stack, level, item, k);
        dfs += d * ((a10 - a00) * (1.0 - ft) + (a11 - a01) * ft);
        dft += d * ((a01 + fs * (a11 - a01)) - (a00 + fs * (a10 - a00)));
    }
    let c = stack.channels;
    for (tap, weight) in taps.texels.iter().zip(taps.weights()) {
        if let Some((f, x, y)) = *tap {
            let o = cube_offset(stack, level, item, f, x, y);
            for (g, d) in tex_grad[level][o..o + c].iter_mut().zip(dy) {
                *g += scale * weight * d;
            }
        }
    }
    [scale * dfs * taps.size, scale * dft * taps.size]
}
