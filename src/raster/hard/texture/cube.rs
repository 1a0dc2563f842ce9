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

use super::forward::pick_levels;
use super::{Filter, Level, LevelInput, MipStack, level_gradient, level_of_detail};
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
fn cube_mip_levels(
    stack: &MipStack,
    dir: [f64; 3],
    level: CubeLevelInput,
    filter: Filter,
) -> (f64, usize, usize, f64) {
    let raw = cube_level_of_detail(dir, level, stack.levels[0].width);
    let (l0, l1, f) = pick_levels(stack, raw, filter);
    (raw, l0, l1, f)
}

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

#[cfg(test)]
mod tests {
    use super::super::tests::{near_integer, stream};
    use super::super::{Boundary, Mode, sample};
    use super::*;

    /// A cube map of `cubes` cubes with `size × size` faces of `channels` random values in
    /// [0, 1), and its mip stack.
    fn random_cube(seed: u64, cubes: usize, size: usize, channels: usize) -> MipStack {
        let mut rnd = stream(seed);
        let texels = (0..cubes * 6 * size * size * channels)
            .map(|_| rnd())
            .collect();
        MipStack::cube(cubes, size, channels, texels)
            .unwrap()
            .build(None)
            .unwrap()
    }

    /// One face of cube 0 of `cube` as a 2D texture of its own, with its own mip stack.
    fn face_alone(cube: &MipStack, face: usize) -> MipStack {
        let (n, c) = (cube.levels[0].width, cube.channels);
        let o = face * n * n * c;
        MipStack::base(1, n, n, c, cube.levels[0].texels[o..o + n * n * c].to_vec())
            .unwrap()
            .build(None)
            .unwrap()
    }

    fn bias(bias: f64) -> CubeLevelInput {
        CubeLevelInput {
            uv_da: None,
            bias: Some(bias),
        }
    }

    #[test]
    fn cube_faces_follow_the_opengl_table() {
        assert_eq!(cube_face([1.0, 0.0, 0.0]), Some((0, 0.5, 0.5)));
        assert_eq!(cube_face([2.0, 1.0, -1.0]), Some((0, 0.75, 0.25)));
        assert_eq!(cube_face([-2.0, 1.0, -1.0]), Some((1, 0.25, 0.25)));
        assert_eq!(cube_face([0.5, 2.0, 1.0]), Some((2, 0.625, 0.75)));
        assert_eq!(cube_face([0.5, -2.0, 1.0]), Some((3, 0.625, 0.25)));
        assert_eq!(cube_face([0.5, 1.0, 2.0]), Some((4, 0.625, 0.25)));
        assert_eq!(cube_face([0.5, 1.0, -2.0]), Some((5, 0.375, 0.25)));
        assert_eq!(cube_face([0.0; 3]), None);
        assert_eq!(cube_face([f64::NAN, 1.0, 0.0]), None);
        // Ties go to x, then y; a zero major component's sign is positive.
        assert_eq!(cube_face([1.0, 1.0, 1.0]).unwrap().0, 0);
        assert_eq!(cube_face([-1.0, 0.5, 1.0]).unwrap().0, 1);
        assert_eq!(cube_face([0.5, -1.0, 1.0]).unwrap().0, 3);
        // cube_direction inverts it on every face.
        for face in 0..6 {
            let (f, s, t) = cube_face(cube_direction(face, 0.3, 0.8)).unwrap();
            assert_eq!(f, face);
            assert!(
                (s - 0.3).abs() < 1e-15 && (t - 0.8).abs() < 1e-15,
                "{face}: {s} {t}"
            );
        }
    }

