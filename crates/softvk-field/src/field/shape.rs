//! Analytic shapes for tests: a field `f(p) = −sharpness · sd(p)` with `sd` the signed distance
//! (negative inside) of a sphere, a box or a torus, so that φ = 0.5 exactly on the surface.
//!
//! The shape's numbers are the field's parameters (so a fit can move them, and the probing
//! losses can be checked on a field with four parameters):
//!
//! | shape  | parameters                         | sd                                                 |
//! |--------|------------------------------------|----------------------------------------------------|
//! | sphere | `cx cy cz r`                       | `|p − c| − r`                                      |
//! | box    | `cx cy cz hx hy hz` (half extents) | `d = |p − c| − h`: `|max(d, 0)| + min(max_i d_i, 0)` |
//! | torus  | `cx cy cz R r` (axis y)            | `|(|(p − c).xz| − R, (p − c).y)| − r`              |
//!
//! Twin of `kernels/softvk/include/field_shape.glsl`, in f64; [`Shape::sd_and_grad`] also gives ∂sd/∂θ.

/// An analytic shape and its initial parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// A ball.
    Sphere {
        /// Centre.
        center: [f64; 3],
        /// Radius.
        radius: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Centre.
        center: [f64; 3],
        /// Half extents along x, y, z.
        half_extents: [f64; 3],
    },
    /// A torus around the y axis through `center`.
    Torus {
        /// Centre.
        center: [f64; 3],
        /// Distance from the axis to the tube's centre line.
        major: f64,
        /// Tube radius.
        minor: f64,
    },
}

/// The most parameters a shape has (the box's six).
pub const MAX_SHAPE_PARAMS: usize = 6;

impl Shape {
    /// The kernel's shape code (`kind` in `field_shape.glsl`).
    pub(crate) fn code(&self) -> u32 {
        match self {
            Shape::Sphere { .. } => 0,
            Shape::Box { .. } => 1,
            Shape::Torus { .. } => 2,
        }
    }

    /// Number of parameters: 4, 6 or 5.
    pub fn param_count(&self) -> usize {
        match self {
            Shape::Sphere { .. } => 4,
            Shape::Box { .. } => 6,
            Shape::Torus { .. } => 5,
        }
    }

    /// The parameters, in the order of the table above.
    pub fn params(&self) -> Vec<f64> {
        match *self {
            Shape::Sphere { center, radius } => vec![center[0], center[1], center[2], radius],
            Shape::Box {
                center,
                half_extents: h,
            } => vec![center[0], center[1], center[2], h[0], h[1], h[2]],
            Shape::Torus {
                center,
                major,
                minor,
            } => vec![center[0], center[1], center[2], major, minor],
        }
    }

    /// The same kind of shape with the numbers `params` (as many as [`Shape::param_count`]).
    pub fn with_params(&self, params: &[f64]) -> Shape {
        let c = [params[0], params[1], params[2]];
        match self {
            Shape::Sphere { .. } => Shape::Sphere {
                center: c,
                radius: params[3],
            },
            Shape::Box { .. } => Shape::Box {
                center: c,
                half_extents: [params[3], params[4], params[5]],
            },
            Shape::Torus { .. } => Shape::Torus {
                center: c,
                major: params[3],
                minor: params[4],
            },
        }
    }

    /// Exact volume enclosed by the surface.
    pub fn volume(&self) -> f64 {
        use std::f64::consts::PI;
        match *self {
            Shape::Sphere { radius, .. } => 4.0 / 3.0 * PI * radius.powi(3),
            Shape::Box {
                half_extents: h, ..
            } => 8.0 * h[0] * h[1] * h[2],
            Shape::Torus { major, minor, .. } => 2.0 * PI * PI * major * minor * minor,
        }
    }

    /// Signed distance at `p` (negative inside).
    pub fn sd(&self, p: [f64; 3]) -> f64 {
        sd_and_grad(self.code(), &self.params(), p).0
    }

    /// Signed distance at `p` and its derivatives by the parameters (unused entries 0).
    pub fn sd_and_grad(&self, p: [f64; 3]) -> (f64, [f64; MAX_SHAPE_PARAMS]) {
        sd_and_grad(self.code(), &self.params(), p)
    }
}

/// `x / y`, or 0 where `y` is 0 (a distance's gradient where it has none), as the kernel.
fn ratio(x: f64, y: f64) -> f64 {
    if y > 0.0 { x / y } else { 0.0 }
}

/// GLSL's `sign`: 0 at 0 (`f64::signum` gives ±1 there).
fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// Signed distance of shape `code` (0 sphere, 1 box, 2 torus) with parameters `params` at `p`,
/// and ∂sd/∂params (unused entries 0), loop for loop as `shape_sd` in the kernel.
pub(crate) fn sd_and_grad(
    code: u32,
    params: &[f64],
    p: [f64; 3],
) -> (f64, [f64; MAX_SHAPE_PARAMS]) {
    let d = [p[0] - params[0], p[1] - params[1], p[2] - params[2]];
    let mut g = [0.0; MAX_SHAPE_PARAMS];
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    match code {
        0 => {
            let len = norm(&d);
            for k in 0..3 {
                g[k] = -ratio(d[k], len);
            }
            g[3] = -1.0;
            (len - params[3], g)
        }
        1 => {
            let q: [f64; 3] = std::array::from_fn(|k| d[k].abs() - params[3 + k]);
            let m = q[0].max(q[1]).max(q[2]);
            let (dq, sd) = if m > 0.0 {
                let qp = q.map(|x| x.max(0.0));
                let len = norm(&qp);
                (qp.map(|x| ratio(x, len)), len)
            } else {
                let axis = if q[0] >= q[1] && q[0] >= q[2] {
                    0
                } else if q[1] >= q[2] {
                    1
                } else {
                    2
                };
                let mut dq = [0.0; 3];
                dq[axis] = 1.0;
                (dq, m)
            };
            for k in 0..3 {
                g[k] = -dq[k] * sign(d[k]);
                g[3 + k] = -dq[k];
            }
            (sd, g)
        }
        _ => {
            let rho = norm(&[d[0], d[2]]);
            let q = [rho - params[3], d[1]];
            let len = norm(&q);
            let (nx, ny) = (ratio(q[0], len), ratio(q[1], len));
            g[0] = -nx * ratio(d[0], rho);
            g[1] = -ny;
            g[2] = -nx * ratio(d[2], rho);
            g[3] = -nx;
            g[4] = -1.0;
            (len - params[4], g)
        }
    }
}
