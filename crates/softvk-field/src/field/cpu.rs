//! The f64 twin of the field kernels: [`eval`] (φ), [`logit`] (f) and [`backward`]
//! (dL/dparams from dL/dφ), loop for loop as `kernels/softvk/include/field_{grid,mlp,shape}.glsl`
//! compute them, in f64. Gradients are checked against central finite differences of
//! [`eval`] in the tests.

use super::mlp::{MlpLayout, SOFTPLUS_BETA};
use super::shape::sd_and_grad;
use super::{Cube, FieldKind};

/// `1 / (1 + e^{−f})`.
pub fn sigmoid(f: f64) -> f64 {
    1.0 / (1.0 + (-f).exp())
}

/// φ = sigmoid(f) at `p`, for a field of `kind` in `cube` with parameters `params`.
pub fn eval(kind: &FieldKind, cube: &Cube, params: &[f64], p: [f64; 3]) -> f64 {
    sigmoid(logit(kind, cube, params, p))
}

/// The logit f at `p`.
pub fn logit(kind: &FieldKind, cube: &Cube, params: &[f64], p: [f64; 3]) -> f64 {
    match kind {
        FieldKind::Grid { res } => {
            let (node, w) = grid_corners(cube, *res, p);
            (0..8).map(|k| w[k] * params[node[k]]).sum()
        }
        FieldKind::Mlp { .. } => {
            let layout = kind.mlp_layout().expect("an MLP kind has a layout");
            mlp_forward(&layout, cube, params, p).0
        }
        FieldKind::Analytic { shape, sharpness } => {
            -sharpness * sd_and_grad(shape.code(), params, p).0
        }
    }
}

/// dL/dparams of `L` whose derivative by φ at `points[i]` is `d_phi[i]`:
/// `Σ_i d_phi[i] · φ_i (1 − φ_i) · ∂f/∂params (points[i])`.
pub fn backward(
    kind: &FieldKind,
    cube: &Cube,
    params: &[f64],
    points: &[[f64; 3]],
    d_phi: &[f64],
) -> Vec<f64> {
    assert_eq!(points.len(), d_phi.len(), "one dL/dphi per point");
    let mut grad = vec![0.0; params.len()];
    for (&p, &g) in points.iter().zip(d_phi) {
        match kind {
            FieldKind::Grid { res } => {
                let (node, w) = grid_corners(cube, *res, p);
                let f: f64 = (0..8).map(|k| w[k] * params[node[k]]).sum();
                let phi = sigmoid(f);
                let dl = g * phi * (1.0 - phi);
                for k in 0..8 {
                    grad[node[k]] += w[k] * dl;
                }
            }
            FieldKind::Mlp { .. } => {
                let layout = kind.mlp_layout().expect("an MLP kind has a layout");
                mlp_backward_point(&layout, cube, params, p, g, &mut grad);
            }
            FieldKind::Analytic { shape, sharpness } => {
                let (sd, dsd) = sd_and_grad(shape.code(), params, p);
                let phi = sigmoid(-sharpness * sd);
                let dl = g * phi * (1.0 - phi);
                for (j, gj) in grad.iter_mut().enumerate() {
                    *gj += dl * -sharpness * dsd[j];
                }
            }
        }
    }
    grad
}

/// The grid cell and fractions of `p` (`grid_locate`): grid coordinates
/// `g = clamp((u + 1) / 2 · (res − 1), 0, res − 1)`, cell `min(⌊g⌋, res − 2)`, `t = g − cell`.
pub fn grid_locate(cube: &Cube, res: u32, p: [f64; 3]) -> ([usize; 3], [f64; 3]) {
    let r1 = f64::from(res - 1);
    let u = cube.normalize(p);
    let mut cell = [0usize; 3];
    let mut t = [0.0; 3];
    for k in 0..3 {
        let g = ((u[k] + 1.0) * 0.5 * r1).clamp(0.0, r1);
        let f = g.floor().min(r1 - 1.0).max(0.0);
        cell[k] = f as usize;
        t[k] = g - f;
    }
    (cell, t)
}