    /// `texture_construct_mip(cube_mode=True)`: each face of each cube halved on its own, and
    /// the pyramid's backward carries a level's gradient into its own face's texels only.
    #[test]
    fn the_cube_mip_stack_halves_each_face_apart() {
        let (n, c) = (4usize, 2usize);
        let texels: Vec<f64> = (0..2 * 6 * n * n * c)
            .map(|i| f64::from(i as u32))
            .collect();
        let two = MipStack::cube(2, n, c, texels.clone())
            .unwrap()
            .build(None)
            .unwrap();
        assert_eq!(two.max_level(), 2);
        for item in 0..12 {
            let o = item * n * n * c;
            let alone = MipStack::base(1, n, n, c, texels[o..o + n * n * c].to_vec())
                .unwrap()
                .build(None)
                .unwrap();
            for level in 1..=2 {
                let m = n >> level;
                let p = item * m * m * c;
                assert_eq!(
                    two.levels[level].texels[p..p + m * m * c],
                    alone.levels[level].texels[..],
                    "item {item} level {level}"
                );
            }
            // The last level is each face's mean, channel by channel.
            for k in 0..c {
                let mean = (0..n * n).map(|i| texels[o + i * c + k]).sum::<f64>() / 16.0;
                assert_eq!(two.levels[2].texels[item * c + k], mean);
            }
        }
        // A unit gradient on the 1 × 1 level of cube 1's face −y, channel 1, goes to that
        // face's sixteen texels alone, a sixteenth each.
        let mut grads = two.zero_grads();
        let item = 6 + 3;
        grads[2][item * c + 1] = 1.0;
        let base = two.pyramid_backward(grads);
        for (i, g) in base.iter().enumerate() {
            let inside = i / (n * n * c) == item && i % c == 1;
            assert_eq!(*g, if inside { 1.0 / 16.0 } else { 0.0 }, "texel value {i}");
        }
        // Faces whose size cannot halve down, and a wrong count of values, are errors.
        let odd = MipStack::cube(1, 6, 1, vec![0.0; 6 * 36]).unwrap();
        assert!(odd.clone().build(Some(1)).is_ok());
        assert!(odd.build(None).is_err());
        assert!(MipStack::cube(1, 4, 1, vec![0.0; 16]).is_err());
        assert!(MipStack::cube(0, 4, 1, vec![]).is_err());
    }

    /// λ by hand: a face's coordinates move by `±1/(2|m|)` with a minor component and by
    /// `−(s − ½)/m` with the major one `m`, in texels of the base face.
    #[test]
    fn the_cube_level_is_the_footprint_on_the_face_in_its_texels() {
        let at = |dir: [f64; 3], uv_da: [f64; 6], bias: Option<f64>| {
            let input = CubeLevelInput {
                uv_da: Some(uv_da),
                bias,
            };
            cube_level_of_detail(dir, input, 16)
        };
        // Straight at +z's centre, the direction moving 0.5 along x a pixel across and 0.125
        // along y a pixel down: s moves ¼ (4 texels), t ⅛ · ½ (1 texel): λ = log2 4 = 2.
        let da = [0.5, 0.0, 0.0, 0.125, 0.0, 0.0];
        assert_eq!(at([0.0, 0.0, 1.0], da, None), 2.0);
        // Three times as long a direction, the same derivatives: a third of the footprint.
        let l = at([0.0, 0.0, 3.0], da, None);
        assert!((l - (4.0f64 / 3.0).log2()).abs() < 1e-14, "{l}");
        // X and Y swapped (the layout interleaves them per component): the same level.
        assert_eq!(
            at([0.0, 0.0, 1.0], [0.0, 0.5, 0.125, 0.0, 0.0, 0.0], None),
            2.0
        );
        // Along the major axis at the centre, s and t stand still: λ = −∞ (level 0).
        assert_eq!(
            at([0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0, 1.0, 1.0], None),
            f64::NEG_INFINITY
        );
        // Off the centre the major component moves s: at (0.5, 0, 1), ds/dz = −¼, 4 texels.
        assert_eq!(
            at([0.5, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0], None),
            2.0
        );
        // On −x, s = z/(2|x|) + ½: dz/dX = 1 at x = −2 moves s by ¼; the bias adds.
        assert_eq!(
            at([-2.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0, 0.0], Some(0.5)),
            2.5
        );
        // The face derivatives themselves: ds/dX = ½ · 1 − ¼ · 1, dt/dY = −½ · 2.
        assert_eq!(
            cube_face_derivatives([0.5, 0.0, 1.0], [1.0, 0.0, 0.0, 2.0, 1.0, 0.0]),
            [0.25, 0.0, 0.0, -1.0]
        );
        // No face, no footprint.
        assert_eq!(cube_face_derivatives([0.0; 3], [1.0; 6]), [0.0; 4]);
    }