/// The 8 trilinear weights of corner `k = x + 2y + 4z` (`grid_weights`).
pub fn grid_weights(t: [f64; 3]) -> [f64; 8] {
    std::array::from_fn(|k| {
        let f = |bit: usize, t: f64| if k & bit != 0 { t } else { 1.0 - t };
        f(1, t[0]) * f(2, t[1]) * f(4, t[2])
    })
}

/// The node indices and weights of the 8 corners of `p`'s cell.
fn grid_corners(cube: &Cube, res: u32, p: [f64; 3]) -> ([usize; 8], [f64; 8]) {
    let (cell, t) = grid_locate(cube, res, p);
    let r = res as usize;
    let node = std::array::from_fn(|k| {
        let v = [
            cell[0] + (k & 1),
            cell[1] + ((k >> 1) & 1),
            cell[2] + ((k >> 2) & 1),
        ];
        v[0] + r * (v[1] + r * v[2])
    });
    (node, grid_weights(t))
}

/// The encoding `(u, sin(2^k π u), cos(2^k π u))` of `p` (`mlp_forward`'s first loop).
pub fn mlp_encoding(layout: &MlpLayout, cube: &Cube, p: [f64; 3]) -> Vec<f64> {
    let u = cube.normalize(p);
    let mut enc = u.to_vec();
    let mut freq = std::f64::consts::PI;
    for _ in 0..layout.frequencies {
        enc.extend(u.map(|x| (freq * x).sin()));
        enc.extend(u.map(|x| (freq * x).cos()));
        freq *= 2.0;
    }
    enc
}

fn softplus(z: f64) -> f64 {
    z.max(0.0) + (-SOFTPLUS_BETA * z.abs()).exp().ln_1p() / SOFTPLUS_BETA
}

/// Forward: the logit, every layer's input (the encoding, then each hidden layer's output) and
/// softplus'(z) of every hidden unit.
fn mlp_forward(
    layout: &MlpLayout,
    cube: &Cube,
    params: &[f64],
    p: [f64; 3],
) -> (f64, Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let mut inputs = vec![mlp_encoding(layout, cube, p)];
    let mut slopes = Vec::new();
    let layers = layout.hidden_layers as usize;
    for l in 0..=layers {
        let (offset, n_in, n_out) = layout.layer(l);
        let a = &inputs[l];
        let z: Vec<f64> = (0..n_out)
            .map(|o| {
                let row = &params[offset + o * n_in..offset + (o + 1) * n_in];
                row.iter().zip(a).map(|(w, x)| w * x).sum::<f64>()
                    + params[offset + n_out * n_in + o]
            })
            .collect();
        if l == layers {
            return (z[0], inputs, slopes);
        }
        slopes.push(z.iter().map(|&z| sigmoid(SOFTPLUS_BETA * z)).collect());
        inputs.push(z.iter().map(|&z| softplus(z)).collect());
    }
    unreachable!("the output layer returns")
}

/// Adds one point's `dL/dφ · ∂φ/∂params` to `grad`.
fn mlp_backward_point(
    layout: &MlpLayout,
    cube: &Cube,
    params: &[f64],
    p: [f64; 3],
    d_phi: f64,
    grad: &mut [f64],
) {
    let (f, inputs, slopes) = mlp_forward(layout, cube, params, p);
    let phi = sigmoid(f);
    let layers = layout.hidden_layers as usize;
    let mut delta = vec![d_phi * phi * (1.0 - phi)];
    for l in (0..=layers).rev() {
        let (offset, n_in, n_out) = layout.layer(l);
        for o in 0..n_out {
            for i in 0..n_in {
                grad[offset + o * n_in + i] += delta[o] * inputs[l][i];
            }
            grad[offset + n_out * n_in + o] += delta[o];
        }
        if l > 0 {
            delta = (0..n_in)
                .map(|i| {
                    let back: f64 = (0..n_out)
                        .map(|o| params[offset + o * n_in + i] * delta[o])
                        .sum();
                    slopes[l - 1][i] * back
                })
                .collect();
        }
    }
}