    /// The level's gradients are zero where the footprint on the face is isotropic (0/0), and
    /// for a direction with no face, as nvdiffrast's.
    #[test]
    fn an_isotropic_cube_footprint_gives_the_level_no_gradient() {
        let zero = CubeLevelGrad::default();
        let round = [0.5, 0.0, 0.0, 0.5, 0.0, 0.0];
        assert_eq!(cube_level_gradient([0.0, 0.0, 1.0], round, 16), zero);
        assert_eq!(cube_level_gradient([0.0; 3], [0.5; 6], 16), zero);
        let long = [0.5, 0.0, 0.0, 0.25, 0.0, 0.0];
        let g = cube_level_gradient([0.2, 0.1, 1.0], long, 16);
        assert!(g.uv_da.iter().any(|g| *g != 0.0) && g.dir.iter().any(|g| *g != 0.0));
    }

    /// In a face's interior, where no tap leaves the face, every mode reads the levels the
    /// level picks as 2D sampling of that face alone does (an oracle that knows nothing of
    /// cubes), by the bias and by `uv_da` alike.
    #[test]
    fn cube_mipmap_modes_read_the_levels_the_level_picks() {
        let cube = random_cube(5, 1, 8, 3);
        // s = 0.4, t = 0.6 on +y: inside the face's taps down to level 2 (2 × 2).
        let (face, st) = (2, [0.4, 0.6]);
        let dir = cube_direction(face, st[0], st[1]).map(|x| 1.7 * x);
        let alone = face_alone(&cube, face);
        let flat = |filter: Filter, level: LevelInput| {
            let mode = Mode {
                filter,
                boundary: Boundary::Clamp,
            };
            sample(&alone, 0, st, level, mode)
        };
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-12);
        let da = [1.24, -0.48, 0.2, 1.6, 0.88, -0.28];
        for filter in [Filter::LinearMipmapNearest, Filter::LinearMipmapLinear] {
            for b in [-3.0, 0.0, 0.4, 1.0, 1.5, 1.99] {
                let got = sample_cube(&cube, 0, dir, bias(b), filter).unwrap();
                let want = flat(
                    filter,
                    LevelInput {
                        uv_da: None,
                        bias: Some(b),
                    },
                );
                assert!(close(&got, &want), "{filter:?} bias {b}: {got:?} {want:?}");
            }
            // By uv_da: the face derivatives as the 2D uv_da give the same λ and sample.
            let level = CubeLevelInput {
                uv_da: Some(da),
                bias: Some(-0.3),
            };
            let lambda = cube_level_of_detail(dir, level, 8);
            assert!(lambda > 0.5 && lambda < 1.9, "{lambda}");
            let flat_level = LevelInput {
                uv_da: Some(cube_face_derivatives(dir, da)),
                bias: Some(-0.3),
            };
            assert_eq!(super::super::level_of_detail(flat_level, 8, 8), lambda);
            let got = sample_cube(&cube, 0, dir, level, filter).unwrap();
            assert!(close(&got, &flat(filter, flat_level)), "{filter:?} uv_da");
        }
        // Linear is level 0; a NaN level is level 0; past the last level is the last level.
        let linear = sample_cube(&cube, 0, dir, bias(2.0), Filter::Linear).unwrap();
        assert!(close(&linear, &flat(Filter::Linear, LevelInput::default())));
        let nan = sample_cube(&cube, 0, dir, bias(f64::NAN), Filter::LinearMipmapLinear);
        assert_eq!(nan.unwrap(), linear);
        let past = sample_cube(&cube, 0, dir, bias(7.0), Filter::LinearMipmapLinear);
        let last = sample_cube(&cube, 0, dir, bias(3.0), Filter::LinearMipmapNearest);
        assert_eq!(past.unwrap(), last.unwrap());
    }

    /// Near +z's corner with +y and −x (n = 4, s = 0.05, t = 0.1), the tap up and left is
    /// beyond the corner: it reads the mean of the other three, +y's texel (0, 3) above,
    /// −x's (3, 0) to the left and +z's own (0, 0), and its weight goes a third to each.
    #[test]
    fn a_tap_beyond_a_corner_reads_the_mean_of_the_other_three() {
        let (n, c) = (4usize, 2usize);
        let cube = random_cube(9, 1, n, c);
        let texel = |face: usize, x: usize, y: usize| -> Vec<f64> {
            let o = ((face * n + y) * n + x) * c;
            cube.levels[0].texels[o..o + c].to_vec()
        };
        let dir = cube_direction(4, 0.05, 0.1).map(|x| 0.6 * x);
        // u = 0.2 − 0.5 and v = 0.4 − 0.5: fractions 0.7 and 0.9 from the taps at −1.
        let (fs, ft) = (0.7, 0.9);
        let (a10, a01, a11) = (texel(2, 0, 3), texel(1, 3, 0), texel(4, 0, 0));
        let got = sample_cube(&cube, 0, dir, CubeLevelInput::default(), Filter::Linear).unwrap();
        for k in 0..c {
            let a00 = (a10[k] + a01[k] + a11[k]) / 3.0;
            let top = a00 + fs * (a10[k] - a00);
            let bottom = a01[k] + fs * (a11[k] - a01[k]);
            let want = top + ft * (bottom - top);
            assert!(
                (got[k] - want).abs() < 1e-14,
                "channel {k}: {} {want}",
                got[k]
            );
        }
        let mut tex_grad = cube.zero_grads();
        let dy = [1.0, 0.0];
        let level = CubeLevelInput::default();
        sample_cube_backward(&cube, 0, dir, level, Filter::Linear, &dy, &mut tex_grad).unwrap();
        let w00 = (1.0 - fs) * (1.0 - ft);
        let expect = [
            ((2, 0, 3), fs * (1.0 - ft) + w00 / 3.0),
            ((1, 3, 0), (1.0 - fs) * ft + w00 / 3.0),
            ((4, 0, 0), fs * ft + w00 / 3.0),
        ];
        let mut total = 0.0;
        for (i, g) in tex_grad[0].iter().enumerate() {
            let (face, y, x, k) = (i / (n * n * c), i / (n * c) % n, i / c % n, i % c);
            let want = expect
                .iter()
                .find(|(at, _)| *at == (face, x, y) && k == 0)
                .map_or(0.0, |(_, w)| *w);
            assert!(
                (g - want).abs() < 1e-14,
                "face {face} ({x}, {y}) channel {k}: {g}"
            );
            total += g;
        }
        assert!((total - 1.0).abs() < 1e-14);
    }

    /// A direction sweeping across each of the cube's twelve edges (from both faces, at the
    /// edge's middle and near both its corners) gives a continuous sample on every level and
    /// between levels: no step between neighbouring directions larger than the level's own
    /// slope allows, where sampling each face on its own (clamped at its edge, on the same
    /// level) jumps.
    #[test]
    fn a_cube_map_has_no_seam_across_any_edge_on_any_level() {
        let (n, c) = (8usize, 2usize);
        let cube = random_cube(3, 1, n, c);
        let faces: Vec<MipStack> = (0..6).map(|f| face_alone(&cube, f)).collect();
        let steps = 400;
        let settings = [
            (Filter::Linear, 0.0),
            (Filter::LinearMipmapNearest, 1.0),
            (Filter::LinearMipmapNearest, 2.0),
            (Filter::LinearMipmapNearest, 3.0),
            (Filter::LinearMipmapLinear, 0.5),
            (Filter::LinearMipmapLinear, 1.5),
            (Filter::LinearMipmapLinear, 2.5),
        ];
        for (filter, b) in settings {
            // One step moves the lookup by at most 0.4 / steps of a face, s and t together by
            // twice that past an edge near a corner, and texels differ by less than 1.
            let finest = (n >> b as usize) as f64;
            let bound = 2.0 * 0.4 * finest / steps as f64;
            let (mut crossings, mut seams, mut steepest) = (0, 0, 0.0f64);
            for face in 0..6 {
                for across in [0, 1] {
                    for sign in [1.0, -1.0] {
                        for along in [0.3, 0.03, 0.97] {
                            // From 0.8 to 1.2 (or 0.2 to −0.2) across the edge, continued on
                            // the face's plane.
                            let at = |k: usize| {
                                let x = 0.4 * (k as f64 / steps as f64) - 0.2;
                                let out = 0.5 + sign * (0.5 + x);
                                let (s, t) = if across == 0 {
                                    (out, along)
                                } else {
                                    (along, out)
                                };
                                cube_direction(face, s, t)
                            };
                            let per_face = |dir: [f64; 3]| {
                                let (f, s, t) = cube_face(dir).unwrap();
                                let mode = Mode {
                                    filter,
                                    boundary: Boundary::Clamp,
                                };
                                let level = LevelInput {
                                    uv_da: None,
                                    bias: Some(b),
                                };
                                sample(&faces[f], 0, [s, t], level, mode)
                            };
                            let (mut worst, mut worst_face) = (0.0f64, 0.0f64);
                            for k in 0..steps {
                                let (da, db) = (at(k), at(k + 1));
                                let va = sample_cube(&cube, 0, da, bias(b), filter).unwrap();
                                let vb = sample_cube(&cube, 0, db, bias(b), filter).unwrap();
                                let (pa, pb) = (per_face(da), per_face(db));
                                for k in 0..c {
                                    worst = worst.max((va[k] - vb[k]).abs());
                                    worst_face = worst_face.max((pa[k] - pb[k]).abs());
                                }
                            }
                            assert!(
                                worst <= bound,
                                "{filter:?} bias {b} face {face} across {across} sign \
                                 {sign} along {along}: step {worst} > {bound}"
                            );
                            crossings += 1;
                            steepest = steepest.max(worst);
                            // Twice the steepest step a continuous sample can take: a jump.
                            if worst_face > 2.0 * bound {
                                seams += 1;
                            }
                        }
                    }
                }
            }
            eprintln!(
                "{filter:?} bias {b}: {seams} of {crossings} crossings seams per face; the \
                 cube's steepest step {steepest} of {bound}"
            );
            assert!(
                seams * 10 >= crossings * 9,
                "{filter:?} bias {b}: per-face sampling shows only {seams} of {crossings} \
                 crossings as seams"
            );
        }
    }

    /// Every gradient of one pixel (to the base texels through the pyramid, the direction,
    /// `uv_da` and the bias) against central differences of the forward, per component, in
    /// every filter mode, at directions in face interiors, near edges and near corners (on
    /// either side), away from the kinks (counted: the draws skipped), each error within a
    /// measured floor.
    #[test]
    fn the_cube_backward_matches_central_differences_at_interiors_edges_and_corners() {
        let mut rnd = stream(11);
        let (n, c) = (8usize, 2usize);
        let base: Vec<f64> = (0..6 * n * n * c).map(|_| rnd()).collect();
        let stack_of = |texels: Vec<f64>, filter: Filter| {
            let s = MipStack::cube(1, n, c, texels).unwrap();
            if filter.uses_mips() {
                s.build(None).unwrap()
            } else {
                s
            }
        };
        let eps = 1e-6;
        // The floor measured at eps = 1e-6: the worst error of any component is about 1e-10
        // (rounding, ~1e-16 / eps), so 1e-8 leaves a hundredfold; a wrong term in a
        // derivative errs by the order of the gradient itself (0.01 to 10).
        let floor = 1e-8;
        let mut worst = [0.0f64; 4];
        let (mut checked, mut skipped, mut edges, mut corners) = (0, 0, 0, 0);
        for filter in [
            Filter::Nearest,
            Filter::Linear,
            Filter::LinearMipmapNearest,
            Filter::LinearMipmapLinear,
        ] {
            let stack = stack_of(base.clone(), filter);
            for draw in 0..36 {
                // Within [−0.03, 0.06] of an edge, on either side of it.
                let near = |r: f64| {
                    if r < 0.5 {
                        r * 0.18 - 0.03
                    } else {
                        1.03 - (r - 0.5) * 0.18
                    }
                };
                let face = ((rnd() * 6.0) as usize).min(5);
                let free = 0.1 + 0.8 * rnd();
                let (s, t) = match draw % 3 {
                    0 => (free, 0.1 + 0.8 * rnd()),
                    1 if rnd() < 0.5 => (near(rnd()), free),
                    1 => (free, near(rnd())),
                    _ => (near(rnd()), near(rnd())),
                };
                let length = 0.5 + 1.5 * rnd();
                let dir = cube_direction(face, s, t).map(|x| length * x);
                let da: [f64; 6] = std::array::from_fn(|_| (rnd() - 0.5) * 2.0 * length);
                let level = CubeLevelInput {
                    uv_da: Some(da),
                    bias: Some(rnd() - 0.5),
                };
                let dy: Vec<f64> = (0..c).map(|_| rnd() - 0.5).collect();
                // The kinks: texel centres and edges on every level (a face's edge among
                // them), integer λ (the clamp's ends among them), an isotropic footprint.
                let p = Projection::of(dir).unwrap();
                let st = p.clamped(dir);
                let lambda = cube_level_of_detail(dir, level, n);
                let [sx, sy, tx, ty] = cube_face_derivatives(dir, da).map(|d| d * n as f64);
                let (a, b, cc) = (sx * sx + tx * tx, sy * sy + ty * ty, sx * sy + tx * ty);
                let round = (0.25 * (a - b) * (a - b) + cc * cc).sqrt() < 1e-3 * (a + b);
                let kinked = stack.levels.iter().any(|l| {
                    let m = l.width as f64;
                    st.iter()
                        .any(|x| near_integer(x * m - 0.5, 1e-3) || near_integer(x * m, 1e-3))
                }) || (filter.uses_mips() && (near_integer(lambda, 1e-3) || round));
                if kinked {
                    skipped += 1;
                    continue;
                }
                // What the taps of the levels read did: another face, a corner.
                let used = match filter {
                    Filter::Nearest => vec![],
                    Filter::Linear => vec![0],
                    _ => {
                        let (_, l0, l1, _) = cube_mip_levels(&stack, dir, level, filter);
                        vec![l0, l1]
                    }
                };
                let taps: Vec<CubeTaps> = used
                    .iter()
                    .map(|&l| CubeTaps::new(&stack.levels[l], p.face, st))
                    .collect();
                if taps.iter().any(|t| t.corner().is_some()) {
                    corners += 1;
                }
                if taps
                    .iter()
                    .any(|t| t.texels.iter().flatten().any(|&(f, _, _)| f != p.face))
                {
                    edges += 1;
                }
                let loss = |stack: &MipStack, dir: [f64; 3], level: CubeLevelInput| -> f64 {
                    sample_cube(stack, 0, dir, level, filter)
                        .unwrap()
                        .iter()
                        .zip(&dy)
                        .map(|(a, b)| a * b)
                        .sum()
                };
                let mut tex_grad = stack.zero_grads();
                let g = sample_cube_backward(&stack, 0, dir, level, filter, &dy, &mut tex_grad)
                    .unwrap();
                let what = format!("{filter:?} dir {dir:?} (face {} at {st:?})", p.face);
                let mut check = |kind: usize, name: String, analytic: f64, numeric: f64| {
                    let e = (analytic - numeric).abs();
                    worst[kind] = worst[kind].max(e);
                    assert!(e <= floor, "{what}: {name} {analytic} numeric {numeric}");
                };
                for k in 0..3 {
                    let (mut a, mut b) = (dir, dir);
                    a[k] += eps;
                    b[k] -= eps;
                    let num = (loss(&stack, a, level) - loss(&stack, b, level)) / (2.0 * eps);
                    check(1, format!("d/ddir[{k}]"), g.dir[k], num);
                }
                for k in 0..6 {
                    let (mut a, mut b) = (level, level);
                    a.uv_da.as_mut().unwrap()[k] += eps;
                    b.uv_da.as_mut().unwrap()[k] -= eps;
                    let num = (loss(&stack, dir, a) - loss(&stack, dir, b)) / (2.0 * eps);
                    check(2, format!("d/duv_da[{k}]"), g.uv_da[k], num);
                }
                let (mut a, mut b) = (level, level);
                a.bias = a.bias.map(|x| x + eps);
                b.bias = b.bias.map(|x| x - eps);
                let num = (loss(&stack, dir, a) - loss(&stack, dir, b)) / (2.0 * eps);
                check(3, "d/dbias".into(), g.bias, num);
                // The base texels, through the pyramid (the stack rebuilt each time).
                let to_base = stack.pyramid_backward(tex_grad);
                for i in 0..base.len() {
                    let (mut a, mut b) = (base.clone(), base.clone());
                    a[i] += eps;
                    b[i] -= eps;
                    let num = (loss(&stack_of(a, filter), dir, level)
                        - loss(&stack_of(b, filter), dir, level))
                        / (2.0 * eps);
                    check(0, format!("d/dtex[{i}]"), to_base[i], num);
                }
                checked += 1;
            }
        }
        eprintln!(
            "{checked} checked, {skipped} skipped, {edges} across an edge, {corners} past a \
             corner; worst errors (tex, dir, uv_da, bias) {worst:?}"
        );
        assert!(
            checked >= 120 && skipped * 8 < checked && edges >= 40 && corners >= 15,
            "{checked} checked, {skipped} skipped, {edges} across an edge, {corners} past a corner"
        );
    }

    #[test]
    fn cube_lookups_refuse_what_is_not_a_cube_map_and_read_each_items_cube() {
        let level = CubeLevelInput::default();
        let flat = MipStack::base(6, 4, 2, 1, vec![0.0; 48]).unwrap();
        assert!(sample_cube(&flat, 0, [1.0, 0.0, 0.0], level, Filter::Linear).is_err());
        let five = MipStack::base(5, 2, 2, 1, vec![0.0; 20]).unwrap();
        assert!(sample_cube(&five, 0, [1.0, 0.0, 0.0], level, Filter::Nearest).is_err());
        let two = random_cube(1, 2, 2, 1);
        assert!(sample_cube(&two, 2, [1.0, 0.0, 0.0], level, Filter::Nearest).is_err());
        let mut tex_grad = two.zero_grads();
        let wrong_dy = sample_cube_backward(
            &two,
            0,
            [1.0, 0.0, 0.0],
            level,
            Filter::Linear,
            &[1.0, 1.0],
            &mut tex_grad,
        );
        assert!(wrong_dy.is_err());
        // Each item reads its own cube; one cube serves every item.
        let nearest = |stack: &MipStack, item: usize| {
            sample_cube(stack, item, [0.1, -0.2, -1.0], level, Filter::Nearest).unwrap()[0]
        };
        let o = (6 + 5) * 4;
        let y = ((0.5 + 0.2 / 2.0) * 2.0) as usize;
        let x = ((0.5 - 0.1 / 2.0) * 2.0) as usize;
        assert_eq!(nearest(&two, 1), two.levels[0].texels[o + y * 2 + x]);
        let one = random_cube(1, 1, 2, 1);
        assert_eq!(nearest(&one, 0), nearest(&one, 7));
        // A direction with no face reads zero and takes no gradient.
        let mut tex_grad = one.zero_grads();
        let g = sample_cube_backward(
            &one,
            0,
            [0.0; 3],
            level,
            Filter::Linear,
            &[1.0],
            &mut tex_grad,
        )
        .unwrap();
        assert_eq!(g, CubeGrad::default());
        assert!(tex_grad.iter().flatten().all(|g| *g == 0.0));
        assert_eq!(
            sample_cube(&one, 0, [0.0; 3], level, Filter::Linear).unwrap(),
            [0.0]
        );
    }
}
